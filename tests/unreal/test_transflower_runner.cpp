// The Unreal plugin's engine-independent TransflowerRunner and
// TransflowerStepBatch (integrations/unreal/Source/Duolando/Public/
// DuolandoRunner.h) on the Transflower paper fixture (tests/fixtures/
// transflower_paper: seed motion 12 x 11, 18 audio rows x 7, window 14
// rows, 5 frames, the recorded base samples, the authors' frames). Called
// by tests/c/test_runner.cpp's main, run under valgrind by .ci/ffi.sh.
// Every reference below is the same session stepped alone on this thread
// with the C API; the runner must give it BIT FOR BIT: its worker runs the
// same calls on the same inputs in the same order (one matrix thread,
// duo_set_threads untouched), so there is no reason for a single ulp of
// difference. What it checks:
// - golden: "exact", the recorded noise given as the runner's noise track,
//   the audio submitted a few rows at a time into a queue of 4 rows with 2
//   frames ahead: the reference's frames bit for bit, indices 0..4, and the
//   authors' frames within the case's 9.7e-6 relative tolerance (as
//   tests/c/test_duolando.c and the component test); the model freed first;
// - rejection: a NaN row is replaced by the row before it (RejectedRows 1):
//   the frames of the seeded session fed that row twice, bit for bit;
// - Reset: after frames, and again while the worker is stepping (a frame in
//   flight is discarded): the frames of a fresh session with the new seed;
// - backlog: nothing taken, 1 frame ahead, 6 rows buffered in the session,
//   a queue of 8: SubmitAudio stops taking rows at a bound set by those
//   sizes, RowRoom() 0, no worker error; taking frames frees room and the
//   whole stream then comes out with no frame lost, bit for bit;
// - refusals (Status): a Duolando and a Bailando model, a batched config, a
//   partial noise sample, a short seed motion; SoloRunner refuses the
//   Transflower model; a refused runner queues and gives nothing;
// - shutdown: before any row, while the worker steps (the rows just taken
//   into the session), with the queues full, right after a Reset;
// - TransflowerStepBatch: three batched sessions (seeds 21, 22, 23) stepped
//   through one batch give each session's frames alone, bit for bit; the
//   batch refuses a Duolando model, a NULL and a repeated session (by
//   index), more than DUO_MAX_BATCH sessions, a backlogged session; a
//   batched session's pull does not step; moving the batch keeps it.
#include "DuolandoRunner.h"
#include "test_npy.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

