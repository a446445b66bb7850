// UDuolandoTransflowerComponent: one probabilistic solo dancer (a Transflower
// model, .duo family 2) over the C ABI's duo_transflower_* session, run by a
// worker thread (duolando::TransflowerRunner, DuolandoRunner.h).
//
// The caller feeds audio (PushAudioRows: whole rows of AudioFeatures()
// floats, 20 per second) and takes frames (TryPullFrame) until it answers
// false; ResetSession(seed) goes back to the seed motion with no audio.
// The base samples come from the session's seeded RNG (RngSeed), or from
// NoiseTrack while it lasts (recorded noise, e.g. to replay a dance). A
// frame is the model's motion features (Channels() floats, its scaled
// feature space: e.g. 69-d exponential maps and root deltas in the paper
// config), not joints: turning them into a pose (the authors' scaler and
// skeleton) is the game's job (docs/TRANSFLOWER.md "Motion to a skeleton").
//
// THREADS: every function here is for the game thread and returns without
// waiting for the model: the frames' steps (published size, one thread:
// "realtime" mean 39.6 ms, p99 41.5 ms, the first step a whole R step,
// ~260 ms; docs/TRANSFLOWER.md "Speed and memory at the published size")
// run on the runner's worker, up to 20 frames (1 s) ahead of TryPullFrame,
// and it alone touches the session. EndPlay (and destruction) joins the
// worker: it waits for at most the step in flight.
#pragma once

#include "Components/ActorComponent.h"
#include "CoreMinimal.h"

#include <memory>

#include "DuolandoTransflowerComponent.generated.h"

struct duo_model;
struct duo_transflower_info;
namespace duolando { class TransflowerRunner; }

// (The parameter is not named FrameIndex, as the component's property is: no shadowing.)
DECLARE_DYNAMIC_MULTICAST_DELEGATE_OneParam(FDuolandoTransflowerFrameSignature, int64, PulledIndex);

UCLASS(ClassGroup = (Animation), meta = (BlueprintSpawnableComponent))
class DUOLANDO_API UDuolandoTransflowerComponent : public UActorComponent
{
	GENERATED_BODY()

public:
	UDuolandoTransflowerComponent();
	~UDuolandoTransflowerComponent();   // out of line: duo_transflower_info and TransflowerRunner are incomplete here

	/** The Transflower .duo model: absolute, or relative to the project's Content folder
	 *  (memory-mapped when a plain file, else read into one native copy). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	FFilePath ModelFile;

	/** The motion before the first frame: SeedRows() x Channels() floats, row-major, in the
	 *  model's scaled feature space. Copied into the session at BeginPlay. */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<float> SeedMotion;

	/** Style labels: one value per style input (Labels() of them, each below the model's
	 *  label_values); empty for models without one (the paper config). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<int32> Labels;

	/** Session preset: "exact" (refresh 1: the offline model's frames bit for bit, the slowest),
	 *  "reference" (refresh 4, f32), "realtime" (refresh 16, f16, rolling). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	FString Preset = TEXT("realtime");

	/** Seed of the session's base samples at BeginPlay (another seed, another dance). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	int64 RngSeed = 0;

	/** Recorded base samples (whole samples of NoiseFloats() floats, channel-major): frame t
	 *  takes sample t while they last, then the seeded RNG; again from the start after
	 *  ResetSession. Empty: the RNG only. Copied at BeginPlay. */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<float> NoiseTrack;

	/** The newest pulled frame: Channels() floats (motion features). */
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	TArray<float> Frame;

	/** Index of Frame (frame t is song row OutputTimeOffset() + t); -1 before the first. */
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	int64 FrameIndex = -1;

	/** The last library result of this component (a duo_result: 0 DUO_OK, 5 DUO_NOT_READY,
	 *  2 DUO_INVALID_ARGUMENT, 7 DUO_BACKLOG, ...; failures are also logged by name). */
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	int32 LastResult = 0;

	/** Fired once per pulled frame, after Frame and FrameIndex are written. */
	UPROPERTY(BlueprintAssignable, Category = "Duolando")
	FDuolandoTransflowerFrameSignature OnFrame;

	/** Queues one or more whole audio rows (AudioFeatures() floats each) for the worker. All
	 *  or nothing: false (logged) on a wrong count, a non-finite value or one above
	 *  DUO_MAX_MUSIC_FEATURE (DUO_NON_FINITE_INPUT), DUO_BACKLOG (the queue of 512 rows is
	 *  full: take frames first, the dance waits for TryPullFrame; push longer audio in pieces)
	 *  or no session. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool PushAudioRows(const TArray<float>& Rows);

	/** The next frame into Frame, if the worker has made it. False when none is ready yet
	 *  (LastResult DUO_NOT_READY, not logged: its audio is not in, or its step still runs) or
	 *  after a failure of the worker (LastResult its result, logged once). */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool TryPullFrame();

	/** Back to frame 0: the seed motion, no audio, the base samples reseeded with Seed (and
	 *  NoiseTrack from its start). Does not wait: rows queued and frames not taken are dropped. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool ResetSession(int64 Seed);

	/** Model sizes (duo_transflower_info's fields; 0 without a session). */
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 Channels() const;   // floats per frame
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 SeedRows() const;   // rows of SeedMotion
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 AudioFeatures() const;   // floats per audio row
	/** Audio rows a step reads: frame t needs rows t .. t + AudioWindow() - 1. */
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 AudioWindow() const;
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 NoiseFloats() const;   // floats of one base sample (NoiseTrack holds whole ones)
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 NumLabels() const;   // values Labels must hold
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 Fps() const;   // frames per second (20)
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 OutputTimeOffset() const;   // frame t is song row OutputTimeOffset() + t
	/** Audio rows after a frame's own row that its step reads (19 in the published configs). */
	UFUNCTION(BlueprintPure, Category = "Duolando")
	int32 LookaheadRows() const;

	virtual void BeginPlay() override;
	virtual void EndPlay(const EEndPlayReason::Type Reason) override;

	/** True between a successful BeginPlay and EndPlay. */
	bool IsRunning() const { return Runner != nullptr; }
	/** Frames pulled since BeginPlay (OnFrame broadcasts; ResetSession does not clear it). */
	int64 FramesPulled() const { return Pulled; }

private:
	bool Record(int32 Result, const TCHAR* Call);   // sets LastResult; logs a failure by name and the library's message
	bool Refuse(int32 Result, const FString& Why);  // sets LastResult; logs Why; false
	bool Publish(uint64 Index);                      // Frame written: index, count, OnFrame

	duo_model* Model = nullptr;
	std::unique_ptr<duolando::TransflowerRunner> Runner;   // the session and its worker
	std::unique_ptr<duo_transflower_info> Info;   // the model's sizes (48 bytes); zeros without a session
	int64 Pulled = 0;
};
