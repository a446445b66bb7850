// UDuolandoFollowerComponent: one generated follower dancer.
//
// The game thread hands in the leader's 55 SMPL-X joints every frame (in
// Unreal world coordinates: centimetres, z up) with SubmitLeaderPose; a
// worker thread (duolando::SessionRunner) runs the session; each tick the
// component publishes the newest follower pose in Unreal coordinates.
// Nothing here blocks the game thread on inference.
#pragma once

#include "Components/ActorComponent.h"
#include "CoreMinimal.h"

#include <memory>

#include "DuolandoFollowerComponent.generated.h"

namespace duolando { class SessionRunner; }
struct duo_model;

DECLARE_DYNAMIC_MULTICAST_DELEGATE_OneParam(FDuolandoFollowerFrameSignature, int64, FrameIndex);

UCLASS(ClassGroup = (Animation), meta = (BlueprintSpawnableComponent))
class DUOLANDO_API UDuolandoFollowerComponent : public UActorComponent
{
	GENERATED_BODY()

public:
	UDuolandoFollowerComponent();
	~UDuolandoFollowerComponent();   // out of line: SessionRunner is incomplete here

	/** The .duo model file: absolute, or relative to the project's Content folder. A plain file
	 *  (editor; packaged: "Additional Non-Asset Directories to Copy") is memory-mapped and its pages
	 *  shared by every component opening it; otherwise (a .pak, an APK) it is read through Unreal's
	 *  file system into one native copy. */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	FFilePath ModelFile;

	/** Music features of the track (frames x 54, 30 fps; `duolando features` computes them offline). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<float> MusicFeatures;

	/** Follower start tokens (up, down, lhand, rhand, transl). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	TArray<int32> SeedTokens = {0, 0, 0, 0, 0};

	/** true: lowest latency (0 frames); false: the reference budget (seconds of delay, best quality). */
	UPROPERTY(EditAnywhere, Category = "Duolando")
	bool bLowLatency = true;

	/** Newest follower pose, Unreal world coordinates (cm); rotations are local, in SMPL-X rest axes converted to Unreal. */
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	TArray<FVector> FollowerPositions;
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	TArray<FQuat> FollowerLocalRotations;
	UPROPERTY(BlueprintReadOnly, Category = "Duolando")
	FVector FollowerRoot = FVector::ZeroVector;

	UPROPERTY(BlueprintAssignable, Category = "Duolando")
	FDuolandoFollowerFrameSignature OnFollowerFrame;

	/** Game thread: the leader's 55 joints this frame (Unreal world coordinates, cm). Call at 30 Hz. */
	UFUNCTION(BlueprintCallable, Category = "Duolando")
	void SubmitLeaderPose(const TArray<FVector>& JointsWorld);

	virtual void BeginPlay() override;
	virtual void EndPlay(const EEndPlayReason::Type Reason) override;
	virtual void TickComponent(float DeltaTime, ELevelTick TickType, FActorComponentTickFunction* ThisTickFunction) override;

	/** Follower frames published so far (OnFollowerFrame broadcasts). */
	int64 FramesPublished() const { return Published; }
	/** Leader poses dropped because the worker fell more than 64 frames behind (oldest first). */
	int64 DroppedLeaderFrames() const { return Dropped; }
	/** True between a successful BeginPlay and EndPlay. */
	bool IsRunning() const { return Runner != nullptr; }

private:
	duo_model* Model = nullptr;
	std::unique_ptr<duolando::SessionRunner> Runner;
	int64 Published = 0;
	int64 Dropped = 0;
};
