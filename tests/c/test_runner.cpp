// The Unreal plugin's engine-independent SessionRunner
// (integrations/unreal/Source/Duolando/Public/DuolandoRunner.h): a game
// thread submits leader frames (some NaN) and drains follower frames while
// the worker thread runs the session; two runners share one model. Run
// under valgrind by .ci/ffi.sh. usage: test_runner <repo root>
#include "DuolandoRunner.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

static std::vector<float> ReadNpyF32(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::vector<unsigned char> raw((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (raw.size() < 10) return {};
  size_t header = 10 + raw[8] + 256u * raw[9];
  std::vector<float> out((raw.size() - header) / 4);
  std::memcpy(out.data(), raw.data() + header, out.size() * 4);
  return out;
}

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  std::string root = argv[1];
  std::vector<float> leader = ReadNpyF32(root + "/tests/fixtures/rollout_tiny_odd/leader_pos3d.npy");
  std::vector<float> music = ReadNpyF32(root + "/tests/fixtures/rollout_tiny_odd/music.npy");
  size_t frames = leader.size() / 165 / 4 * 4;
  if (frames == 0 || music.size() < frames * 54) return 2;

  duo_model* model = nullptr;
  if (duo_model_open_file((root + "/tests/fixtures/tiny/model.duo").c_str(), &model) != DUO_OK) return 3;
  duo_session_config config;
  duo_session_config_minimum(model, &config);
  const uint32_t seed[5] = {1, 2, 3, 4, 5};
  int failures = 0;
  {
    duolando::SessionRunner a(model, config, seed, music.data(), frames * 54, 300);
    duolando::SessionRunner b(model, config, seed, music.data(), frames * 54, 300);
    duo_model_free(model);  // the sessions keep it alive
    if (a.Status() != DUO_OK || b.Status() != DUO_OK) return 4;
    std::vector<duo_follower_frame> got_a(frames), got_b(frames);
    size_t na = 0, nb = 0;
    for (size_t i = 0; i < frames; ++i) {
      duo_leader_frame f;
      std::memcpy(&f, &leader[i * 165], sizeof f);
      if (i % 9 == 4) f.joints[0].x = NAN;  // a tracker glitch
      a.Submit(f);
      b.Submit(f);
      na += a.Take(&got_a[na], frames - na);
      nb += b.Take(&got_b[nb], frames - nb);
    }
    while (!a.Idle() || !b.Idle()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    na += a.Take(&got_a[na], frames - na);
    nb += b.Take(&got_b[nb], frames - nb);
    if (na == 0 || na != nb) ++failures;
    for (size_t i = 0; i < na; ++i) {
      if (got_a[i].index != i || std::memcmp(&got_a[i], &got_b[i], sizeof got_a[i]) != 0) ++failures;
      for (int j = 0; j < DUO_JOINTS; ++j)
        if (!std::isfinite(got_a[i].positions[j].x) || !std::isfinite(got_a[i].rotations[j].w)) ++failures;
    }
    if (a.RejectedFrames() == 0 || a.RejectedFrames() != b.RejectedFrames()) ++failures;
    if (a.WorkerError() != DUO_OK || a.DroppedFrames() != 0) ++failures;
    std::printf("test_runner: %zu follower frames per runner, %llu NaN frames replaced, %d failures\n", na,
                static_cast<unsigned long long>(a.RejectedFrames()), failures);
  }
  return failures ? 1 : 0;
}
