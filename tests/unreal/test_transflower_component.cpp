// Runs the Unreal plugin's UDuolandoTransflowerComponent (Private/
// DuolandoTransflowerComponent.cpp, compiled unchanged) against the real
// libduolando and the TEST STUB engine headers (tests/unreal/stub: not
// Unreal Engine). Called by test_component.cpp's main (.ci/ffi.sh).
// What it checks, on the Transflower paper fixture (tests/fixtures/
// transflower_paper: seed motion 12 x 11, audio rows x 7, recorded base
// samples, the authors' frames):
// - "exact", audio pushed row by row, the recorded noise replayed through
//   TryPullFrameWithNoise: Frame equals the authors' frames (output.npy)
//   within the case's 9.7e-6 relative tolerance (as tests/c/test_duolando.c),
//   indices 0, 1, ... and one OnFrame per frame; a wrong-size row, a NaN
//   row, an empty or out-of-range PushInputRows before them are refused by
//   name, and they and an empty PushAudioRows change nothing;
// - ResetSession: no frame before audio (DUO_NOT_READY, not logged), the
//   same seed gives the same seeded frame, another seed another frame, a
//   component with RngSeed = s at BeginPlay the frame of ResetSession(s);
//   a wrong-size noise buffer is refused and the session unchanged;
//   DUO_BACKLOG once 400 rows beyond the window wait; PushInputRows on the
//   audio input (1) works, on the motion (0) is refused;
// - BeginPlay refusals (no session, an error logged, LastResult set): a
//   Duolando and a Bailando model, a wrong-size SeedMotion, labels given to
//   a model without style inputs, an unknown preset, a missing file; calls
//   without a session answer DUO_NULL_PARAMETER; the follower and solo
//   components refuse the Transflower model.
#include "DuolandoFollowerComponent.h"
#include "DuolandoSoloDancerComponent.h"
#include "DuolandoTransflowerComponent.h"
#include "Misc/Paths.h"
#include "duolando.h"
#include "test_npy.h"

#include <cmath>
#include <cstdio>
#include <limits>
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

