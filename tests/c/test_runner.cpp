// The Unreal plugin's engine-independent SessionRunner
// (integrations/unreal/Source/Duolando/Public/DuolandoRunner.h): a game
// thread submits leader frames (some NaN) and drains follower frames while
// the worker thread runs the session; four runners share one model, two of
// them bound to one step batch (freed at once: the sessions keep it), all
// four giving the same frames. The
// SoloRunner on the Bailando fixture: music rows submitted a few at a time
// (one NaN row replaced) with a small output ring the game thread drains,
// then Finish: the golden positions within 1e-5 m; the same with the rows
// given as a track; each runner refuses the other family's model. Run
// under valgrind by .ci/ffi.sh; with tests/unreal/test_transflower_runner.cpp
// (TransflowerRunner, TransflowerStepBatch). usage: test_runner <repo root>
#include "DuolandoRunner.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

// ThreadSanitizer sees the runners' C++ but not the library's lock (Rust
// atomics, not instrumented), so the batch memory two bound sessions take
// in turn looks raced there: under it, the two runners bound to a batch
// are left out (valgrind's build runs them; the lock itself is checked by
// ffi/tests/batched_session.rs, and under Rust's ThreadSanitizer by hand:
// docs/C_API.md "Sessions bound to a batch").
#if defined(__SANITIZE_THREAD__)
#define DUO_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define DUO_TSAN 1
#endif
#endif
#ifdef DUO_TSAN
static const int kRunners = 2;
#else
static const int kRunners = 4;
#endif

