#!/usr/bin/env bash
# The C ABI (issue #5): header vs exported symbols, header compiled as C99
# and C++17 (included twice), the C host test linked against the static and
# the dynamic library and run under valgrind, the C++ session runner of the
# Unreal plugin run under valgrind, the Unity wrapper compiled and run under
# Mono, and, opt-in with DUO_FFI_AARCH64=1, the C host test for aarch64
# under qemu-user (it cross-builds std-adapters: ~12 min, too long for the
# 45-min CI budget, so .ci/run leaves it off). Debian/Ubuntu; installs valgrind, mono-mcs,
# gcc-aarch64-linux-gnu and qemu-user when missing (root or sudo). The Rust
# tests of the crate run with `cargo test --workspace`. Honours
# CARGO_TARGET_DIR. Called by .ci/run.
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
cargo build -p duolando-ffi
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
ldd "$OUT/test_dynamic" | grep -q libduolando.so
"$OUT/test_static" "$ROOT"

VALGRIND=(valgrind --error-exitcode=1 --leak-check=full --errors-for-leak-kinds=definite,indirect,possible --show-leak-kinds=definite,indirect,possible)
echo "--- valgrind: static"
"${VALGRIND[@]}" "$OUT/test_static" "$ROOT"
echo "--- valgrind: dynamic"
"${VALGRIND[@]}" "$OUT/test_dynamic" "$ROOT"

if [ -f integrations/unreal/Source/Duolando/Public/DuolandoRunner.h ]; then
    echo "--- Unreal plugin: the engine-independent session runner (C++17, threads) under valgrind"
    g++ -std=c++17 -Wall -Wextra -Werror -pedantic -g -Iinclude -Iintegrations/unreal/Source/Duolando/Public \
        tests/c/test_runner.cpp -L"$LIB" -lduolando -lpthread -Wl,-rpath,"$LIB" -o "$OUT/test_runner"
    "${VALGRIND[@]}" "$OUT/test_runner" "$ROOT"
fi

echo "--- Unity wrapper: compiled with Mono's C# compiler, run under Mono against libduolando.so"
if ! command -v mcs >/dev/null || ! command -v mono >/dev/null; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq mono-mcs
fi
mcs -unsafe -target:library -warnaserror -out:"$OUT/Duolando.dll" integrations/unity/Duolando.cs
mcs -unsafe -warnaserror -out:"$OUT/test_unity.exe" integrations/unity/Duolando.cs tests/c/test_unity.cs
LD_LIBRARY_PATH="$LIB${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" mono "$OUT/test_unity.exe" "$ROOT"
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