// After ResetSession(seed) (or BeginPlay), the window's audio in: the first seeded frame.
static std::vector<float> FirstSeededFrame(UDuolandoTransflowerComponent& C, const std::vector<float>& audio) {
  TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NOT_READY && C.FrameIndex == -1);
  TF_CHECK(C.PushAudioRows(Slice(audio, 0, static_cast<size_t>(C.AudioWindow() * C.AudioFeatures()))));
  TF_CHECK(C.TryPullFrame() && C.FrameIndex == 0 && C.LastResult == DUO_OK);
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
  {
    UDuolandoTransflowerComponent C;
    Setup(C, motion, "exact", 0);
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
    TF_CHECK(!C.PushInputRows(1, TArray<float>()) && C.LastResult == DUO_INVALID_ARGUMENT);
    TF_CHECK(!C.PushInputRows(2, Slice(audio, 0, ac)) && C.LastResult == DUO_INVALID_ARGUMENT);  // 2 inputs
    // 0 floats through duo_session_push_music: DUO_INVALID_ARGUMENT (the header's rule), nothing changed.
    TF_CHECK(!C.PushAudioRows(TArray<float>()) && C.LastResult == DUO_INVALID_ARGUMENT);
    TArray<float> Bad = Slice(audio, 0, ac);
    Bad[2] = std::numeric_limits<float>::quiet_NaN();
    TF_CHECK(!C.PushAudioRows(Bad) && C.LastResult == DUO_NON_FINITE_INPUT);
    TF_CHECK(!C.PushInputRows(0, Slice(motion, 0, kChannels)) && C.LastResult == DUO_INVALID_ARGUMENT);  // the motion input
    double worst = 0, scale = 1;
    size_t got = 0;
    for (size_t r = 0; r < ar; ++r) {
      // Row 1 through the generic input call (input 1 is the audio), the rest as audio rows.
      TF_CHECK(r == 1 ? C.PushInputRows(1, Slice(audio, r * ac, ac)) : C.PushAudioRows(Slice(audio, r * ac, ac)));
      while ((got + 1) * nc <= noise.size() && C.TryPullFrameWithNoise(Slice(noise, got * nc, nc))) {
        TF_CHECK(C.FrameIndex == static_cast<int64>(got));
        for (int j = 0; j < kChannels && got < wr; ++j) {
          worst = std::fmax(worst, std::fabs(C.Frame[j] - want[got * kChannels + j]));
          scale = std::fmax(scale, std::fabs(want[got * kChannels + j]));
        }
        ++got;
      }
      TF_CHECK(C.LastResult == DUO_NOT_READY || C.LastResult == DUO_OK);  // no failure on the way
    }
    std::printf("transflower component: %zu frames replayed, rel err %.2e vs the authors' (tolerance 9.7e-6)\n", got, worst / scale);
    TF_CHECK(got == wr && C.FramesPulled() == static_cast<int64>(wr) && Indices.size() == wr);
    for (size_t i = 0; i < Indices.size(); ++i) TF_CHECK(Indices[i] == static_cast<int64>(i));
    TF_CHECK(worst / scale <= 9.7e-6);
    // Seeded frames: a seed repeats itself, another seed differs.
    TF_CHECK(C.ResetSession(11));
    std::vector<float> A = FirstSeededFrame(C, audio);
    TF_CHECK(C.ResetSession(11));
    std::vector<float> B = FirstSeededFrame(C, audio);
    TF_CHECK(C.ResetSession(12));
    std::vector<float> D = FirstSeededFrame(C, audio);
    TF_CHECK(A.size() == kChannels && A == B && A != D);
    // A wrong-size base sample is refused; the session is unchanged (frame 0 still next).
    TF_CHECK(C.ResetSession(11));
    TF_CHECK(C.PushAudioRows(Slice(audio, 0, static_cast<size_t>(C.AudioWindow()) * ac)));
    TF_CHECK(!C.TryPullFrameWithNoise(Slice(noise, 0, nc - 1)) && C.LastResult == DUO_INVALID_ARGUMENT);
    TF_CHECK(C.TryPullFrame() && C.FrameIndex == 0);
    for (int j = 0; j < kChannels; ++j) TF_CHECK(C.Frame[j] == A[static_cast<size_t>(j)]);
    // DUO_BACKLOG once the audio buffer (400 rows beyond the window: the preset) is full.
    TF_CHECK(C.ResetSession(11));
    int Pushed = 0;
    while (Pushed < 2000 && C.PushAudioRows(Slice(audio, (static_cast<size_t>(Pushed) % ar) * ac, ac))) ++Pushed;
    std::printf("transflower component: %d rows taken before %s\n", Pushed, duo_result_name(C.LastResult));
    TF_CHECK(C.LastResult == DUO_BACKLOG && Pushed >= 400 && Pushed < 2000);
    C.EndPlay(EEndPlayReason::Quit);
    TF_CHECK(!C.IsRunning() && C.Channels() == 0);
    TF_CHECK(!C.TryPullFrame() && C.LastResult == DUO_NULL_PARAMETER);
    TF_CHECK(!C.ResetSession(1) && C.LastResult == DUO_NULL_PARAMETER);

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
        {"missing file", "transflower_paper/no_such_model.duo", "exact", kSeedRows * kChannels, 0, DUO_IO},
    };
    for (const Case& k : cases) {
      std::fprintf(stderr, "(expected error next: %s)\n", k.what);
      UDuolandoTransflowerComponent C;
      C.ModelFile.FilePath = k.file;
      C.SeedMotion = Slice(motion, 0, static_cast<size_t>(k.seed_floats));
      for (int i = 0; i < k.labels; ++i) C.Labels.Add(0);
      C.Preset = k.preset;
      C.BeginPlay();
      const bool ok = !C.IsRunning() && C.LastResult == k.result && C.Channels() == 0 && C.Frame.Num() == 0;
      if (!ok) std::fprintf(stderr, "case %s: running %d, LastResult %d\n", k.what, C.IsRunning(), C.LastResult);
      TF_CHECK(ok);
      TF_CHECK(!C.PushAudioRows(Slice(audio, 0, ac)) && C.LastResult == DUO_NULL_PARAMETER);
      TF_CHECK(!C.TryPullFrameWithNoise(Slice(noise, 0, nc)) && C.FramesPulled() == 0);
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
