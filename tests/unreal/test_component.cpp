// Runs the Unreal plugin's UDuolandoFollowerComponent and module
// (integrations/unreal/Source/Duolando/Private/*.cpp, compiled unchanged)
// against the real libduolando and the TEST STUB engine headers in
// tests/unreal/stub/ (not Unreal Engine: flat std:: stand-ins, no UObject
// system, no game thread). What it checks: the model is found relative to
// the (stub) project Content folder, BeginPlay starts the runner, 30 fps
// leader poses in Unreal coordinates go in, TickComponent publishes
// follower frames (delegate, positions in cm, unit rotations, rising
// indices), a missing model fails cleanly, EndPlay joins and frees.
// UDuolandoSoloDancerComponent on the Bailando fixture: the whole music
// track in, ticks at 60 fps publish every frame once, in order, never
// before its time, in Unreal coordinates equal to the golden positions
// (within 1e-3 cm = 1e-5 m); Restart starts again from frame 0; each
// component refuses the other family's model. UDuolandoTransflowerComponent:
// test_transflower_component.cpp (its own checks, run from main here).
// Usage: test_component <repo root>   (.ci/ffi.sh)
#include "DuolandoFollowerComponent.h"
#include "DuolandoSoloDancerComponent.h"
#include "Misc/Paths.h"
#include "Modules/ModuleManager.h"
#include "duolando.h"
#include "test_npy.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

IModuleInterface* StubCreateModule_Duolando();
int RunTransflowerComponentTests(const std::string& root);  // test_transflower_component.cpp: its failures

