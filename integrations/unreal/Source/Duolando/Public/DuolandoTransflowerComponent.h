// UDuolandoTransflowerComponent: one probabilistic solo dancer (a Transflower
// model, .duo family 2) over the C ABI's duo_transflower_* session.
//
// The caller drives the session: PushAudioRows (whole rows of
// AudioFeatures() floats, 20 per second), then TryPullFrame (the session's
// seeded base sample) or TryPullFrameWithNoise (the caller's, e.g. recorded
// noise to replay a dance) until it answers false; ResetSession(seed) goes
// back to the seed motion with no audio. A pulled frame is the model's
// motion features (Channels() floats, its scaled feature space: e.g. 69-d
// exponential maps and root deltas in the paper config), not joints:
// turning them into a pose (the authors' scaler and skeleton) is the
// game's job (docs/TRANSFLOWER.md "Motion to a skeleton").
//
// BLOCKING: TryPullFrame* runs the frame's model step on the calling thread
// (published size, one thread: "realtime" mean 39.6 ms, p99 41.5 ms, the
// first step a whole R step, ~260 ms;
// docs/TRANSFLOWER.md "Speed and memory at the published size", int8, a
// shared 2-core machine). Unlike the follower and Bailando
// components there is no worker thread here: call the pulls from a worker
// (e.g. an async task) holding the component exclusively, or accept the
// hitch. One thread at a time per component (the session's rule).
#pragma once

#include "Components/ActorComponent.h"
#include "CoreMinimal.h"

#include <memory>

#include "DuolandoTransflowerComponent.generated.h"

struct duo_model;
struct duo_session;
struct duo_transflower_info;

// (The parameter is not named FrameIndex, as the component's property is: no shadowing.)
DECLARE_DYNAMIC_MULTICAST_DELEGATE_OneParam(FDuolandoTransflowerFrameSignature, int64, PulledIndex);

UCLASS(ClassGroup = (Animation), meta = (BlueprintSpawnableComponent))
class DUOLANDO_API UDuolandoTransflowerComponent : public UActorComponent
{
	GENERATED_BODY()

public:
	UDuolandoTransflowerComponent();
	~UDuolandoTransflowerComponent();   // out of line: duo_transflower_info is incomplete here

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

	/** One or more whole audio rows (AudioFeatures() floats each). False (logged) on a wrong
	 *  count, a non-finite value, DUO_BACKLOG (pull frames first) or no session; the session
	 *  is then unchanged. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool PushAudioRows(const TArray<float>& Rows);

	/** Rows of sliding input InputIndex for models with more than one (duo_transflower_push_input;
	 *  none of the published configs has one). False (logged) on failure. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool PushInputRows(int32 InputIndex, const TArray<float>& Rows);

	/** The next frame with the session's seeded base sample into Frame (runs its step: see
	 *  BLOCKING above). False when its audio is not in yet (not logged) or on failure (logged). */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool TryPullFrame();

	/** As TryPullFrame with the caller's base sample: NoiseFloats() floats, channel-major
	 *  (channels x frames per sample); the session's RNG is not drawn. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	bool TryPullFrameWithNoise(const TArray<float>& Noise);

	/** Back to frame 0: the seed motion, no audio, the base samples reseeded with Seed. */
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
	int32 NoiseFloats() const;   // floats of one base sample (TryPullFrameWithNoise)
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
	bool IsRunning() const { return Session != nullptr; }
	/** Frames pulled since BeginPlay (OnFrame broadcasts; ResetSession does not clear it). */
	int64 FramesPulled() const { return Pulled; }

private:
	bool Record(int32 Result, const TCHAR* Call);   // sets LastResult; logs a failure by name
	bool Publish(uint64 Index);                      // Frame written: index, count, OnFrame

	duo_model* Model = nullptr;
	duo_session* Session = nullptr;
	std::unique_ptr<duo_transflower_info> Info;   // the model's sizes (48 bytes); zeros without a session
	int64 Pulled = 0;
};