static std::vector<float> ReadNpyF32(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::vector<unsigned char> raw((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (raw.size() < 10) return {};
  size_t header = 10 + raw[8] + 256u * raw[9];
  std::vector<float> out((raw.size() - header) / 4);
  std::memcpy(out.data(), raw.data() + header, out.size() * 4);
  return out;
}

// Takes every frame of a solo runner (the game thread) until it has ended;
// returns the max abs error against `want` (72 floats per frame), counting
// frames and checking their indices.
static float TakeSolo(duolando::SoloRunner& r, const std::vector<float>& want, size_t* got, int* failures) {
  float worst = 0;
  duolando::SoloFrame frames[5];
  for (int spins = 0; spins < 200000; ++spins) {
    bool ended = r.Ended();  // before the Take: frames computed before it are taken below
    size_t n = r.Take(frames, 5);
    for (size_t k = 0; k < n; ++k) {
      if (frames[k].index != *got) ++*failures;
      for (size_t j = 0; j < DUO_BAILANDO_JOINTS * 3 && (*got + 1) * 72 <= want.size(); ++j) {
        float d = std::fabs(frames[k].positions[j] - want[*got * 72 + j]);
        if (!(d <= worst)) worst = d;
      }
      ++*got;
    }
    if (ended && n == 0) return worst;
    if (n == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ++*failures;  // never ended
  return worst;
}

static int TestSolo(const std::string& root) {
  int failures = 0;
  std::vector<float> rows = ReadNpyF32(root + "/tests/fixtures/bailando_rollout_btiny_demo_odd/music.npy");
  std::vector<float> want = ReadNpyF32(root + "/tests/fixtures/bailando_rollout_btiny_demo_odd/pos3d.npy");
  if (rows.size() != 21 * 438 || want.size() != 192 * 72) return 1;
  const size_t n_rows = rows.size() / 438;
  duo_model* solo = nullptr;
  duo_model* duet = nullptr;
  if (duo_model_open_file((root + "/tests/fixtures/bailando_btiny/model.duo").c_str(), &solo) != DUO_OK) return 1;
  if (duo_model_open_file((root + "/tests/fixtures/tiny/model.duo").c_str(), &duet) != DUO_OK) return 1;
  duo_session_config exact, duet_config;
  if (duo_session_config_preset(solo, "exact", &exact) != DUO_OK) return 1;
  duo_session_config_minimum(duet, &duet_config);
  const uint32_t seed[2] = {15, 14};  // the golden's seed tokens (meta.json)
  const uint32_t seed5[5] = {1, 2, 3, 4, 5};
  {
    // Each runner refuses the other family's model.
    duolando::SoloRunner wrong_solo(duet, duet_config, seed5);
    duolando::SessionRunner wrong_duet(solo, exact, seed5, nullptr, 0);
    if (wrong_solo.Status() != DUO_INVALID_ARGUMENT || wrong_duet.Status() != DUO_INVALID_ARGUMENT) ++failures;
  }
  for (int with_nan = 0; with_nan < 2; ++with_nan) {
    // Rows a few at a time (the queue holds 4), frames drained 5 at a time
    // from a ring of 8 (the worker waits for room). Second pass: row 10 is
    // NaN and is replaced by row 9 (the rows keep their clock: 192 frames,
    // finite; the dance differs from the golden from there on).
    duolando::SoloRunner r(solo, exact, seed, nullptr, 0, 4, 8);
    if (r.Status() != DUO_OK) return 1;
    if (r.MusicFeatures() != 438) ++failures;
    std::vector<float> stream = rows;
    if (with_nan) stream[10 * 438 + 3] = NAN;
    size_t submitted = 0, got = 0;
    float worst = 0;
    bool finite = true;
    duolando::SoloFrame frames[5];
    while (submitted < n_rows) {
      submitted += r.SubmitMusic(&stream[submitted * 438], std::min<size_t>(3, n_rows - submitted));
      size_t n = r.Take(frames, 5);
      for (size_t k = 0; k < n; ++k) {
        if (frames[k].index != got) ++failures;
        for (size_t j = 0; j < DUO_BAILANDO_JOINTS * 3 && (got + 1) * 72 <= want.size(); ++j) {
          float d = std::fabs(frames[k].positions[j] - want[got * 72 + j]);
          if (!(d <= worst)) worst = d;
          finite = finite && std::isfinite(frames[k].positions[j]);
        }
        ++got;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    r.Finish();
    if (r.SubmitMusic(rows.data(), 1) != 0) ++failures;  // after Finish: ignored
    worst = std::fmax(worst, TakeSolo(r, want, &got, &failures));
    std::printf("test_runner: solo, rows streamed%s: %zu frames, %llu row(s) replaced, max abs err %g m\n",
                with_nan ? " (row 10 NaN)" : "", got, static_cast<unsigned long long>(r.RejectedRows()),
                static_cast<double>(worst));
    if (got != 192 || !finite || r.RejectedRows() != static_cast<uint64_t>(with_nan) || r.WorkerError() != DUO_OK) ++failures;
    if (!with_nan && !(worst <= 1e-5f)) ++failures;
    if (with_nan && !(worst > 1e-3f)) ++failures;  // row 9 twice is another dance
  }
  {
    duolando::SoloRunner r(solo, exact, seed, rows.data(), rows.size(), 4, 8);
    if (r.Status() != DUO_OK) return 1;
    r.Finish();
    size_t got = 0;
    float worst = TakeSolo(r, want, &got, &failures);
    std::printf("test_runner: solo, a track: %zu frames, max abs err %g m\n", got, static_cast<double>(worst));
    if (got != 192 || !(worst <= 1e-5f) || r.WorkerError() != DUO_OK || r.RejectedRows() != 0) ++failures;
  }
  duo_model_free(solo);
  duo_model_free(duet);
  return failures;
}

int RunTransflowerRunnerTests(const std::string& root);  // tests/unreal/test_transflower_runner.cpp

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
    duo_step_batch* batch = nullptr;
    if (duo_step_batch_new(model, &config, 1, &batch) != DUO_OK) return 4;
    duolando::SessionRunner a(model, config, seed, music.data(), frames * 54, 300);
    duolando::SessionRunner b(model, config, seed, music.data(), frames * 54, 300);
    std::unique_ptr<duolando::SessionRunner> c, d;
    if (kRunners == 4) {
      c.reset(new duolando::SessionRunner(model, config, seed, music.data(), frames * 54, 300, batch));
      d.reset(new duolando::SessionRunner(model, config, seed, music.data(), frames * 54, 300, batch));
    }
    duo_step_batch_free(batch);  // the bound sessions keep it alive
    duo_model_free(model);       // the sessions keep it alive
    duolando::SessionRunner* all[4] = {&a, &b, c.get(), d.get()};
    std::vector<duolando::SessionRunner*> runners(all, all + kRunners);
    for (auto* r : runners)
      if (r->Status() != DUO_OK) return 4;
    std::vector<duo_follower_frame> got[4];
    size_t n[4] = {0, 0, 0, 0};
    for (auto& g : got) g.resize(frames);
    for (size_t i = 0; i < frames; ++i) {
      duo_leader_frame f;
      std::memcpy(&f, &leader[i * 165], sizeof f);
      if (i % 9 == 4) f.joints[0].x = NAN;  // a tracker glitch
      for (int k = 0; k < kRunners; ++k) {
        runners[k]->Submit(f);
        n[k] += runners[k]->Take(&got[k][n[k]], frames - n[k]);
      }
    }
    for (auto* r : runners)
      while (!r->Idle()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    for (int k = 0; k < kRunners; ++k) n[k] += runners[k]->Take(&got[k][n[k]], frames - n[k]);
    const std::vector<duo_follower_frame>& got_a = got[0];
    size_t na = n[0];
    for (int k = 1; k < kRunners; ++k)
      if (n[k] != na) ++failures;
    if (na == 0) ++failures;
    for (size_t i = 0; i < na; ++i) {
      for (int k = 1; k < kRunners; ++k)
        if (std::memcmp(&got_a[i], &got[k][i], sizeof got_a[i]) != 0) ++failures;
      if (got_a[i].index != i) ++failures;
      for (int j = 0; j < DUO_JOINTS; ++j)
        if (!std::isfinite(got_a[i].positions[j].x) || !std::isfinite(got_a[i].rotations[j].w)) ++failures;
    }
    for (auto* r : runners) {
      if (r->RejectedFrames() == 0 || r->RejectedFrames() != a.RejectedFrames()) ++failures;
      if (r->WorkerError() != DUO_OK || r->DroppedFrames() != 0) ++failures;
    }
    std::printf("test_runner: %d runners (%d bound to a batch), %zu follower frames each, %llu NaN frames replaced, %d failures\n", kRunners, kRunners - 2, na,
                static_cast<unsigned long long>(a.RejectedFrames()), failures);
  }
  int solo_failures = TestSolo(root);
  std::printf("test_runner: solo runner, %d failures\n", solo_failures);
  int transflower_failures = RunTransflowerRunnerTests(root);
  return failures || solo_failures || transflower_failures ? 1 : 0;
}
