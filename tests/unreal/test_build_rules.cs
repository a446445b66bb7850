// Evaluates the Unreal plugin's build rules (Duolando.Build.cs,
// DuolandoLibrary.Build.cs, compiled unchanged against the TEST STUB
// tests/unreal/UnrealBuildToolStub.cs) for each platform the .uplugin
// allows, and checks what each would link and stage: desktop links the
// shared library and stages it with RuntimeDependencies into
// $(BinaryOutputDir); Android and iOS link the static archive and stage
// nothing; every file lies under the module's lib/<Platform>/ folder with
// the names .ci/c_library.sh produces.
// Usage: mono test_build_rules.exe <plugin Source/ThirdParty/DuolandoLibrary dir>
using System;
using System.Linq;
using UnrealBuildTool;

static class TestBuildRules
{
    static int failures;
    static void Check(bool ok, string what) { if (!ok) { failures++; Console.Error.WriteLine("FAIL: " + what); } }

    static int Main(string[] args)
    {
        string dir = args[0].TrimEnd('/');
        ModuleRules.StubModuleDirectory = dir;
        var platforms = new[] { UnrealTargetPlatform.Win64, UnrealTargetPlatform.Linux, UnrealTargetPlatform.Mac,
                                UnrealTargetPlatform.Android, UnrealTargetPlatform.IOS };
        string[] shared = { "duolando.dll", "libduolando.so", "libduolando.dylib" };
        foreach (var p in platforms)
        {
            var t = new ReadOnlyTargetRules(p);
            var lib = new DuolandoLibrary(t);
            var mod = new Duolando(t);
            Check(lib.Type == ModuleType.External, p + ": DuolandoLibrary is External");
            Check(lib.PublicSystemIncludePaths.Contains(dir + "/include"), p + ": include/ on the include path");
            Check(mod.PublicDependencyModuleNames.Contains("DuolandoLibrary"), p + ": Duolando depends on DuolandoLibrary");
            Check(lib.PublicAdditionalLibraries.Count == 1, p + ": one library linked");
            foreach (string l in lib.PublicAdditionalLibraries)
                Check(l.StartsWith(dir + "/lib/" + (p == UnrealTargetPlatform.Android ? "Android/arm64-v8a" : p.ToString()) + "/"), p + ": " + l + " under lib/<Platform>/");
            bool desktop = p == UnrealTargetPlatform.Win64 || p == UnrealTargetPlatform.Linux || p == UnrealTargetPlatform.Mac;
            var deps = lib.RuntimeDependencies.Items;
            if (desktop)
            {
                Check(deps.Count == 1, p + ": one runtime dependency staged");
                foreach (var d in deps)
                {
                    string file = d.Key.Substring(d.Key.LastIndexOf('/') + 1);
                    Check(d.Key.StartsWith("$(BinaryOutputDir)/"), p + ": staged next to the module binaries");
                    Check(shared.Contains(file) && d.Value != null && d.Value.EndsWith("/" + file) && d.Value.StartsWith(dir + "/lib/"), p + ": staged from lib/: " + d.Value);
                }
            }
            else
            {
                Check(deps.Count == 0, p + ": nothing to stage (static)");
                Check(lib.PublicAdditionalLibraries.All(l => l.EndsWith("/libduolando.a")), p + ": static archive");
            }
            Check((p == UnrealTargetPlatform.Win64) == lib.PublicDelayLoadDLLs.Contains("duolando.dll"), p + ": delay-load on Windows only");
            Console.WriteLine(p + ": link " + string.Join(" ", lib.PublicAdditionalLibraries.Select(l => l.Substring(dir.Length + 1)))
                              + (lib.PublicSystemLibraries.Count > 0 ? " -l" + string.Join(" -l", lib.PublicSystemLibraries) : "")
                              + (deps.Count > 0 ? "; stage " + string.Join(" ", deps.Select(d => d.Key)) : ""));
        }
        if (failures == 0) Console.WriteLine("test_build_rules: all checks passed");
        return failures == 0 ? 0 : 1;
    }
}
