// Opening a .duo model and reading the library's last error, shared by the
// Duolando components.
#pragma once

#include "CoreMinimal.h"
#include "DuolandoLog.h"
#include "Misc/FileHelper.h"
#include "Misc/Paths.h"

#include "duolando.h"

// This thread's last library error message.
inline FString DuolandoLastError()
{
	char Buf[512];
	duo_last_error_message(Buf, sizeof Buf);
	return UTF8_TO_TCHAR(Buf);
}

// Memory-mapped when the model is a plain file, else read through Unreal's
// file system (pak, APK) and copied into native memory. Relative paths are
// under the project's Content folder. Logs and returns nullptr on failure;
// OutResult (optional): the library's last answer (DUO_OK on success).
inline duo_model* DuolandoOpenModel(const FString& File, duo_result* OutResult = nullptr)
{
	duo_result Unused = DUO_OK;
	duo_result& Result = OutResult ? *OutResult : Unused;
	FString Path = File;
	if (FPaths::IsRelative(Path))
		Path = FPaths::Combine(FPaths::ProjectContentDir(), Path);
	duo_model* Opened = nullptr;
	if ((Result = duo_model_open_file(TCHAR_TO_UTF8(*Path), &Opened)) == DUO_OK)
		return Opened;
	FString Reason = DuolandoLastError();
	TArray<uint8> Bytes;
	if (FFileHelper::LoadFileToArray(Bytes, *Path))
	{
		if ((Result = duo_model_open_copy(Bytes.GetData(), static_cast<size_t>(Bytes.Num()), &Opened)) == DUO_OK)
			return Opened;
		Reason = DuolandoLastError();
	}
	UE_LOG(LogDuolando, Error, TEXT("Duolando: cannot open the model %s: %s"), *Path, *Reason);
	return nullptr;
}
