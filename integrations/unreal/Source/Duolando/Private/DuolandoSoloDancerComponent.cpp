#include "DuolandoSoloDancerComponent.h"

#include "DuolandoLog.h"
#include "DuolandoModelFile.h"
#include "DuolandoRunner.h"

UDuolandoSoloDancerComponent::UDuolandoSoloDancerComponent()
{
	PrimaryComponentTick.bCanEverTick = true;
}

UDuolandoSoloDancerComponent::~UDuolandoSoloDancerComponent() = default;

void UDuolandoSoloDancerComponent::BeginPlay()
{
	Super::BeginPlay();
	DancerPositions.SetNum(DUO_BAILANDO_JOINTS);
	Model = DuolandoOpenModel(ModelFile.FilePath);
	if (!Model)
		return;
	duo_model_info Info;
	if (duo_model_get_info(Model, &Info) != DUO_OK || Info.family != DUO_FAMILY_BAILANDO)
	{
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s is not a solo (Bailando) model: use UDuolandoFollowerComponent (Duolando) or UDuolandoTransflowerComponent (Transflower)"), *ModelFile.FilePath);
		duo_model_free(Model);
		Model = nullptr;
		return;
	}
	if (MusicRows.Num() == 0 || MusicRows.Num() % static_cast<int32>(Info.music_features) != 0)
	{
		UE_LOG(LogDuolando, Error, TEXT("Duolando: MusicRows has %d floats: whole rows of %u features are needed"), MusicRows.Num(), Info.music_features);
		return;
	}
	Fps = Info.fps;
	Pending = std::make_unique<duolando::SoloFrame>();
	StartRunner();
}

bool UDuolandoSoloDancerComponent::StartRunner()
{
	Runner.reset();
	bHasPending = false;
	bEnded = false;
	Clock = 0;
	if (!Model)
		return false;
	duo_session_config Config;
	if (duo_session_config_preset(Model, TCHAR_TO_UTF8(*Preset), &Config) != DUO_OK)
	{
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s"), *DuolandoLastError());
		return false;
	}
	uint32_t Seed[2] = {0, 0};
	for (int32 i = 0; i < 2 && i < SeedTokens.Num(); ++i)
		Seed[i] = static_cast<uint32_t>(SeedTokens[i]);
	// The rows are copied into the session: MusicRows may change afterwards.
	Runner = std::make_unique<duolando::SoloRunner>(Model, Config, Seed, MusicRows.GetData(), static_cast<size_t>(MusicRows.Num()));
	if (Runner->Status() != DUO_OK)
	{
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s"), *DuolandoLastError());
		Runner.reset();
		return false;
	}
	Runner->Finish();   // the whole track is in: dance to its end
	return true;
}

void UDuolandoSoloDancerComponent::Restart()
{
	StartRunner();
}

void UDuolandoSoloDancerComponent::EndPlay(const EEndPlayReason::Type Reason)
{
	Runner.reset();          // joins the worker, frees the session
	duo_model_free(Model);   // (order does not matter: sessions hold a reference)
	Model = nullptr;
	Super::EndPlay(Reason);
}

void UDuolandoSoloDancerComponent::TickComponent(float DeltaTime, ELevelTick TickType, FActorComponentTickFunction* ThisTickFunction)
{
	Super::TickComponent(DeltaTime, TickType, ThisTickFunction);
	if (!Runner || bEnded)
		return;
	Clock += DeltaTime;
	for (;;)
	{
		if (!bHasPending)
		{
			const bool Ended = Runner->Ended();   // before Take: a frame made before it is taken now
			bHasPending = Runner->Take(Pending.get(), 1) == 1;
			if (!bHasPending)
			{
				if (Ended)
				{
					bEnded = true;
					if (Runner->WorkerError() != DUO_OK)
						UE_LOG(LogDuolando, Error, TEXT("Duolando: the solo dancer stopped (%s)"), UTF8_TO_TCHAR(duo_result_name(Runner->WorkerError())));
				}
				return;   // not computed yet: published when it is (LateFrames)
			}
		}
		duolando::SoloFrame& F = *Pending;
		if (static_cast<double>(F.index) / Fps > Clock)
			return;   // not due yet
		for (int32 j = 0; j < DUO_BAILANDO_JOINTS; ++j)
		{
			duo_vec3 P = duo_vec3_to_unreal(duo_vec3{F.positions[3 * j], F.positions[3 * j + 1], F.positions[3 * j + 2]});
			DancerPositions[j] = FVector(P.x, P.y, P.z);
		}
		bHasPending = false;
		if (Clock - static_cast<double>(F.index) / Fps > 1.0 / Fps)
			++Late;
		++Published;
		OnDancerFrame.Broadcast(static_cast<int64>(F.index));
	}
}
