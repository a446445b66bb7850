using UnrealBuildTool;

// Runtime module: UDuolandoFollowerComponent, UDuolandoSoloDancerComponent,
// UDuolandoTransflowerComponent, the session runner
// (Public/DuolandoRunner.h) and the module that loads the library.
// The library itself is the External module DuolandoLibrary
// (Source/ThirdParty/DuolandoLibrary: header, per-platform binaries,
// RuntimeDependencies).
public class Duolando : ModuleRules
{
	public Duolando(ReadOnlyTargetRules Target) : base(Target)
	{
		PCHUsage = PCHUsageMode.UseExplicitOrSharedPCHs;
		CppStandard = CppStandardVersion.Cpp17;
		PublicDependencyModuleNames.AddRange(new string[] { "Core", "CoreUObject", "Engine", "DuolandoLibrary" });
		PrivateDependencyModuleNames.AddRange(new string[] { "Projects" });   // IPluginManager: the plugin's Binaries folder
	}
}
