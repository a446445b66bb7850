#!/usr/bin/env bash
# The C ABI (issue #5): header vs exported symbols, header compiled as C99
# and C++17 (included twice), the C host test linked against the static and
# the dynamic library and run under valgrind; the engine integrations
# (issue #36 §6): the Unreal plugin's runners and Transflower step batch
# under valgrind and ThreadSanitizer, its module + components (follower,
# Bailando solo, Transflower) compiled against TEST STUB engine headers
# (tests/unreal/stub) and run against the library, its .uplugin checked and
# Build.cs rules compiled against a TEST STUB UnrealBuildTool and evaluated
# per platform; the Unity wrapper compiled and run under Mono, the Unity
# package layout checked, its runtime and sample compiled against a TEST
# STUB UnityEngine (tests/unity) and the sample run under Mono. None of this
# runs Unity or Unreal (docs/PLATFORMS.md). Opt-in with DUO_FFI_AARCH64=1:
# the debug C host test for aarch64 under qemu-user (.ci/cross.sh runs it
# against the shipped aarch64 library in CI). Debian/Ubuntu; installs
# valgrind, mono-mcs, python3, gcc-aarch64-linux-gnu and qemu-user when
# missing (root or sudo). The Rust tests of the crate run with
# `cargo test --workspace`. Honours CARGO_TARGET_DIR. Called by .ci/run.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
LIB=$TARGET/debug
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT

if ! command -v valgrind >/dev/null; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq valgrind
fi

echo "--- build libduolando (static + dynamic)"
# The workspace's libraries in the test profile, as `cargo test --workspace`
# builds them (same features): after that (.ci/run) nothing is rebuilt.
cargo build --profile test --workspace --lib
ls -la "$LIB/libduolando.a" "$LIB/libduolando.so"

echo "--- header functions == exported duo_* symbols"
# Comments stripped by the preprocessor, then every `duo_name(`.
gcc -fpreprocessed -dD -E -P include/duolando.h 2>/dev/null \
    | grep -oE '\bduo_[a-z0-9_]+[[:space:]]*\(' | sed -E 's/[[:space:]]*\($//' | sort -u > "$OUT/header.txt"
nm -D --defined-only "$LIB/libduolando.so" | awk '$2 == "T" && $3 ~ /^duo_/ {print $3}' | sort -u > "$OUT/dynamic.txt"
nm --defined-only "$LIB/libduolando.a" 2>/dev/null | awk '$2 == "T" && $3 ~ /^duo_/ {print $3}' | sort -u > "$OUT/static.txt"
diff -u "$OUT/header.txt" "$OUT/dynamic.txt" || { echo "include/duolando.h and libduolando.so disagree (above: - header only, + library only)"; exit 1; }
diff -u "$OUT/header.txt" "$OUT/static.txt" || { echo "include/duolando.h and libduolando.a disagree"; exit 1; }
echo "$(wc -l < "$OUT/header.txt") functions: $(tr '\n' ' ' < "$OUT/header.txt")"

echo "--- header as C99 and C++17, included twice"
gcc -std=c99 -Wall -Wextra -Werror -pedantic -Iinclude tests/c/header_c.c "$LIB/libduolando.a" -lpthread -lm -ldl -o "$OUT/header_c"
"$OUT/header_c"
g++ -std=c++17 -Wall -Wextra -Werror -pedantic -Iinclude tests/c/header_cpp.cpp "$LIB/libduolando.a" -lpthread -lm -ldl -o "$OUT/header_cpp"
"$OUT/header_cpp"

echo "--- C host test, static and dynamic"
CFLAGS="-std=c99 -Wall -Wextra -Werror -pedantic -g -Iinclude"
# Native libraries a Rust staticlib needs on Linux (rustc --print native-static-libs).
gcc $CFLAGS tests/c/test_duolando.c "$LIB/libduolando.a" -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc -o "$OUT/test_static"
gcc $CFLAGS tests/c/test_duolando.c -L"$LIB" -lduolando -lpthread -lm -Wl,-rpath,"$LIB" -o "$OUT/test_dynamic"
# Captured first: `ldd | grep -q` under pipefail can fail by SIGPIPE (see .ci/size.sh).
test_ldd=$(ldd "$OUT/test_dynamic")
grep -q libduolando.so <<<"$test_ldd" || { echo "test_dynamic does not load libduolando.so:"; echo "$test_ldd"; exit 1; }
"$OUT/test_static" "$ROOT"

