// Runs the Unreal plugin's UDuolandoTransflowerComponent (Private/
// DuolandoTransflowerComponent.cpp, compiled unchanged) against the real
// libduolando and the TEST STUB engine headers (tests/unreal/stub: not
// Unreal Engine). Called by test_component.cpp's main (.ci/ffi.sh).
// The component's steps run on its TransflowerRunner's worker, so every
// frame here is waited for (TryPullFrame polled, PullWait below).
// What it checks, on the Transflower paper fixture (tests/fixtures/
// transflower_paper: seed motion 12 x 11, audio rows x 7, recorded base
// samples, the authors' frames):
// - "exact", audio pushed row by row, the recorded noise given as
//   NoiseTrack: Frame equals the same session's frames stepped alone on
//   this thread bit for bit (the worker runs the same calls on the same
//   inputs), and the authors' frames (output.npy) within the case's 9.7e-6
//   relative tolerance (as tests/c/test_duolando.c), indices 0, 1, ... and
//   one OnFrame per frame; a wrong-size row, a NaN row, a row above
//   DUO_MAX_MUSIC_FEATURE and an empty PushAudioRows before them are
//   refused by name and change nothing;
// - ResetSession: no frame before audio (DUO_NOT_READY, not logged), the
//   same seed gives the same seeded frame, another seed another frame, a
//   component with RngSeed = s at BeginPlay the frame of ResetSession(s);
//   DUO_BACKLOG (all or nothing) once the session's 400 buffered rows and
//   the component's queue are full, and more rows taken after frames are;
// - BeginPlay refusals (no session, an error logged, LastResult set): a
//   Duolando and a Bailando model, a wrong-size SeedMotion, labels given to
//   a model without style inputs, a partial NoiseTrack sample, an unknown
//   preset, a missing file; calls without a session answer
//   DUO_NULL_PARAMETER; the follower and solo components refuse the
//   Transflower model.
#include "DuolandoFollowerComponent.h"
#include "DuolandoSoloDancerComponent.h"
#include "DuolandoTransflowerComponent.h"
#include "Misc/Paths.h"
#include "duolando.h"
#include "test_npy.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <thread>
#include <string>
#include <vector>

