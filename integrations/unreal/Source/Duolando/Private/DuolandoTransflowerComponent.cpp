#include "DuolandoTransflowerComponent.h"

#include "DuolandoLog.h"
#include "DuolandoModelFile.h"

UDuolandoTransflowerComponent::UDuolandoTransflowerComponent()
	: Info(std::make_unique<duo_transflower_info>())
{
	PrimaryComponentTick.bCanEverTick = false;   // the caller pulls frames; nothing to tick
	*Info = duo_transflower_info{};
}

UDuolandoTransflowerComponent::~UDuolandoTransflowerComponent()
{
	duo_session_free(Session);   // both NULL after EndPlay
	duo_model_free(Model);
}

int32 UDuolandoTransflowerComponent::Channels() const { return static_cast<int32>(Info->channels); }
int32 UDuolandoTransflowerComponent::SeedRows() const { return static_cast<int32>(Info->seed_rows); }
int32 UDuolandoTransflowerComponent::AudioFeatures() const { return static_cast<int32>(Info->audio_features); }
int32 UDuolandoTransflowerComponent::AudioWindow() const { return static_cast<int32>(Info->audio_window); }
int32 UDuolandoTransflowerComponent::NoiseFloats() const { return static_cast<int32>(Info->noise_floats); }
int32 UDuolandoTransflowerComponent::NumLabels() const { return static_cast<int32>(Info->labels); }
int32 UDuolandoTransflowerComponent::Fps() const { return static_cast<int32>(Info->fps); }
int32 UDuolandoTransflowerComponent::OutputTimeOffset() const { return static_cast<int32>(Info->output_time_offset); }
int32 UDuolandoTransflowerComponent::LookaheadRows() const { return Info->lookahead_rows; }

bool UDuolandoTransflowerComponent::Record(int32 Result, const TCHAR* Call)
{
	LastResult = Result;
	if (Result == DUO_OK)
		return true;
	if (Result != DUO_NOT_READY)   // not a failure: push more audio
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s: %s (%s)"), Call, UTF8_TO_TCHAR(duo_result_name(Result)), *DuolandoLastError());
	return false;
}

void UDuolandoTransflowerComponent::BeginPlay()
{
	Super::BeginPlay();
	duo_result Opened = DUO_OK;
	Model = DuolandoOpenModel(ModelFile.FilePath, &Opened);   // logs a failure
	LastResult = Opened;
	if (!Model)
		return;
	duo_model_info ModelInfo;
	if (duo_model_get_info(Model, &ModelInfo) != DUO_OK || ModelInfo.family != DUO_FAMILY_TRANSFLOWER)
	{
		LastResult = DUO_INVALID_ARGUMENT;
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s is not a Transflower model: use UDuolandoFollowerComponent (Duolando) or UDuolandoSoloDancerComponent (Bailando)"), *ModelFile.FilePath);
		duo_model_free(Model);
		Model = nullptr;
		return;
	}
	duo_transflower_info Sizes;
	duo_transflower_config Config;
	bool Ok = Record(duo_transflower_get_info(Model, &Sizes), TEXT("duo_transflower_get_info")) &&
		Record(duo_transflower_config_preset(Model, TCHAR_TO_UTF8(*Preset), &Config), TEXT("duo_transflower_config_preset"));
	if (Ok && SeedMotion.Num() != static_cast<int32>(Sizes.seed_rows * Sizes.channels))
	{
		LastResult = DUO_INVALID_ARGUMENT;
		UE_LOG(LogDuolando, Error, TEXT("Duolando: SeedMotion has %d floats: the model needs %u rows x %u features"), SeedMotion.Num(), Sizes.seed_rows, Sizes.channels);
		Ok = false;
	}
	if (Ok && Labels.Num() != static_cast<int32>(Sizes.labels))
	{
		LastResult = DUO_INVALID_ARGUMENT;
		UE_LOG(LogDuolando, Error, TEXT("Duolando: Labels has %d values: the model takes %u"), Labels.Num(), Sizes.labels);
		Ok = false;
	}
	if (Ok)
	{
		Config.rng_seed = static_cast<uint64_t>(RngSeed);
		// Labels as the ABI takes them (uint32; a negative value becomes one above label_values: refused).
		TArray<uint32> LabelValues;
		LabelValues.SetNum(Labels.Num());
		for (int32 i = 0; i < Labels.Num(); ++i)
			LabelValues[i] = static_cast<uint32>(Labels[i]);
		// The seed motion and labels are copied into the session.
		Ok = Record(duo_transflower_session_new(Model, &Config, SeedMotion.GetData(), static_cast<size_t>(SeedMotion.Num()),
						LabelValues.Num() > 0 ? LabelValues.GetData() : nullptr, static_cast<size_t>(LabelValues.Num()), &Session),
			TEXT("duo_transflower_session_new"));
	}
	if (!Ok)
	{
		duo_model_free(Model);
		Model = nullptr;
		return;
	}
	*Info = Sizes;
	Frame.SetNum(static_cast<int32>(Sizes.channels));
	FrameIndex = -1;
}

