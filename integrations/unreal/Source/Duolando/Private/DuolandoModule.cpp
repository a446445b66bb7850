// The Duolando runtime module. On Windows the library is delay-loaded
// (DuolandoLibrary.Build.cs): StartupModule loads duolando.dll from the
// plugin's Binaries/Win64 folder (editor, RuntimeDependencies staged it
// there), falling back to the default DLL search (a packaged game has it
// next to its executable). Elsewhere the loader resolves it (Linux/Mac:
// staged next to the module binary) or it is linked in (Android, iOS).
#include "DuolandoLog.h"
#include "HAL/PlatformProcess.h"
#include "Interfaces/IPluginManager.h"
#include "Misc/Paths.h"
#include "Modules/ModuleManager.h"

#include "duolando.h"

DEFINE_LOG_CATEGORY(LogDuolando);

class FDuolandoModule : public IModuleInterface
{
public:
	virtual void StartupModule() override
	{
#if PLATFORM_WINDOWS
		TSharedPtr<IPlugin> Plugin = IPluginManager::Get().FindPlugin(TEXT("Duolando"));
		if (Plugin.IsValid())
		{
			const FString Dll = FPaths::Combine(Plugin->GetBaseDir(), TEXT("Binaries/Win64/duolando.dll"));
			Handle = FPlatformProcess::GetDllHandle(*Dll);
		}
		if (!Handle)
			Handle = FPlatformProcess::GetDllHandle(TEXT("duolando.dll"));
		if (!Handle)
		{
			UE_LOG(LogDuolando, Error, TEXT("Duolando: duolando.dll not found (plugin Binaries/Win64 or next to the executable)"));
			return;
		}
#endif
		UE_LOG(LogDuolando, Log, TEXT("Duolando: libduolando %s"), UTF8_TO_TCHAR(duo_version()));
	}

	virtual void ShutdownModule() override
	{
		if (Handle)
			FPlatformProcess::FreeDllHandle(Handle);
		Handle = nullptr;
	}

private:
	void* Handle = nullptr;
};

IMPLEMENT_MODULE(FDuolandoModule, Duolando)