VALGRIND=(valgrind --error-exitcode=1 --leak-check=full --errors-for-leak-kinds=definite,indirect,possible --show-leak-kinds=definite,indirect,possible)
# valgrind runs one thread at a time (~3.5 min per run here): the two runs
# side by side, one per core, each log printed whole once both are done.
echo "--- valgrind: static and dynamic, side by side"
"${VALGRIND[@]}" "$OUT/test_static" "$ROOT" >"$OUT/valgrind_static.log" 2>&1 & vg_static=$!
"${VALGRIND[@]}" "$OUT/test_dynamic" "$ROOT" >"$OUT/valgrind_dynamic.log" 2>&1 & vg_dynamic=$!
rc_static=0; wait "$vg_static" || rc_static=$?
rc_dynamic=0; wait "$vg_dynamic" || rc_dynamic=$?
for kind in static dynamic; do echo "--- valgrind: $kind"; cat "$OUT/valgrind_$kind.log"; done
[ "$rc_static" -eq 0 ] && [ "$rc_dynamic" -eq 0 ] || { echo "valgrind: static exit $rc_static, dynamic exit $rc_dynamic"; exit 1; }

UE=integrations/unreal
UEMOD=$UE/Source/Duolando
echo "--- Unreal plugin: the engine-independent runners and step batch (C++17, threads) under valgrind and ThreadSanitizer"
RUNNER_TESTS="tests/c/test_runner.cpp tests/unreal/test_transflower_runner.cpp"
g++ -std=c++17 -Wall -Wextra -Werror -pedantic -g -Iinclude -I$UEMOD/Public \
    $RUNNER_TESTS -L"$LIB" -lduolando -lpthread -Wl,-rpath,"$LIB" -o "$OUT/test_runner"
"${VALGRIND[@]}" "$OUT/test_runner" "$ROOT" >"$OUT/valgrind_runner.log" 2>&1 & vg_runner=$!
# Memcheck sees no races: the runners' own C++ again, instrumented (the library is not),
# built and run while valgrind runs on the other core.
g++ -std=c++17 -Wall -Wextra -Werror -pedantic -g -O1 -fsanitize=thread -Iinclude -I$UEMOD/Public \
    $RUNNER_TESTS -L"$LIB" -lduolando -lpthread -Wl,-rpath,"$LIB" -o "$OUT/test_runner_tsan"
TSAN_OPTIONS=halt_on_error=1 "$OUT/test_runner_tsan" "$ROOT" > /dev/null
rc_runner=0; wait "$vg_runner" || rc_runner=$?
cat "$OUT/valgrind_runner.log"
[ "$rc_runner" -eq 0 ] || { echo "valgrind: runners exit $rc_runner"; exit 1; }

echo "--- Unreal plugin: module + component compiled against TEST STUB engine headers (tests/unreal/stub) and run"
# Not Unreal Engine: the stubs only let g++ check and run the plugin's own C++.
UEFLAGS="-std=c++17 -Wall -Wextra -Werror -g -DDUOLANDO_API= -Itests/unreal/stub -Iinclude -I$UEMOD/Public -I$UEMOD/Private"
g++ $UEFLAGS -fsyntax-only -DPLATFORM_WINDOWS=1 $UEMOD/Private/DuolandoModule.cpp   # the Windows DLL-loading branch
g++ $UEFLAGS tests/unreal/test_component.cpp tests/unreal/test_transflower_component.cpp \
    $UEMOD/Private/DuolandoFollowerComponent.cpp $UEMOD/Private/DuolandoSoloDancerComponent.cpp \
    $UEMOD/Private/DuolandoTransflowerComponent.cpp $UEMOD/Private/DuolandoModule.cpp \
    -L"$LIB" -lduolando -lpthread -Wl,-rpath,"$LIB" -o "$OUT/test_component"
"$OUT/test_component" "$ROOT"

# Mono's C# compiler and runtime (Unity wrapper, build rules), python3 (JSON checks).
if ! command -v mcs >/dev/null || ! command -v mono >/dev/null || ! command -v python3 >/dev/null; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq mono-mcs python3
fi
echo "--- Unreal plugin: .uplugin, Build.cs rules compiled against a TEST STUB UnrealBuildTool (tests/unreal) and evaluated per platform"
python3 - "$UE" <<'PY'
import json, os, sys
root = sys.argv[1]
plugin = json.load(open(os.path.join(root, "Duolando.uplugin")))
assert plugin["FileVersion"] == 3 and plugin["Modules"], plugin
for m in plugin["Modules"]:
    rules = os.path.join(root, "Source", m["Name"], m["Name"] + ".Build.cs")
    assert os.path.isfile(rules), rules
    for sub in ("Public", "Private"):
        assert os.path.isdir(os.path.join(root, "Source", m["Name"], sub)), sub
print("Duolando.uplugin: modules", [m["Name"] for m in plugin["Modules"]], "platforms", plugin["Modules"][0]["PlatformAllowList"])
PY
mkdir -p "$OUT/ubt"
mcs -target:library -warnaserror -out:"$OUT/ubt/UnrealBuildTool.dll" tests/unreal/UnrealBuildToolStub.cs
mcs -warnaserror -r:"$OUT/ubt/UnrealBuildTool.dll" -out:"$OUT/ubt/test_build_rules.exe" $UEMOD/Duolando.Build.cs \
    $UE/Source/ThirdParty/DuolandoLibrary/DuolandoLibrary.Build.cs tests/unreal/test_build_rules.cs