static int tr_failures = 0;
#define TR_CHECK(c)                                                      \
  do {                                                                   \
    if (!(c)) {                                                          \
      std::fprintf(stderr, "FAIL %s:%d: %s\n", __FILE__, __LINE__, #c); \
      ++tr_failures;                                                     \
    }                                                                    \
  } while (0)

namespace {

struct Fixture {
  std::vector<float> motion, audio, noise, want;
  size_t rows = 0, d = 0, nz = 0, frames = 0;
  duo_model* model = nullptr;
  duo_transflower_info info{};
  duo_transflower_config exact{};
};

const size_t kSeedFloats = 12 * 11;

// The session alone on this thread: `audio` pushed row by row, every frame
// pulled (with noise sample t for frame t when `noise` is given).
std::vector<float> Alone(const Fixture& fx, duo_transflower_config c, const std::vector<float>& audio,
                         const std::vector<float>* noise) {
  std::vector<float> out;
  duo_session* s = nullptr;
  c.batched = 0;
  TR_CHECK(duo_transflower_session_new(fx.model, &c, fx.motion.data(), kSeedFloats, nullptr, 0, &s) == DUO_OK);
  std::vector<float> f(fx.info.channels);
  uint64_t index = 0;
  for (size_t r = 0; r * fx.d < audio.size(); ++r) {
    TR_CHECK(duo_session_push_music(s, &audio[r * fx.d], fx.d) == DUO_OK);
    for (;;) {
      size_t t = out.size() / f.size();
      duo_result p = noise && (t + 1) * fx.nz <= noise->size()
                         ? duo_transflower_pull_frame_with_noise(s, &(*noise)[t * fx.nz], fx.nz, f.data(), f.size(), &index)
                         : duo_transflower_pull_frame(s, f.data(), f.size(), &index);
      if (p != DUO_OK) break;
      TR_CHECK(index == t);
      out.insert(out.end(), f.begin(), f.end());
    }
  }
  duo_session_free(s);
  return out;
}

// `audio` through the runner (at most `chunk` rows per SubmitAudio), its
// frames taken (at most 2 per Take; indices from `first`) until `frames`
// came or 20 s passed.
std::vector<float> Through(duolando::TransflowerRunner& r, const std::vector<float>& audio, size_t d, size_t frames,
                           size_t chunk = 3, uint64_t first = 0) {
  const size_t c = r.Info().channels;
  std::vector<float> out, two(2 * c);
  uint64_t idx[2];
  size_t sent = 0, rows = audio.size() / d;
  auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (out.size() < frames * c && std::chrono::steady_clock::now() < until) {
    if (sent < rows) sent += r.SubmitAudio(&audio[sent * d], std::min(chunk, rows - sent));
    size_t n = r.Take(two.data(), idx, 2);
    for (size_t k = 0; k < n; ++k) {
      TR_CHECK(idx[k] == first + out.size() / c);
      out.insert(out.end(), &two[k * c], &two[(k + 1) * c]);
    }
    if (n == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return out;
}

// `n` rows of the fixture's audio, cycled.
std::vector<float> Cycled(const Fixture& fx, size_t n) {
  std::vector<float> a;
  for (size_t r = 0; r < n; ++r) a.insert(a.end(), &fx.audio[(r % fx.rows) * fx.d], &fx.audio[(r % fx.rows + 1) * fx.d]);
  return a;
}

void TestRunner(Fixture& fx, const std::string& root) {
  const size_t c = fx.info.channels, W = fx.info.audio_window;
  // Golden: the recorded noise as the track, the model freed first.
  {
    std::vector<float> ref = Alone(fx, fx.exact, fx.audio, &fx.noise);
    TR_CHECK(ref.size() == fx.frames * c);
    duo_model* own = nullptr;
    TR_CHECK(duo_model_open_file((root + "/tests/fixtures/transflower_paper/model.duo").c_str(), &own) == DUO_OK);
    duolando::TransflowerRunner r(own, fx.exact, fx.motion.data(), kSeedFloats, nullptr, 0, fx.noise.data(),
                                  fx.noise.size(), 4, 2);
    duo_model_free(own);  // the session keeps it alive
    TR_CHECK(r.Status() == DUO_OK && r.RowFeatures() == fx.d && r.Info().channels == c);
    std::vector<float> got = Through(r, fx.audio, fx.d, fx.frames, 3);
    double worst = 0, scale = 1;
    for (size_t i = 0; i < got.size() && i < fx.want.size(); ++i) {
      worst = std::fmax(worst, std::fabs(got[i] - fx.want[i]));
      scale = std::fmax(scale, std::fabs(fx.want[i]));
    }
    std::printf("transflower runner: %zu frames replayed, bit for bit with the session alone: %s, rel err %.2e vs the authors'\n",
                got.size() / c, got == ref ? "yes" : "NO", worst / scale);
    TR_CHECK(got.size() == ref.size() && std::memcmp(got.data(), ref.data(), ref.size() * sizeof(float)) == 0);
    TR_CHECK(worst / scale <= 9.7e-6);
    TR_CHECK(r.RejectedRows() == 0 && r.WorkerError() == DUO_OK);
    // Reset with a noise track: the track replays from its start.
    r.Reset(5);
    TR_CHECK(Through(r, fx.audio, fx.d, fx.frames) == ref);
  }
  // Seeded: 40 rows (27 frames), row 20 NaN: replaced by row 19.
  duo_transflower_config seeded = fx.exact;
  seeded.rng_seed = 11;
  std::vector<float> audio40 = Cycled(fx, 40), patched = audio40, bad = audio40;
  std::memcpy(&patched[20 * fx.d], &audio40[19 * fx.d], fx.d * sizeof(float));
  bad[20 * fx.d + 3] = std::nanf("");
  const size_t frames40 = 40 - W + 1;
  std::vector<float> ref11 = Alone(fx, seeded, patched, nullptr);
  TR_CHECK(ref11.size() == frames40 * c && ref11 != Alone(fx, seeded, audio40, nullptr));
  {
    duolando::TransflowerRunner r(fx.model, seeded, fx.motion.data(), kSeedFloats, nullptr, 0);
    TR_CHECK(r.Status() == DUO_OK);
    TR_CHECK(Through(r, bad, fx.d, frames40, 5) == ref11);
    TR_CHECK(r.RejectedRows() == 1 && r.WorkerError() == DUO_OK);
    // Reset after frames: a fresh session with seed 12.
    duo_transflower_config s12 = seeded;
    s12.rng_seed = 12;
    std::vector<float> ref12 = Alone(fx, s12, audio40, nullptr);
    TR_CHECK(ref12 != Alone(fx, seeded, audio40, nullptr));
    r.Reset(12);
    TR_CHECK(Through(r, audio40, fx.d, frames40) == ref12);
    // Reset while the worker steps: rows in, the worker busy with them; the
    // frames it makes meanwhile are discarded, none come out of order.
    for (int k = 0; k < 3; ++k) {
      r.Reset(12);
      TR_CHECK(r.SubmitAudio(audio40.data(), W + 4) == W + 4);
      std::this_thread::sleep_for(std::chrono::milliseconds(k));
      r.Reset(11);
    }
    TR_CHECK(Through(r, patched, fx.d, frames40) == ref11);
    TR_CHECK(r.WorkerError() == DUO_OK);
  }
  // Backlog: nothing taken; 1 frame ahead, the session holding 6 rows beyond the window, a queue of 8.
  {
    duo_transflower_config small = seeded;
    small.input_buffer_rows = 6;
    std::vector<float> audio80 = Cycled(fx, 80);
    std::vector<float> ref = Alone(fx, small, audio80, nullptr);
    duolando::TransflowerRunner r(fx.model, small, fx.motion.data(), kSeedFloats, nullptr, 0, nullptr, 0, 8, 1);
    TR_CHECK(r.Status() == DUO_OK && r.RowRoom() == 8);
    size_t accepted = 0, before = 1;
    for (int spin = 0; spin < 20000 && accepted != before; ++spin) {  // until a pause changes nothing
      before = accepted;
      accepted += r.SubmitAudio(&audio80[accepted * fx.d], 80 - accepted);
      std::this_thread::sleep_for(std::chrono::milliseconds(accepted == before ? 200 : 1));
      accepted += r.SubmitAudio(&audio80[accepted * fx.d], 80 - accepted);
    }
    // The session holds W + 6 rows past its last frame made: frame 0 made
    // (the one frame ahead), frame 1 blocked on the full ring, so rows
    // 1 .. W + 6 in the session (its window + 6), 8 more queued, 1 row
    // more the worker holds as blocked: W + 6 + 8 + 1 +- 1.
    std::printf("transflower runner: backlog after %zu rows (window %zu + 6 buffered + 8 queued + 1 frame ahead)\n", accepted,
                W);
    TR_CHECK(accepted >= W + 6 + 8 && accepted <= W + 6 + 8 + 2 && r.RowRoom() == 0);
    TR_CHECK(r.WorkerError() == DUO_OK && r.RejectedRows() == 0);
    std::vector<float> rest(audio80.begin() + static_cast<std::ptrdiff_t>(accepted * fx.d), audio80.end());
    std::vector<float> got(c);
    uint64_t idx = 9;
    TR_CHECK(r.Take(got.data(), &idx, 1) == 1 && idx == 0);
    std::vector<float> tail = Through(r, rest, fx.d, 80 - W, 3, 1);  // frames 1 .. 80 - W
    got.insert(got.end(), tail.begin(), tail.end());
    TR_CHECK(got == ref);
  }
  // Refusals.
  {
    duo_model *duet = nullptr, *solo = nullptr;
    TR_CHECK(duo_model_open_file((root + "/tests/fixtures/tiny/model.duo").c_str(), &duet) == DUO_OK);
    TR_CHECK(duo_model_open_file((root + "/tests/fixtures/bailando_btiny/model.duo").c_str(), &solo) == DUO_OK);
    duolando::TransflowerRunner a(duet, fx.exact, fx.motion.data(), kSeedFloats, nullptr, 0);
    duolando::TransflowerRunner b(solo, fx.exact, fx.motion.data(), kSeedFloats, nullptr, 0);
    duo_transflower_config batched = fx.exact;
    batched.batched = 1;
    duolando::TransflowerRunner e(fx.model, batched, fx.motion.data(), kSeedFloats, nullptr, 0);
    duolando::TransflowerRunner f(fx.model, fx.exact, fx.motion.data(), kSeedFloats, nullptr, 0, fx.noise.data(), fx.nz + 1);
    duolando::TransflowerRunner g(fx.model, fx.exact, fx.motion.data(), kSeedFloats - 1, nullptr, 0);
    duo_session_config sc;
    TR_CHECK(duo_session_config_preset(solo, "exact", &sc) == DUO_OK);
    const uint32_t seed2[2] = {1, 2};
    duolando::SoloRunner h(fx.model, sc, seed2);
    for (duolando::RowRunner* x : {static_cast<duolando::RowRunner*>(&a), static_cast<duolando::RowRunner*>(&b),
                                   static_cast<duolando::RowRunner*>(&e), static_cast<duolando::RowRunner*>(&f),
                                   static_cast<duolando::RowRunner*>(&g), static_cast<duolando::RowRunner*>(&h)}) {
      TR_CHECK(x->Status() == DUO_INVALID_ARGUMENT);
      TR_CHECK(x->SubmitRows(fx.audio.data(), 1) == 0 && x->RowRoom() == 0);
    }
    std::vector<float> one(c);
    TR_CHECK(g.Take(one.data(), nullptr, 1) == 0);
    g.Reset(1);  // refused runner: nothing to reset, nothing breaks
    duo_model_free(duet);
    duo_model_free(solo);
  }
  // Shutdown in every state (valgrind: no leak, no invalid access, no hang).
  {
    duolando::TransflowerRunner idle(fx.model, fx.exact, fx.motion.data(), kSeedFloats, nullptr, 0);
  }
  for (int k = 0; k < 3; ++k) {
    duolando::TransflowerRunner r(fx.model, seeded, fx.motion.data(), kSeedFloats, nullptr, 0, nullptr, 0, 32, 4);
    TR_CHECK(r.SubmitAudio(audio40.data(), W + 8) == W + 8);
    // The worker has taken every row into the session: it is at its first steps.
    while (r.RowRoom() < 32) std::this_thread::yield();
    if (k == 1) r.Reset(3);  // and a reset pending
    if (k == 2) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  {
    duo_transflower_config tiny = seeded;
    tiny.input_buffer_rows = 2;
    duolando::TransflowerRunner full(fx.model, tiny, fx.motion.data(), kSeedFloats, nullptr, 0, nullptr, 0, 2, 1);
    std::vector<float> a = Cycled(fx, W + 40);
    size_t sent = 0, idle = 0;
    while (sent < W + 40 && idle < 200) {  // until 200 ms pass with no row taken: queues full, a frame waiting
      size_t n = full.SubmitAudio(&a[sent * fx.d], W + 40 - sent);
      sent += n;
      idle = n ? 0 : idle + 1;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    TR_CHECK(sent < W + 40 && full.RowRoom() == 0);
  }
}

void TestStepBatch(Fixture& fx, const std::string& root) {
  const size_t c = fx.info.channels, W = fx.info.audio_window;
  duo_transflower_config bc = fx.exact;
  bc.pending_frames = 2;
  std::vector<float> audio = Cycled(fx, 30);
  const size_t rows = 30, frames = rows - W + 1;
  std::vector<float> want[3];
  for (int k = 0; k < 3; ++k) {
    bc.rng_seed = 21 + static_cast<uint64_t>(k);
    want[k] = Alone(fx, bc, audio, nullptr);
    TR_CHECK(want[k].size() == frames * c);
  }
  TR_CHECK(want[0] != want[1] && want[1] != want[2]);
  {
    duo_model* duet = nullptr;
    TR_CHECK(duo_model_open_file((root + "/tests/fixtures/tiny/model.duo").c_str(), &duet) == DUO_OK);
    duolando::TransflowerStepBatch wrong(duet), none(nullptr);
    TR_CHECK(wrong.Status() == DUO_INVALID_ARGUMENT && wrong.Get() == nullptr);
    TR_CHECK(none.Status() == DUO_NULL_PARAMETER && none.Get() == nullptr);
    duo_model_free(duet);
  }
  duo_session* s[3] = {nullptr, nullptr, nullptr};
  bc.batched = 1;
  for (int k = 0; k < 3; ++k) {
    bc.rng_seed = 21 + static_cast<uint64_t>(k);
    TR_CHECK(duo_transflower_session_new(fx.model, &bc, fx.motion.data(), kSeedFloats, nullptr, 0, &s[k]) == DUO_OK);
  }
  duolando::TransflowerStepBatch first(fx.model);
  TR_CHECK(first.Status() == DUO_OK && first.Get() != nullptr);
  duolando::TransflowerStepBatch batch(std::move(first));  // moved: one owner, freed once
  TR_CHECK(batch.Status() == DUO_OK && batch.Get() != nullptr && first.Get() == nullptr);

  size_t stepped = 9, failed = 0;
  // Refusals by index; nothing changes.
  duo_session* list[4] = {s[0], nullptr, s[1], s[2]};
  TR_CHECK(batch.Step(list, 4, &stepped, &failed) == DUO_NULL_PARAMETER && failed == 1);
  list[1] = s[2];
  TR_CHECK(batch.Step(list, 4, &stepped, &failed) == DUO_INVALID_ARGUMENT && failed == 3);  // s[2] twice
  std::vector<duo_session*> many(DUO_MAX_BATCH + 1, s[0]);
  TR_CHECK(batch.Step(many.data(), many.size(), &stepped, &failed) == DUO_INVALID_ARGUMENT && failed == DUO_NO_SESSION);
  TR_CHECK(batch.Step(s, 0, &stepped, &failed) == DUO_OK && stepped == 0 && failed == DUO_NO_SESSION);
  // No audio: nothing to step. A batched session's pull never steps.
  TR_CHECK(batch.Step(s, 3, &stepped, &failed) == DUO_OK && stepped == 0);
  std::vector<float> f(c), got[3];
  uint64_t index = 0;
  for (int k = 0; k < 3; ++k) TR_CHECK(duo_session_push_music(s[k], audio.data(), W * fx.d) == DUO_OK);
  TR_CHECK(duo_transflower_pull_frame(s[0], f.data(), c, &index) == DUO_NOT_READY);
  // Backlog: session 2's two pending frames made, not pulled.
  TR_CHECK(duo_session_push_music(s[2], &audio[W * fx.d], fx.d) == DUO_OK);
  for (int k = 0; k < 2; ++k) TR_CHECK(batch.Step(&s[2], 1, &stepped, &failed) == DUO_OK && stepped == 1);
  TR_CHECK(batch.Step(s, 3, &stepped, &failed) == DUO_BACKLOG && failed == 2);
  // The rest, row by row for all three: each as alone.
  for (size_t r = W; r <= rows; ++r) {
    if (r < rows)
      for (int k = 0; k < 3; ++k)
        if (k < 2 || r > W) TR_CHECK(duo_session_push_music(s[k], &audio[r * fx.d], fx.d) == DUO_OK);
    do {
      for (int k = 0; k < 3; ++k)
        while (duo_transflower_pull_frame(s[k], f.data(), c, &index) == DUO_OK) {
          TR_CHECK(index == got[k].size() / c);
          got[k].insert(got[k].end(), f.begin(), f.end());
        }
      TR_CHECK(batch.Step(s, 3, &stepped, &failed) == DUO_OK);
    } while (stepped > 0);
  }
  for (int k = 0; k < 3; ++k) {
    while (duo_transflower_pull_frame(s[k], f.data(), c, &index) == DUO_OK) got[k].insert(got[k].end(), f.begin(), f.end());
    TR_CHECK(got[k].size() == want[k].size() && std::memcmp(got[k].data(), want[k].data(), want[k].size() * sizeof(float)) == 0);
  }
  std::printf("transflower step batch: 3 batched sessions, %zu / %zu / %zu frames, each as alone bit for bit: %s\n",
              got[0].size() / c, got[1].size() / c, got[2].size() / c,
              got[0] == want[0] && got[1] == want[1] && got[2] == want[2] ? "yes" : "NO");
  for (int k = 0; k < 3; ++k) duo_session_free(s[k]);
}

}  // namespace

int RunTransflowerRunnerTests(const std::string& root) {
  Fixture fx;
  const std::string dir = root + "/tests/fixtures/transflower_paper/";
  size_t mr = 0, mc = 0, wr = 0, wc = 0, nr = 0;
  fx.motion = ReadNpy(dir + "in_expmap_scaled_20.npy", &mr, &mc);
  fx.audio = ReadNpy(dir + "in_audio_feats_scaled_20.npy", &fx.rows, &fx.d);
  fx.noise = ReadNpy(dir + "noise.npy", &nr, &fx.nz);
  fx.want = ReadNpy(dir + "output.npy", &wr, &wc);
  fx.frames = wr;
  if (mc != 11 || mr < 12 || fx.audio.empty() || fx.noise.empty() || wc != 11 ||
      duo_model_open_file((dir + "model.duo").c_str(), &fx.model) != DUO_OK ||
      duo_transflower_get_info(fx.model, &fx.info) != DUO_OK ||
      duo_transflower_config_preset(fx.model, "exact", &fx.exact) != DUO_OK) {
    std::fprintf(stderr, "transflower runner: fixture not read\n");
    return 1;
  }
  TR_CHECK(fx.info.audio_features == fx.d && fx.info.noise_floats == fx.nz && nr == wr);
  TestRunner(fx, root);
  TestStepBatch(fx, root);
  duo_model_free(fx.model);
  std::printf("transflower runner: %d failures\n", tr_failures);
  return tr_failures;
}
