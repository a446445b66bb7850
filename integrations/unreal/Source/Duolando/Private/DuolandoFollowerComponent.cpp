#include "DuolandoFollowerComponent.h"

#include "DuolandoLog.h"
#include "DuolandoModelFile.h"
#include "DuolandoRunner.h"

UDuolandoFollowerComponent::UDuolandoFollowerComponent()
{
	PrimaryComponentTick.bCanEverTick = true;
}

UDuolandoFollowerComponent::~UDuolandoFollowerComponent() = default;

void UDuolandoFollowerComponent::BeginPlay()
{
	Super::BeginPlay();
	Model = DuolandoOpenModel(ModelFile.FilePath);
	if (!Model)
		return;
	duo_model_info Info;
	if (duo_model_get_info(Model, &Info) != DUO_OK || Info.family != DUO_FAMILY_DUOLANDO)
	{
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s is not a follower (Duolando) model: use UDuolandoSoloDancerComponent (Bailando) or UDuolandoTransflowerComponent (Transflower)"), *ModelFile.FilePath);
		duo_model_free(Model);
		Model = nullptr;
		return;
	}
	duo_session_config Config;
	if (bLowLatency)
		duo_session_config_minimum(Model, &Config);
	else
		duo_session_config_reference(Model, &Config);
	uint32_t Seed[5] = {0, 0, 0, 0, 0};
	for (int32 i = 0; i < 5 && i < SeedTokens.Num(); ++i)
		Seed[i] = static_cast<uint32_t>(SeedTokens[i]);
	// MusicFeatures is borrowed by the session: it must not change while the runner lives.
	const float* Music = MusicFeatures.Num() > 0 ? MusicFeatures.GetData() : nullptr;
	Runner = std::make_unique<duolando::SessionRunner>(Model, Config, Seed, Music, static_cast<size_t>(MusicFeatures.Num()));
	if (Runner->Status() != DUO_OK)
	{
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s"), *DuolandoLastError());
		Runner.reset();
	}
	FollowerPositions.SetNum(DUO_JOINTS);
	FollowerLocalRotations.SetNum(DUO_JOINTS);
}

void UDuolandoFollowerComponent::EndPlay(const EEndPlayReason::Type Reason)
{
	Runner.reset();          // joins the worker, frees the session
	duo_model_free(Model);   // (order does not matter: sessions hold a reference)
	Model = nullptr;
	Super::EndPlay(Reason);
}

void UDuolandoFollowerComponent::SubmitLeaderPose(const TArray<FVector>& JointsWorld)
{
	if (!Runner || JointsWorld.Num() != DUO_JOINTS)
		return;
	duo_leader_frame Frame;
	for (int32 j = 0; j < DUO_JOINTS; ++j)
	{
		Frame.joints[j] = {static_cast<float>(JointsWorld[j].X), static_cast<float>(JointsWorld[j].Y), static_cast<float>(JointsWorld[j].Z)};
	}
	duo_leader_frame_convert(&Frame, DUO_COORDS_UNREAL);  // -> SMPL-X metres
	if (!Runner->Submit(Frame))
		++Dropped;   // the input ring overwrote its oldest pose
}

void UDuolandoFollowerComponent::TickComponent(float DeltaTime, ELevelTick TickType, FActorComponentTickFunction* ThisTickFunction)
{
	Super::TickComponent(DeltaTime, TickType, ThisTickFunction);
	if (!Runner)
		return;
	// Drain everything ready; keep the newest (no allocation: a fixed stack buffer).
	duo_follower_frame Frames[4];
	size_t N;
	while ((N = Runner->Take(Frames, 4)) > 0)
	{
		duo_follower_frame& F = Frames[N - 1];
		duo_follower_frame_convert(&F, DUO_COORDS_UNREAL);
		for (int32 j = 0; j < DUO_JOINTS; ++j)
		{
			FollowerPositions[j] = FVector(F.positions[j].x, F.positions[j].y, F.positions[j].z);
			FollowerLocalRotations[j] = FQuat(F.rotations[j].x, F.rotations[j].y, F.rotations[j].z, F.rotations[j].w);
		}
		FollowerRoot = FVector(F.root.x, F.root.y, F.root.z);
		++Published;
		OnFollowerFrame.Broadcast(static_cast<int64>(F.index));
	}
}
