// The prebuilt C library (crate duolando-ffi) as an Unreal "External"
// module. Lay the files out as
//   include/duolando.h                       (copy of include/duolando.h)
//   lib/Win64/duolando.dll, duolando.dll.lib (x86_64-pc-windows-msvc cdylib)
//   lib/Linux/libduolando.so                 (x86_64-unknown-linux-gnu cdylib, SONAME libduolando.so)
//   lib/Mac/libduolando.dylib                (aarch64/x86_64-apple-darwin cdylib, lipo; install name @rpath/libduolando.dylib)
//   lib/Android/arm64-v8a/libduolando.a      (aarch64-linux-android staticlib)
//   lib/IOS/libduolando.a                    (aarch64-apple-ios staticlib)
// (README.md: the commands that produce them; .ci/c_library.sh builds and
// strips each; docs/PLATFORMS.md: which of them CI builds.)
//
// Desktop: the shared library is linked and staged next to the module's
// binaries with RuntimeDependencies, so editor builds and packaged games
// find it at run time (Windows: delay-loaded, FDuolandoModule::StartupModule
// loads it from the plugin's Binaries folder first).
// Android and iOS: the static archive is linked into the game, nothing to
// stage (no Android NDK in CI to link a libduolando.so, and iOS wants
// static code).
using System.IO;
using UnrealBuildTool;

public class DuolandoLibrary : ModuleRules
{
	public DuolandoLibrary(ReadOnlyTargetRules Target) : base(Target)
	{
		Type = ModuleType.External;
		PublicSystemIncludePaths.Add(Path.Combine(ModuleDirectory, "include"));
		string Lib = Path.Combine(ModuleDirectory, "lib");

		if (Target.Platform == UnrealTargetPlatform.Win64)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Win64", "duolando.dll.lib"));
			PublicDelayLoadDLLs.Add("duolando.dll");
			RuntimeDependencies.Add("$(BinaryOutputDir)/duolando.dll", Path.Combine(Lib, "Win64", "duolando.dll"));
		}
		else if (Target.Platform == UnrealTargetPlatform.Linux)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Linux", "libduolando.so"));
			RuntimeDependencies.Add("$(BinaryOutputDir)/libduolando.so", Path.Combine(Lib, "Linux", "libduolando.so"));
		}
		else if (Target.Platform == UnrealTargetPlatform.Mac)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Mac", "libduolando.dylib"));
			RuntimeDependencies.Add("$(BinaryOutputDir)/libduolando.dylib", Path.Combine(Lib, "Mac", "libduolando.dylib"));
		}
		else if (Target.Platform == UnrealTargetPlatform.Android)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Android", "arm64-v8a", "libduolando.a"));
			// rustc --print native-static-libs for aarch64-linux-android.
			PublicSystemLibraries.AddRange(new string[] { "dl", "log", "unwind", "m", "c" });
		}
		else if (Target.Platform == UnrealTargetPlatform.IOS)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "IOS", "libduolando.a"));
			// rustc --print native-static-libs for aarch64-apple-ios: -liconv -lSystem -lc -lm
			PublicSystemLibraries.Add("iconv");
		}
	}
}