(cd "$OUT/ubt" && mono test_build_rules.exe "$ROOT/$UE/Source/ThirdParty/DuolandoLibrary")

echo "--- Unity wrapper: compiled with Mono's C# compiler, run under Mono against libduolando.so"
UNITY=integrations/unity
SAMPLE="$UNITY/Samples~/HumanoidFollower/DuolandoHumanoidFollower.cs"
mcs -unsafe -target:library -warnaserror -out:"$OUT/Duolando.dll" $UNITY/Runtime/Duolando.cs
mcs -unsafe -warnaserror -out:"$OUT/test_unity.exe" $UNITY/Runtime/Duolando.cs tests/c/test_unity.cs
LD_LIBRARY_PATH="$LIB${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" mono "$OUT/test_unity.exe" "$ROOT"

echo "--- Unity package: layout, runtime + sample against a TEST STUB UnityEngine (tests/unity), sample run under Mono"
for f in package.json Runtime/Duolando.Runtime.asmdef Runtime/Duolando.cs Runtime/Plugins/x86_64/README.md \
         Runtime/Plugins/Android/arm64-v8a/README.md Runtime/Plugins/iOS/README.md \
         Samples~/HumanoidFollower/Duolando.Samples.HumanoidFollower.asmdef "${SAMPLE#$UNITY/}"; do
    [ -f "$UNITY/$f" ] || { echo "Unity package: $f missing"; exit 1; }
done
python3 - "$UNITY" <<'PY'
import json, os, sys
root = sys.argv[1]
pkg = json.load(open(os.path.join(root, "package.json")))
assert pkg["name"] == pkg["name"].lower() and pkg["name"].startswith("com."), pkg["name"]
for key in ("version", "displayName", "unity", "description"):
    assert pkg.get(key), key
for sample in pkg["samples"]:
    assert os.path.isdir(os.path.join(root, sample["path"])), sample["path"]
rt = json.load(open(os.path.join(root, "Runtime/Duolando.Runtime.asmdef")))
assert rt["name"] == "Duolando.Runtime" and rt["allowUnsafeCode"] is True
sm = json.load(open(os.path.join(root, "Samples~/HumanoidFollower/Duolando.Samples.HumanoidFollower.asmdef")))
assert rt["name"] in sm["references"], sm["references"]
print("package.json and assembly definitions: OK")
PY
U=$OUT/unity
mkdir -p "$U"
mcs -target:library -warnaserror -out:"$U/UnityEngine.dll" tests/unity/UnityEngineStub.cs
# The runtime as Unity compiles it (UNITY_5_3_OR_NEWER: the Vector3/Quaternion helpers).
mcs -unsafe -target:library -warnaserror -define:UNITY_5_3_OR_NEWER -r:"$U/UnityEngine.dll" \
    -out:"$U/Duolando.Runtime.dll" $UNITY/Runtime/Duolando.cs
# The sample's Android path (StreamingAssets through UnityWebRequest): compiled only.
mcs -target:library -warnaserror -define:UNITY_5_3_OR_NEWER -define:UNITY_ANDROID -r:"$U/UnityEngine.dll" \
    -r:"$U/Duolando.Runtime.dll" -out:"$U/SampleAndroid.dll" "$SAMPLE"
mcs -warnaserror -define:UNITY_5_3_OR_NEWER -r:"$U/UnityEngine.dll" -r:"$U/Duolando.Runtime.dll" \
    -out:"$U/test_sample.exe" "$SAMPLE" tests/unity/test_sample.cs
(cd "$U" && LD_LIBRARY_PATH="$LIB${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" mono test_sample.exe "$ROOT")
if [ "${DUO_FFI_AARCH64:-0}" = 1 ]; then
    echo "--- aarch64-unknown-linux-gnu: libduolando cross-built, the C host test run under qemu-user"
    if ! command -v aarch64-linux-gnu-gcc >/dev/null || ! command -v qemu-aarch64 >/dev/null; then
        SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
        $SUDO apt-get update -qq
        $SUDO apt-get install -y -qq gcc-aarch64-linux-gnu qemu-user
    fi
    rustup target add aarch64-unknown-linux-gnu >/dev/null
    CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
        cargo build -p duolando-ffi --target aarch64-unknown-linux-gnu
    ARM=$TARGET/aarch64-unknown-linux-gnu/debug
    aarch64-linux-gnu-gcc $CFLAGS tests/c/test_duolando.c "$ARM/libduolando.a" -lpthread -lm -ldl -o "$OUT/test_aarch64"
    qemu-aarch64 -L /usr/aarch64-linux-gnu "$OUT/test_aarch64" "$ROOT"
fi
echo "ffi: OK"
