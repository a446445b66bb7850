// UDuolandoSoloDancerComponent: one solo dancer to music (a Bailando model).
//
// BeginPlay hands the whole music track (MusicRows: rows x 438 features,
// 7.5 rows per second, from `duolando features --for bailando`) to a
// worker thread (duolando::SoloRunner), which computes the dance a few
// frames ahead; each tick the component publishes, in order, every frame
// whose time (index / 60 s since BeginPlay, or since Restart) has come, as
// 24 SMPL joint positions in Unreal world coordinates (cm, relative to the
// world origin as the model places them: the root starts at the origin).
// Nothing here blocks the game thread on inference. Start the music
// together with BeginPlay (or call Restart when it starts).
#pragma once

#include "Components/ActorComponent.h"
#include "CoreMinimal.h"

#include <memory>

#include "DuolandoSoloDancerComponent.generated.h"

namespace duolando { class SoloRunner; struct SoloFrame; }
struct duo_model;

DECLARE_DYNAMIC_MULTICAST_DELEGATE_OneParam(FDuolandoSoloFrameSignature, int64, FrameIndex);

UCLASS(ClassGroup = (Animation), meta = (BlueprintSpawnableComponent))
class DUOLANDO_API UDuolandoSoloDancerComponent : public UActorComponent
{
	GENERATED_BODY()

public:
	UDuolandoSoloDancerComponent();
	~UDuolandoSoloDancerComponent();   // out of line: SoloRunner is incomplete here

	/** The solo (Bailando) .duo model: absolute, or relative to the project's Content folder
	 *  (memory-mapped when a plain file, else read into one native copy). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	FFilePath ModelFile;

	/** The music: rows x 438 Bailando features, one row per token (7.5 per second). Copied into the
	 *  session at BeginPlay. */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<float> MusicRows;

	/** The dancer's 2 start tokens (up, down); each below the model's vocabulary. */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<int32> SeedTokens = {0, 0};

	/** Session preset: "exact" (the offline model's numbers, the slowest), "reference",
	 *  "interactive", "minimum". */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	FString Preset = TEXT("reference");

	/** Newest published pose: the 24 SMPL joints (0-21 as SMPL-X's, 22 left_hand, 23 right_hand),
	 *  Unreal world coordinates (cm). */
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	TArray<FVector> DancerPositions;

	/** Fired once per frame, in order (several in one tick when frames fall due together). */
	UPROPERTY(BlueprintAssignable, Category = "Duolando")
	FDuolandoSoloFrameSignature OnDancerFrame;

	/** Game thread: the dance starts again from frame 0 at this moment (call when the music
	 *  starts, if not at BeginPlay). Recreates the runner (the model stays open): waits for the
	 *  worker's current step (milliseconds) to end. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	void Restart();

	virtual void BeginPlay() override;
	virtual void EndPlay(const EEndPlayReason::Type Reason) override;
	virtual void TickComponent(float DeltaTime, ELevelTick TickType, FActorComponentTickFunction* ThisTickFunction) override;

	/** Frames published so far (OnDancerFrame broadcasts). */
	int64 FramesPublished() const { return Published; }
	/** Frames published more than one frame period after their time (the worker was behind). */
	int64 LateFrames() const { return Late; }
	/** True between a successful BeginPlay and EndPlay. */
	bool IsRunning() const { return Runner != nullptr; }
	/** True once the last frame of the music has been published. */
	bool HasEnded() const { return bEnded; }

private:
	bool StartRunner();

	duo_model* Model = nullptr;
	std::unique_ptr<duolando::SoloRunner> Runner;
	std::unique_ptr<duolando::SoloFrame> Pending;   // taken, not yet due
	bool bHasPending = false;
	bool bEnded = false;
	double Clock = 0;   // seconds since the start of the dance
	double Fps = 60;
	int64 Published = 0;
	int64 Late = 0;
};