void UDuolandoTransflowerComponent::EndPlay(const EEndPlayReason::Type Reason)
{
	duo_session_free(Session);   // (order does not matter: sessions hold a model reference)
	Session = nullptr;
	duo_model_free(Model);
	Model = nullptr;
	*Info = duo_transflower_info{};
	Super::EndPlay(Reason);
}

// A call without a session: answered as the library answers a NULL session, and logged.
#define DUOLANDO_NEED_SESSION(Call)                                                            \
	if (!Session)                                                                              \
	{                                                                                          \
		LastResult = DUO_NULL_PARAMETER;                                                       \
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s: no session (BeginPlay failed)"), Call); \
		return false;                                                                          \
	}

bool UDuolandoTransflowerComponent::PushAudioRows(const TArray<float>& Rows)
{
	DUOLANDO_NEED_SESSION(TEXT("PushAudioRows"));
	return Record(duo_session_push_music(Session, Rows.GetData(), static_cast<size_t>(Rows.Num())), TEXT("duo_session_push_music"));
}

bool UDuolandoTransflowerComponent::PushInputRows(int32 InputIndex, const TArray<float>& Rows)
{
	DUOLANDO_NEED_SESSION(TEXT("PushInputRows"));
	return Record(duo_transflower_push_input(Session, static_cast<uint32_t>(InputIndex), Rows.GetData(), static_cast<size_t>(Rows.Num())),
		TEXT("duo_transflower_push_input"));
}

bool UDuolandoTransflowerComponent::Publish(uint64 Index)
{
	FrameIndex = static_cast<int64>(Index);
	++Pulled;
	OnFrame.Broadcast(FrameIndex);
	return true;
}

bool UDuolandoTransflowerComponent::TryPullFrame()
{
	DUOLANDO_NEED_SESSION(TEXT("TryPullFrame"));
	uint64_t Index = 0;   // Frame (Channels() floats) is written only on DUO_OK
	if (!Record(duo_transflower_pull_frame(Session, Frame.GetData(), static_cast<size_t>(Frame.Num()), &Index), TEXT("duo_transflower_pull_frame")))
		return false;
	return Publish(Index);
}

bool UDuolandoTransflowerComponent::TryPullFrameWithNoise(const TArray<float>& Noise)
{
	DUOLANDO_NEED_SESSION(TEXT("TryPullFrameWithNoise"));
	uint64_t Index = 0;
	if (!Record(duo_transflower_pull_frame_with_noise(Session, Noise.GetData(), static_cast<size_t>(Noise.Num()), Frame.GetData(),
					static_cast<size_t>(Frame.Num()), &Index),
			TEXT("duo_transflower_pull_frame_with_noise")))
		return false;
	return Publish(Index);
}

bool UDuolandoTransflowerComponent::ResetSession(int64 Seed)
{
	DUOLANDO_NEED_SESSION(TEXT("ResetSession"));
	if (!Record(duo_transflower_session_reset(Session, static_cast<uint64_t>(Seed)), TEXT("duo_transflower_session_reset")))
		return false;
	FrameIndex = -1;
	return true;
}

#undef DUOLANDO_NEED_SESSION
