// The prebuilt C library (crate duolando-ffi) as an Unreal "External"
// module: the header and one static library per platform, laid out as
//   include/duolando.h
//   lib/Win64/duolando.lib                 (x86_64-pc-windows-msvc)
//   lib/Linux/libduolando.a                (x86_64-unknown-linux-gnu)
//   lib/Mac/libduolando.a                  (aarch64/x86_64-apple-darwin, lipo)
//   lib/Android/arm64-v8a/libduolando.a    (aarch64-linux-android, NDK)
// See README.md for the cargo commands that produce them.
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
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Win64", "duolando.lib"));
			// Native libraries a Rust staticlib needs on Windows.
			PublicSystemLibraries.AddRange(new string[] { "ws2_32.lib", "userenv.lib", "bcrypt.lib", "ntdll.lib", "advapi32.lib" });
		}
		else if (Target.Platform == UnrealTargetPlatform.Linux)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Linux", "libduolando.a"));
			PublicSystemLibraries.AddRange(new string[] { "pthread", "dl", "m" });
		}
		else if (Target.Platform == UnrealTargetPlatform.Mac)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Mac", "libduolando.a"));
		}
		else if (Target.Platform == UnrealTargetPlatform.Android)
		{
			PublicAdditionalLibraries.Add(Path.Combine(Lib, "Android", "arm64-v8a", "libduolando.a"));
			PublicSystemLibraries.AddRange(new string[] { "dl", "m", "log" });
		}
	}
}
