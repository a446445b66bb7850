#include "DuolandoFollowerComponent.h"

#include "DuolandoLog.h"
#include "DuolandoRunner.h"
#include "Misc/FileHelper.h"
#include "Misc/Paths.h"

static FString LastError()
{
	char Buf[512];
	duo_last_error_message(Buf, sizeof Buf);
	return UTF8_TO_TCHAR(Buf);
}

// Memory-mapped when the model is a plain file, else read through Unreal's
// file system (pak, APK) and copied into native memory.
static duo_model* OpenModel(const FString& File)
{
	FString Path = File;
	if (FPaths::IsRelative(Path))
		Path = FPaths::Combine(FPaths::ProjectContentDir(), Path);
	duo_model* Opened = nullptr;
	if (duo_model_open_file(TCHAR_TO_UTF8(*Path), &Opened) == DUO_OK)
		return Opened;
	FString Reason = LastError();
	TArray<uint8> Bytes;
	if (FFileHelper::LoadFileToArray(Bytes, *Path))
	{
		if (duo_model_open_copy(Bytes.GetData(), static_cast<size_t>(Bytes.Num()), &Opened) == DUO_OK)
			return Opened;
		Reason = LastError();
	}
	UE_LOG(LogDuolando, Error, TEXT("Duolando: cannot open the model %s: %s"), *Path, *Reason);
	return nullptr;
}

UDuolandoFollowerComponent::UDuolandoFollowerComponent()
{
	PrimaryComponentTick.bCanEverTick = true;
}

UDuolandoFollowerComponent::~UDuolandoFollowerComponent() = default;

void UDuolandoFollowerComponent::BeginPlay()
{
	Super::BeginPlay();
	Model = OpenModel(ModelFile.FilePath);
	if (!Model)
		return;
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
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s"), *LastError());
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
