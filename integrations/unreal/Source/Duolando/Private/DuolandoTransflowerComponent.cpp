#include "DuolandoTransflowerComponent.h"

#include "DuolandoLog.h"
#include "DuolandoModelFile.h"
#include "DuolandoRunner.h"

#include <cmath>

namespace
{
// Audio rows the component queues for the worker beyond the session's own
// buffer (the preset's input_buffer_rows; 25.6 s at 20 rows a second: one
// PushAudioRows takes at most that many), and frames made ahead of
// TryPullFrame (1 s at 20 fps).
const size_t QueueRows = 512;
const size_t FramesAhead = 20;
}

UDuolandoTransflowerComponent::UDuolandoTransflowerComponent()
	: Info(std::make_unique<duo_transflower_info>())
{
	PrimaryComponentTick.bCanEverTick = false;   // the caller takes frames; nothing to tick
	*Info = duo_transflower_info{};
}

UDuolandoTransflowerComponent::~UDuolandoTransflowerComponent()
{
	Runner.reset();   // joins the worker, frees the session (both NULL after EndPlay)
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
	UE_LOG(LogDuolando, Error, TEXT("Duolando: %s: %s (%s)"), Call, UTF8_TO_TCHAR(duo_result_name(Result)), *DuolandoLastError());
	return false;
}

bool UDuolandoTransflowerComponent::Refuse(int32 Result, const FString& Why)
{
	LastResult = Result;
	UE_LOG(LogDuolando, Error, TEXT("Duolando: %s (%s)"), *Why, UTF8_TO_TCHAR(duo_result_name(Result)));
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
		Ok = Refuse(DUO_INVALID_ARGUMENT, FString::Printf(TEXT("SeedMotion has %d floats: the model needs %u rows x %u features"), SeedMotion.Num(), Sizes.seed_rows, Sizes.channels));
	if (Ok && Labels.Num() != static_cast<int32>(Sizes.labels))
		Ok = Refuse(DUO_INVALID_ARGUMENT, FString::Printf(TEXT("Labels has %d values: the model takes %u"), Labels.Num(), Sizes.labels));
	if (Ok && NoiseTrack.Num() % static_cast<int32>(Sizes.noise_floats) != 0)
		Ok = Refuse(DUO_INVALID_ARGUMENT, FString::Printf(TEXT("NoiseTrack has %d floats: whole samples of %u are needed"), NoiseTrack.Num(), Sizes.noise_floats));
	if (Ok)
	{
		Config.rng_seed = static_cast<uint64_t>(RngSeed);
		// Labels as the ABI takes them (uint32; a negative value becomes one above label_values: refused).
		TArray<uint32> LabelValues;
		LabelValues.SetNum(Labels.Num());
		for (int32 i = 0; i < Labels.Num(); ++i)
			LabelValues[i] = static_cast<uint32>(Labels[i]);
		// The seed motion, labels and noise track are copied: the properties may change afterwards.
		Runner = std::make_unique<duolando::TransflowerRunner>(Model, Config, SeedMotion.GetData(), static_cast<size_t>(SeedMotion.Num()),
			LabelValues.Num() > 0 ? LabelValues.GetData() : nullptr, static_cast<size_t>(LabelValues.Num()),
			NoiseTrack.Num() > 0 ? NoiseTrack.GetData() : nullptr, static_cast<size_t>(NoiseTrack.Num()), QueueRows, FramesAhead);
		Ok = Record(Runner->Status(), TEXT("duo_transflower_session_new"));
	}
	if (!Ok)
	{
		Runner.reset();
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
	Runner.reset();   // joins the worker (at most the step in flight), frees the session
	duo_model_free(Model);   // (order does not matter: sessions hold a model reference)
	Model = nullptr;
	*Info = duo_transflower_info{};
	Super::EndPlay(Reason);
}

// A call without a session: answered as the library answers a NULL session, and logged.
#define DUOLANDO_NEED_RUNNER(Call)                                                             \
	if (!Runner)                                                                               \
	{                                                                                          \
		LastResult = DUO_NULL_PARAMETER;                                                       \
		UE_LOG(LogDuolando, Error, TEXT("Duolando: %s: no session (BeginPlay failed)"), Call); \
		return false;                                                                          \
	}

bool UDuolandoTransflowerComponent::PushAudioRows(const TArray<float>& Rows)
{
	DUOLANDO_NEED_RUNNER(TEXT("PushAudioRows"));
	// Checked here, as the session would (its refusals come back from the worker too late to answer).
	const int32 Features = AudioFeatures();
	if (Rows.Num() == 0 || Rows.Num() % Features != 0)
		return Refuse(DUO_INVALID_ARGUMENT, FString::Printf(TEXT("PushAudioRows: %d floats: whole rows of %d features are needed"), Rows.Num(), Features));
	for (int32 i = 0; i < Rows.Num(); ++i)
		if (!std::isfinite(Rows[i]) || std::fabs(Rows[i]) > DUO_MAX_MUSIC_FEATURE)
			return Refuse(DUO_NON_FINITE_INPUT, FString::Printf(TEXT("PushAudioRows: row %d, feature %d is not finite or above DUO_MAX_MUSIC_FEATURE"), i / Features, i % Features));
	const size_t N = static_cast<size_t>(Rows.Num() / Features);
	if (Runner->RowRoom() < N)   // only the worker takes rows out: the room cannot shrink before SubmitAudio
		return Refuse(DUO_BACKLOG, FString::Printf(TEXT("PushAudioRows: %d rows: the queue is full (take frames with TryPullFrame first)"), static_cast<int32>(N)));
	Runner->SubmitAudio(Rows.GetData(), N);
	LastResult = DUO_OK;
	return true;
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
	DUOLANDO_NEED_RUNNER(TEXT("TryPullFrame"));
	uint64_t Index = 0;   // Frame (Channels() floats) is written only when a frame is taken
	if (Runner->Take(Frame.GetData(), &Index, 1) == 1)
	{
		LastResult = DUO_OK;
		return Publish(Index);
	}
	const duo_result Error = Runner->WorkerError();
	if (Error == DUO_OK)
	{
		LastResult = DUO_NOT_READY;   // not a failure: push more audio, or its step still runs
		return false;
	}
	if (LastResult != Error)   // logged once
		UE_LOG(LogDuolando, Error, TEXT("Duolando: the Transflower worker stopped: %s"), UTF8_TO_TCHAR(duo_result_name(Error)));
	LastResult = Error;
	return false;
}

bool UDuolandoTransflowerComponent::ResetSession(int64 Seed)
{
	DUOLANDO_NEED_RUNNER(TEXT("ResetSession"));
	Runner->Reset(static_cast<uint64_t>(Seed));
	LastResult = DUO_OK;
	FrameIndex = -1;
	return true;
}

#undef DUOLANDO_NEED_RUNNER
