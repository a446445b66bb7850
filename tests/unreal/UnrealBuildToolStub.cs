// TEST STUB — NOT UNREAL BUILD TOOL. The few UnrealBuildTool types the
// plugin's *.Build.cs files use, so CI (.ci/ffi.sh) can compile the rules
// with Mono's C# compiler and evaluate them per platform
// (tests/unreal/test_build_rules.cs). Real UBT has many more members and
// computes ModuleDirectory itself; here the test sets it. Never ship.
using System.Collections.Generic;

namespace UnrealBuildTool
{
    public enum ModuleType { CPlusPlus, External }
    public enum PCHUsageMode { Default, NoPCHs, NoSharedPCHs, UseSharedPCHs, UseExplicitOrSharedPCHs }
    public enum CppStandardVersion { Default, Cpp14, Cpp17, Cpp20, Latest }

    public struct UnrealTargetPlatform
    {
        readonly string name;
        UnrealTargetPlatform(string name) { this.name = name; }
        public static readonly UnrealTargetPlatform Win64 = new UnrealTargetPlatform("Win64");
        public static readonly UnrealTargetPlatform Linux = new UnrealTargetPlatform("Linux");
        public static readonly UnrealTargetPlatform Mac = new UnrealTargetPlatform("Mac");
        public static readonly UnrealTargetPlatform Android = new UnrealTargetPlatform("Android");
        public static readonly UnrealTargetPlatform IOS = new UnrealTargetPlatform("IOS");
        public static bool operator ==(UnrealTargetPlatform a, UnrealTargetPlatform b) { return a.name == b.name; }
        public static bool operator !=(UnrealTargetPlatform a, UnrealTargetPlatform b) { return a.name != b.name; }
        public override bool Equals(object o) { return o is UnrealTargetPlatform && ((UnrealTargetPlatform)o).name == name; }
        public override int GetHashCode() { return name.GetHashCode(); }
        public override string ToString() { return name; }
    }

    public class ReadOnlyTargetRules
    {
        public UnrealTargetPlatform Platform;
        public ReadOnlyTargetRules(UnrealTargetPlatform platform) { Platform = platform; }
    }

    public class RuntimeDependencyList
    {
        public readonly List<KeyValuePair<string, string>> Items = new List<KeyValuePair<string, string>>();
        public void Add(string path) { Items.Add(new KeyValuePair<string, string>(path, null)); }
        public void Add(string path, string sourcePath) { Items.Add(new KeyValuePair<string, string>(path, sourcePath)); }
    }

    public class ModuleRules
    {
        public static string StubModuleDirectory = "";   // stub: set by the test
        public ModuleRules(ReadOnlyTargetRules target) { Target = target; }
        public readonly ReadOnlyTargetRules Target;
        public string ModuleDirectory { get { return StubModuleDirectory; } }
        public ModuleType Type = ModuleType.CPlusPlus;
        public PCHUsageMode PCHUsage = PCHUsageMode.Default;
        public CppStandardVersion CppStandard = CppStandardVersion.Default;
        public readonly List<string> PublicDependencyModuleNames = new List<string>();
        public readonly List<string> PrivateDependencyModuleNames = new List<string>();
        public readonly List<string> PublicIncludePaths = new List<string>();
        public readonly List<string> PublicSystemIncludePaths = new List<string>();
        public readonly List<string> PublicAdditionalLibraries = new List<string>();
        public readonly List<string> PublicSystemLibraries = new List<string>();
        public readonly List<string> PublicDelayLoadDLLs = new List<string>();
        public readonly RuntimeDependencyList RuntimeDependencies = new RuntimeDependencyList();
    }
}