static int failures = 0;
#define CHECK(c)                                                         \
  do {                                                                   \
    if (!(c)) {                                                          \
      std::fprintf(stderr, "FAIL %s:%d: %s\n", __FILE__, __LINE__, #c); \
      ++failures;                                                        \
    }                                                                    \
  } while (0)

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  const std::string root = argv[1];
  size_t lr = 0, lc = 0, mr = 0, mc = 0;
  std::vector<float> leader = ReadNpy(root + "/assets/demo_leader_pos3d.npy", &lr, &lc);
  std::vector<float> music = ReadNpy(root + "/assets/demo_music.npy", &mr, &mc);
  CHECK(lc == 165 && mc == 54 && lr > 200 && !leader.empty() && !music.empty());
  if (failures) return 1;

  IModuleInterface* Module = StubCreateModule_Duolando();
  Module->StartupModule();

  FPaths::StubProjectContentDir = FString(root + "/assets");
  {
    UDuolandoFollowerComponent C;
    CHECK(C.PrimaryComponentTick.bCanEverTick);
    C.ModelFile.FilePath = "demo.duo";  // relative: the project's Content folder
    for (float v : music) C.MusicFeatures.Add(v);
    int64 Broadcasts = 0, LastIndex = -1;
    bool Rising = true;
    C.OnFollowerFrame.AddStub([&](int64 Index) {
      Rising = Rising && Index > LastIndex;
      LastIndex = Index;
      ++Broadcasts;
    });
    C.BeginPlay();
    CHECK(C.IsRunning());
    const int Frames = 200;
    for (int t = 0; t < Frames; ++t) {
      TArray<FVector> Joints;
      for (int j = 0; j < DUO_JOINTS; ++j) {
        const float* p = &leader[static_cast<size_t>(t) * 165 + 3 * j];
        duo_vec3 u = duo_vec3_to_unreal(duo_vec3{p[0], p[1], p[2]});
        Joints.Add(FVector(u.x, u.y, u.z));
      }
      C.SubmitLeaderPose(Joints);
      C.TickComponent(1.0f / 30, LEVELTICK_All, &C.PrimaryComponentTick);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    const int64 Dropped = C.DroppedLeaderFrames();
    for (int i = 0; i < 1000 && LastIndex + 1 + Dropped < Frames; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      C.TickComponent(1.0f / 30, LEVELTICK_All, &C.PrimaryComponentTick);
    }
    std::printf("component: %d leader poses submitted, %lld dropped (worker behind), %lld frames published, last index %lld\n",
                Frames, (long long)Dropped, (long long)C.FramesPublished(), (long long)LastIndex);
    CHECK(C.FramesPublished() > 0 && Broadcasts == C.FramesPublished() && Rising);
    // Latency 0: every pose the runner kept comes out as one follower frame.
    CHECK(LastIndex + 1 + Dropped == Frames);
    CHECK(C.FollowerPositions.Num() == DUO_JOINTS && C.FollowerLocalRotations.Num() == DUO_JOINTS);
    double Lowest = 1e9, Highest = -1e9;
    for (int j = 0; j < DUO_JOINTS; ++j) {
      const FVector& P = C.FollowerPositions[j];
      CHECK(std::isfinite(P.X) && std::isfinite(P.Y) && std::isfinite(P.Z));
      Lowest = std::fmin(Lowest, P.Z);
      Highest = std::fmax(Highest, P.Z);
      const FQuat& Q = C.FollowerLocalRotations[j];
      CHECK(std::fabs(std::sqrt(Q.X * Q.X + Q.Y * Q.Y + Q.Z * Q.Z + Q.W * Q.W) - 1) < 1e-3);
    }
    std::printf("component: follower z from %.1f to %.1f cm (Unreal z up, cm)\n", Lowest, Highest);
    CHECK(Highest - Lowest > 100 && Highest - Lowest < 250);  // a standing dancer, in centimetres
    CHECK(std::fabs(C.FollowerRoot.Z - C.FollowerPositions[0].Z) < 1e-3);
    C.EndPlay(EEndPlayReason::Quit);
    CHECK(!C.IsRunning());
  }
  {
    UDuolandoFollowerComponent Missing;
    Missing.ModelFile.FilePath = FString(root + "/assets/no_such_model.duo");
    Missing.BeginPlay();  // logs an error
    CHECK(!Missing.IsRunning());
    Missing.TickComponent(1.0f / 30, LEVELTICK_All, &Missing.PrimaryComponentTick);
    CHECK(Missing.FramesPublished() == 0);
    Missing.EndPlay(EEndPlayReason::Quit);
  }
  {
    size_t rr = 0, rc = 0, wr = 0, wc = 0;
    std::vector<float> rows = ReadNpy(root + "/tests/fixtures/bailando_rollout_btiny_demo_odd/music.npy", &rr, &rc);
    std::vector<float> want = ReadNpy(root + "/tests/fixtures/bailando_rollout_btiny_demo_odd/pos3d.npy", &wr, &wc);
    CHECK(rc == 438 && rr == 21 && wc == 72 && wr == 192);
    FPaths::StubProjectContentDir = FString(root + "/tests/fixtures");
    UDuolandoSoloDancerComponent D;
    CHECK(D.PrimaryComponentTick.bCanEverTick);
    D.ModelFile.FilePath = "bailando_btiny/model.duo";  // relative: the project's Content folder
    for (float v : rows) D.MusicRows.Add(v);
    D.SeedTokens = {15, 14};  // the golden's (meta.json)
    D.Preset = "exact";
    std::vector<int64> Indices;
    int Tick = 0;
    bool Early = false;
    double Worst = 0;
    D.OnDancerFrame.AddStub([&](int64 Index) {
      Indices.push_back(Index);
      Early = Early || Index > Tick + 1;  // after tick t (1/60 s each) frames 0..t+1 are due
      if (Index < 0 || static_cast<size_t>(Index) >= wr) return;
      for (int j = 0; j < DUO_BAILANDO_JOINTS; ++j) {
        const float* p = &want[static_cast<size_t>(Index) * 72 + 3 * j];
        const FVector& U = D.DancerPositions[j];  // Unreal: 100 (z, -x, y) cm
        Worst = std::fmax(Worst, std::fabs(U.X - 100.0 * p[2]));
        Worst = std::fmax(Worst, std::fabs(U.Y + 100.0 * p[0]));
        Worst = std::fmax(Worst, std::fabs(U.Z - 100.0 * p[1]));
      }
    });
    D.BeginPlay();
    CHECK(D.IsRunning());
    for (Tick = 0; Tick < 20000 && !D.HasEnded(); ++Tick) {
      D.TickComponent(1.0f / 60, LEVELTICK_All, &D.PrimaryComponentTick);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    std::printf("solo component: %zu frames published over %d ticks (%lld late), max abs err %.2e cm\n", Indices.size(), Tick,
                (long long)D.LateFrames(), Worst);
    CHECK(D.HasEnded() && D.FramesPublished() == 192 && Indices.size() == 192);
    for (size_t i = 0; i < Indices.size(); ++i) CHECK(Indices[i] == static_cast<int64>(i));
    CHECK(!Early);
    CHECK(Worst <= 1e-3);
    // Again from frame 0.
    Indices.clear();
    D.Restart();
    CHECK(D.IsRunning() && !D.HasEnded());
    for (Tick = 0; Tick < 20000 && Indices.size() < 10; ++Tick) {
      D.TickComponent(1.0f / 60, LEVELTICK_All, &D.PrimaryComponentTick);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    CHECK(Indices.size() >= 10 && Indices[0] == 0 && Indices[9] == 9 && !Early);
    D.EndPlay(EEndPlayReason::Quit);
    CHECK(!D.IsRunning());
  }
  {
    // Each component refuses the other family's model (an error logged, no runner).
    UDuolandoSoloDancerComponent Duet;
    Duet.ModelFile.FilePath = FString(root + "/assets/demo.duo");
    Duet.MusicRows.Add(0.0f);
    Duet.BeginPlay();
    CHECK(!Duet.IsRunning());
    Duet.TickComponent(1.0f / 60, LEVELTICK_All, &Duet.PrimaryComponentTick);
    CHECK(Duet.FramesPublished() == 0);
    Duet.EndPlay(EEndPlayReason::Quit);
    UDuolandoFollowerComponent Solo;
    Solo.ModelFile.FilePath = FString(root + "/tests/fixtures/bailando_btiny/model.duo");
    Solo.BeginPlay();
    CHECK(!Solo.IsRunning());
    Solo.EndPlay(EEndPlayReason::Quit);
  }
  failures += RunTransflowerComponentTests(root);
  Module->ShutdownModule();
  delete Module;
  if (failures == 0) std::printf("test_component: all checks passed\n");
  return failures == 0 ? 0 : 1;
}