static int tf_failures = 0;
#define TF_CHECK(c)                                                                \
  do {                                                                             \
    if (!(c)) {                                                                    \
      std::fprintf(stderr, "FAIL %s:%d: %s\n", __FILE__, __LINE__, #c);           \
      ++tf_failures;                                                               \
    }                                                                              \
  } while (0)

// Floats [from, from + n) of v as a TArray.
static TArray<float> Slice(const std::vector<float>& v, size_t from, size_t n) {
  TArray<float> out;
  for (size_t i = from; i < from + n && i < v.size(); ++i) out.Add(v[i]);
  return out;
}

static const int kSeedRows = 12, kChannels = 11;  // the paper fixture's motion seed (meta.json)

// A component on the paper fixture with the given preset and seed, not yet begun.
static void Setup(UDuolandoTransflowerComponent& C, const std::vector<float>& motion, const char* preset, int64 seed) {
  C.ModelFile.FilePath = "transflower_paper/model.duo";  // relative: the stub Content folder
  C.SeedMotion = Slice(motion, 0, kSeedRows * kChannels);
  C.Preset = preset;
  C.RngSeed = seed;
}

// TryPullFrame until a frame comes (the worker steps it) or 20 s passed.
static bool PullWait(UDuolandoTransflowerComponent& C) {
  for (int i = 0; i < 20000; ++i) {
    if (C.TryPullFrame()) return true;
    if (C.LastResult != DUO_NOT_READY) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

// After ResetSession(seed) (or BeginPlay), the window's audio in: the first seeded frame.
static std::vector<float> FirstSeededFrame(UDuolandoTransflowerComponent& C, const std::vector<float>& audio) {
  TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NOT_READY && C.FrameIndex == -1);
  TF_CHECK(C.PushAudioRows(Slice(audio, 0, static_cast<size_t>(C.AudioWindow() * C.AudioFeatures()))));
  TF_CHECK(PullWait(C) && C.FrameIndex == 0 && C.LastResult == DUO_OK);
  std::vector<float> f;
  for (int32 j = 0; j < C.Frame.Num(); ++j) f.push_back(C.Frame[j]);
  return f;
}

int RunTransflowerComponentTests(const std::string& root) {
  const std::string dir = root + "/tests/fixtures/transflower_paper/";
  size_t mr = 0, mc = 0, ar = 0, ac = 0, nr = 0, nc = 0, wr = 0, wc = 0;
  std::vector<float> motion = ReadNpy(dir + "in_expmap_scaled_20.npy", &mr, &mc);  // 18 x 11
  std::vector<float> audio = ReadNpy(dir + "in_audio_feats_scaled_20.npy", &ar, &ac);  // 18 x 7
  std::vector<float> noise = ReadNpy(dir + "noise.npy", &nr, &nc);  // frames x noise_floats
  std::vector<float> want = ReadNpy(dir + "output.npy", &wr, &wc);  // frames x 11
  TF_CHECK(mc == kChannels && mr >= kSeedRows && !audio.empty() && !noise.empty() && wc == kChannels && wr > 0);
  if (tf_failures) return tf_failures;
  FPaths::StubProjectContentDir = FString(root + "/tests/fixtures");
  // The reference: the session stepped alone on this thread, the recorded noise replayed.
  std::vector<float> alone;
  {
    duo_model* m = nullptr;
    duo_session* s = nullptr;
    duo_transflower_config x;
    TF_CHECK(duo_model_open_file((dir + "model.duo").c_str(), &m) == DUO_OK && duo_transflower_config_preset(m, "exact", &x) == DUO_OK);
    TF_CHECK(duo_transflower_session_new(m, &x, motion.data(), kSeedRows * kChannels, nullptr, 0, &s) == DUO_OK);
    std::vector<float> f(kChannels);
    for (size_t r = 0; r < ar; ++r) {
      TF_CHECK(duo_session_push_music(s, &audio[r * ac], ac) == DUO_OK);
      size_t t = alone.size() / kChannels;
      while ((t + 1) * nc <= noise.size() &&
             duo_transflower_pull_frame_with_noise(s, &noise[t * nc], nc, f.data(), kChannels, nullptr) == DUO_OK) {
        alone.insert(alone.end(), f.begin(), f.end());
        t = alone.size() / kChannels;
      }
    }
    duo_session_free(s);
    duo_model_free(m);
    TF_CHECK(alone.size() == wr * kChannels);
  }
  {
    UDuolandoTransflowerComponent C;
    Setup(C, motion, "exact", 0);
    C.NoiseTrack = Slice(noise, 0, noise.size());
    TF_CHECK(!C.PrimaryComponentTick.bCanEverTick);
    TF_CHECK(!C.PushAudioRows(Slice(audio, 0, ac)) && C.LastResult == DUO_NULL_PARAMETER);  // before BeginPlay
    TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NULL_PARAMETER && C.Channels() == 0);
    C.BeginPlay();
    TF_CHECK(C.IsRunning() && C.LastResult == DUO_OK);
    TF_CHECK(C.Channels() == kChannels && C.SeedRows() == kSeedRows && C.AudioFeatures() == static_cast<int32>(ac));
    TF_CHECK(C.Frame.Num() == kChannels && C.Fps() == 20 && C.NumLabels() == 0 && C.FrameIndex == -1);
    TF_CHECK(C.NoiseFloats() == static_cast<int32>(nc) && C.AudioWindow() > 0 && C.AudioWindow() <= static_cast<int32>(ar));
    std::printf("transflower component: %d channels, %d audio features, window %d rows, lookahead %d, noise %d floats, offset %d\n",
                C.Channels(), C.AudioFeatures(), C.AudioWindow(), C.LookaheadRows(), C.NoiseFloats(), C.OutputTimeOffset());
    std::vector<int64> Indices;
    C.OnFrame.AddStub([&](int64 Index) { Indices.push_back(Index); });
    // Refused rows (logged by name) leave the session as it was: the golden below still holds.
    TF_CHECK(!C.PushAudioRows(Slice(audio, 0, ac + 1)) && C.LastResult == DUO_INVALID_ARGUMENT);
    // 0 floats: DUO_INVALID_ARGUMENT (duo_session_push_music's rule), nothing changed.
    TF_CHECK(!C.PushAudioRows(TArray<float>()) && C.LastResult == DUO_INVALID_ARGUMENT);
    TArray<float> Bad = Slice(audio, 0, 2 * ac);
    Bad[static_cast<int32>(ac) + 2] = std::numeric_limits<float>::quiet_NaN();
    TF_CHECK(!C.PushAudioRows(Bad) && C.LastResult == DUO_NON_FINITE_INPUT);
    Bad[static_cast<int32>(ac) + 2] = 2 * DUO_MAX_MUSIC_FEATURE;
    TF_CHECK(!C.PushAudioRows(Bad) && C.LastResult == DUO_NON_FINITE_INPUT);
    double worst = 0, scale = 1;
    size_t got = 0;
    bool same = true;
    for (size_t r = 0; r < ar; ++r) {
      TF_CHECK(C.PushAudioRows(Slice(audio, r * ac, ac)));
      // Frames whose audio is in: rows >= window - 1 each complete one.
      const size_t ready = r + 1 >= static_cast<size_t>(C.AudioWindow()) ? r + 2 - static_cast<size_t>(C.AudioWindow()) : 0;
      while (got < ready && PullWait(C)) {
        TF_CHECK(C.FrameIndex == static_cast<int64>(got));
        for (int j = 0; j < kChannels && got < wr; ++j) {
          worst = std::fmax(worst, std::fabs(C.Frame[j] - want[got * kChannels + j]));
          scale = std::fmax(scale, std::fabs(want[got * kChannels + j]));
          same = same && std::memcmp(&C.Frame[j], &alone[got * kChannels + j], sizeof(float)) == 0;
        }
        ++got;
      }
      TF_CHECK(got == ready);  // no failure on the way
    }
    std::printf("transflower component: %zu frames replayed on the worker, bit for bit with the session alone: %s, rel err %.2e vs the authors' (tolerance 9.7e-6)\n",
                got, same ? "yes" : "NO", worst / scale);
    TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NOT_READY);  // no frame past the audio
    TF_CHECK(got == wr && same && C.FramesPulled() == static_cast<int64>(wr) && Indices.size() == wr);
    for (size_t i = 0; i < Indices.size(); ++i) TF_CHECK(Indices[i] == static_cast<int64>(i));
    TF_CHECK(worst / scale <= 9.7e-6);
    // A reset replays the noise track: frame 0 of the golden again, whatever the seed.
    TF_CHECK(C.ResetSession(5));
    std::vector<float> Z = FirstSeededFrame(C, audio);
    TF_CHECK(Z.size() == kChannels && std::memcmp(Z.data(), alone.data(), kChannels * sizeof(float)) == 0);
    C.EndPlay(EEndPlayReason::Quit);
    TF_CHECK(!C.IsRunning() && C.Channels() == 0);
    TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NULL_PARAMETER);
    TF_CHECK(!C.ResetSession(1) && C.LastResult == DUO_NULL_PARAMETER);

    // Seeded frames (no noise track): a seed repeats itself, another seed differs.
    UDuolandoTransflowerComponent Q;
    Setup(Q, motion, "exact", 0);
    Q.BeginPlay();
    TF_CHECK(Q.ResetSession(11));
    std::vector<float> A = FirstSeededFrame(Q, audio);
    TF_CHECK(Q.ResetSession(11));
    std::vector<float> B = FirstSeededFrame(Q, audio);
    TF_CHECK(Q.ResetSession(12));
    std::vector<float> D = FirstSeededFrame(Q, audio);
    TF_CHECK(A.size() == kChannels && A == B && A != D);
    // DUO_BACKLOG once the audio buffer (400 rows beyond the window: the preset), the frames
    // made ahead and the queue are full: the worker has taken in all it can (a pause changes nothing).
    TF_CHECK(Q.ResetSession(11));
    int Pushed = 0, Refused = 0;
    while (Pushed < 2000 && Refused < 3) {
      if (Q.PushAudioRows(Slice(audio, (static_cast<size_t>(Pushed) % ar) * ac, ac))) {
        ++Pushed;
        Refused = 0;
      } else {
        TF_CHECK(Q.LastResult == DUO_BACKLOG);
        ++Refused;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    }
    std::printf("transflower component: %d rows taken before %s\n", Pushed, duo_result_name(Q.LastResult));
    TF_CHECK(Q.LastResult == DUO_BACKLOG && Pushed >= 400 + Q.AudioWindow() && Pushed < 2000);
    TF_CHECK(!Q.PushAudioRows(Slice(audio, 0, ac)) && Q.LastResult == DUO_BACKLOG);
    TF_CHECK(Q.TryPullFrame() && Q.FrameIndex == 0);  // made ahead
    for (int i = 0; i < 3; ++i) TF_CHECK(PullWait(Q));  // frees room: the worker takes rows again
    bool Taken = false;
    for (int i = 0; i < 20000 && !(Taken = Q.PushAudioRows(Slice(audio, 0, ac))); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    TF_CHECK(Taken && Q.LastResult == DUO_OK);
    Q.EndPlay(EEndPlayReason::Quit);   // with the queues full

    // The seed given at BeginPlay: the same frame as ResetSession with it; "realtime" runs too.
    UDuolandoTransflowerComponent S;
    Setup(S, motion, "exact", 11);
    S.BeginPlay();
    TF_CHECK(S.IsRunning() && FirstSeededFrame(S, audio) == A);
    S.EndPlay(EEndPlayReason::Quit);
    UDuolandoTransflowerComponent R;
    Setup(R, motion, "realtime", 11);
    R.BeginPlay();
    std::vector<float> F = FirstSeededFrame(R, audio);
    bool Finite = R.IsRunning() && F.size() == kChannels;
    for (float v : F) Finite = Finite && std::isfinite(v);
    TF_CHECK(Finite);
    R.EndPlay(EEndPlayReason::Quit);
  }
  {
    // BeginPlay refusals: no session, LastResult set, an error logged.
    struct Case {
      const char* what;
      const char* file;
      const char* preset;
      int seed_floats;
      int labels;
      int32 result;  // LastResult expected
    } cases[] = {
        {"Duolando model", "tiny/model.duo", "exact", kSeedRows * kChannels, 0, DUO_INVALID_ARGUMENT},
        {"Bailando model", "bailando_btiny/model.duo", "exact", kSeedRows * kChannels, 0, DUO_INVALID_ARGUMENT},
        {"seed one float short", "transflower_paper/model.duo", "exact", kSeedRows * kChannels - 1, 0, DUO_INVALID_ARGUMENT},
        {"a label for no style input", "transflower_paper/model.duo", "exact", kSeedRows * kChannels, 1, DUO_INVALID_ARGUMENT},
        {"unknown preset", "transflower_paper/model.duo", "interactive", kSeedRows * kChannels, 0, DUO_INVALID_ARGUMENT},
        {"a partial noise sample", "transflower_paper/model.duo", "exact", kSeedRows * kChannels, -1, DUO_INVALID_ARGUMENT},
        {"missing file", "transflower_paper/no_such_model.duo", "exact", kSeedRows * kChannels, 0, DUO_IO},
    };
    for (const Case& k : cases) {
      std::fprintf(stderr, "(expected error next: %s)\n", k.what);
      UDuolandoTransflowerComponent C;
      C.ModelFile.FilePath = k.file;
      C.SeedMotion = Slice(motion, 0, static_cast<size_t>(k.seed_floats));
      for (int i = 0; i < k.labels; ++i) C.Labels.Add(0);
      if (k.labels < 0) C.NoiseTrack = Slice(noise, 0, nc + 1);
      C.Preset = k.preset;
      C.BeginPlay();
      const bool ok = !C.IsRunning() && C.LastResult == k.result && C.Channels() == 0 && C.Frame.Num() == 0;
      if (!ok) std::fprintf(stderr, "case %s: running %d, LastResult %d\n", k.what, C.IsRunning(), C.LastResult);
      TF_CHECK(ok);
      TF_CHECK(!C.PushAudioRows(Slice(audio, 0, ac)) && C.LastResult == DUO_NULL_PARAMETER);
      TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NULL_PARAMETER && C.FramesPulled() == 0);
      TF_CHECK(!C.ResetSession(1) && C.LastResult == DUO_NULL_PARAMETER);
      C.EndPlay(EEndPlayReason::Quit);
    }
    // The other components refuse the Transflower model.
    UDuolandoFollowerComponent Follower;
    Follower.ModelFile.FilePath = "transflower_paper/model.duo";
    Follower.BeginPlay();
    TF_CHECK(!Follower.IsRunning());
    Follower.EndPlay(EEndPlayReason::Quit);
    UDuolandoSoloDancerComponent Solo;
    Solo.ModelFile.FilePath = "transflower_paper/model.duo";
    Solo.MusicRows.Add(0.0f);
    Solo.BeginPlay();
    TF_CHECK(!Solo.IsRunning());
    Solo.EndPlay(EEndPlayReason::Quit);
  }
  if (tf_failures == 0) std::printf("transflower component: all checks passed\n");
  return tf_failures;
}
