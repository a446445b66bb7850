#!/usr/bin/env bash
# Cross builds of the C library for the users' platforms (issue #37 §3),
# each built the way it ships (.ci/c_library.sh: profile ffi, stripped) and
# timed; docs/PLATFORMS.md says what each step proves and what it does not.
#
#   aarch64-linux-android      staticlib (needs no linker): duo_* symbols ==
#                              the header, size <= 4 MB. The shared library
#                              is NOT built: it needs the Android NDK's
#                              linker and libraries (not on Debian; zig has
#                              no bionic libc).
#   aarch64-apple-ios          staticlib (needs no Apple linker): duo_*
#                              symbols (llvm-nm, Mach-O) == the header,
#                              size <= 4 MB. Not linked, not run.
#   aarch64-apple-visionos     opt-in (DUO_CROSS_VISIONOS=1): staticlib with
#                              nightly -Z build-std (tier-3 target), symbols,
#                              size. Not linked, not run.
#   aarch64-unknown-linux-gnu  staticlib + shared library (linker
#                              aarch64-linux-gnu-gcc): symbols, sizes, the
#                              C host test linked against each stripped
#                              file, the static one RUN under qemu-user.
#
# Debian/Ubuntu; installs llvm, gcc-aarch64-linux-gnu and qemu-user when
# missing (root or sudo). Called by .ci/run. Honours CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
A_MAX=4000000
SO_MAX=2000000
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
start=$(date +%s)

need=()
command -v llvm-nm >/dev/null && command -v llvm-strip >/dev/null || need+=(llvm)
command -v aarch64-linux-gnu-gcc >/dev/null || need+=(gcc-aarch64-linux-gnu)
command -v qemu-aarch64 >/dev/null || need+=(qemu-user)
if [ ${#need[@]} -gt 0 ]; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq "${need[@]}"
fi
rustup target add aarch64-linux-android aarch64-apple-ios aarch64-unknown-linux-gnu >/dev/null 2>&1

gcc -fpreprocessed -dD -E -P include/duolando.h 2>/dev/null \
    | grep -oE '\bduo_[a-z0-9_]+[[:space:]]*\(' | sed -E 's/[[:space:]]*\($//' | sort -u > "$OUT/header.txt"

# check_symbols FILE PREFIX: the archive's defined duo_* functions == the header's.
check_symbols() {
    llvm-nm --defined-only "$1" 2>/dev/null | awk -v p="$2" '$2 == "T" && index($3, p "duo_") == 1 {print substr($3, length(p) + 1)}' \
        | sort -u > "$OUT/symbols.txt"
    diff -u "$OUT/header.txt" "$OUT/symbols.txt" || { echo "FAIL: $1 and include/duolando.h disagree"; exit 1; }
    echo "$1: $(wc -l < "$OUT/symbols.txt") duo_* functions == header"
}
# check_size FILE MAX
check_size() {
    local n; n=$(stat -c %s "$1")
    echo "$1: $n bytes (budget $2)"
    [ "$n" -le "$2" ] || { echo "FAIL: over budget"; exit 1; }
}
timed() { local t0; t0=$(date +%s); "$@"; echo "--- $(( $(date +%s) - t0 ))s: $*"; }

echo "=== aarch64-linux-android (Android arm64, Quest): staticlib"
timed bash .ci/c_library.sh aarch64-linux-android static
D=$TARGET/dist/aarch64-linux-android
check_symbols "$D/libduolando.a" ""
check_size "$D/libduolando.a" $A_MAX

echo "=== aarch64-apple-ios (iOS arm64): staticlib"
timed bash .ci/c_library.sh aarch64-apple-ios static
D=$TARGET/dist/aarch64-apple-ios
check_symbols "$D/libduolando.a" "_"   # Mach-O prefixes C names with _
check_size "$D/libduolando.a" $A_MAX


echo "=== aarch64-unknown-linux-gnu: staticlib + shared library, C host test under qemu-user"
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
timed bash .ci/c_library.sh aarch64-unknown-linux-gnu both
D=$TARGET/dist/aarch64-unknown-linux-gnu
check_symbols "$D/libduolando.a" ""
check_size "$D/libduolando.a" $A_MAX
check_size "$D/libduolando.so" $SO_MAX
CFLAGS="-std=c99 -Wall -Wextra -Werror -pedantic -O2 -Iinclude"
aarch64-linux-gnu-gcc $CFLAGS tests/c/test_duolando.c "$D/libduolando.a" -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc -o "$OUT/test_static"
aarch64-linux-gnu-gcc $CFLAGS tests/c/test_duolando.c -L"$D" -lduolando -lpthread -lm -o "$OUT/test_dynamic"
# The dynamic test is linked (the stripped .so resolves every symbol) but
# only the static one is run: under qemu each run takes 0.5-3 minutes.
timed qemu-aarch64 -L /usr/aarch64-linux-gnu "$OUT/test_static" "$ROOT"

if [ "${DUO_CROSS_VISIONOS:-0}" = 1 ]; then
    # Opt-in: a tier-3 target, built with nightly -Z build-std (std from
    # source: ~80 s of CPU more); a nightly change can break it, so .ci/run
    # leaves it off.
    echo "=== aarch64-apple-visionos (Apple Vision Pro): staticlib, nightly -Z build-std"
    # An installed nightly is used as it is (no update); CI's fuzz step installs one.
    rustup run nightly rustc -V >/dev/null 2>&1 || rustup toolchain install nightly --profile minimal >/dev/null 2>&1
    rustup component add rust-src --toolchain nightly >/dev/null 2>&1
    timed bash .ci/c_library.sh aarch64-apple-visionos static
    D=$TARGET/dist/aarch64-apple-visionos
    check_symbols "$D/libduolando.a" "_"
    check_size "$D/libduolando.a" $A_MAX
fi

echo "cross: OK in $(( $(date +%s) - start ))s"
