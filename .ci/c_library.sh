#!/usr/bin/env bash
# Builds libduolando as it ships to engines (docs/C_API.md "Build and link"):
#
#   bash .ci/c_library.sh [TRIPLE] [static|both]     # default: host, both
#
# - Profile `ffi` (workspace Cargo.toml): release + fat LTO over every crate
#   including std, one codegen unit, no debug info, panic = unwind.
# - Cargo runs no LTO for a library whose crate-type list holds `rlib`
#   (duolando-ffi's does: its Rust tests link it), so each kind is built on
#   its own with `cargo rustc --crate-type`: staticlib, then cdylib ("both").
#   A plain `cargo build -p duolando-ffi --profile ffi` gives a 6.2 MB
#   stripped archive instead of 3.2 MB.
# - Stripped copies go to $TARGET/dist/TRIPLE/: the archive with
#   `strip --strip-debug -R .llvmbc -R .llvmcmd` (debug info and the LLVM
#   bitcode the prebuilt compiler_builtins objects embed: 2 MB that only a
#   Rust LTO link reads; C linkers ignore it), the shared library with
#   `strip` (all symbols but the dynamic ones).
# - The shared library gets SONAME libduolando.so (macOS: install name
#   @rpath/libduolando.dylib). A cross target needs CARGO_TARGET_<TRIPLE>_LINKER.
# Prints the native libraries to link with the archive and both sizes in
# bytes ("size: FILE BYTES" lines, read by .ci/size.sh and .ci/cross.sh).
# Honours CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
HOST=$(rustc -vV | sed -n 's/^host: //p')
TRIPLE=${1:-$HOST}
KINDS=${2:-both}

if [ "$TRIPLE" = "$HOST" ]; then
    TARGET_ARGS=()
    BUILT=$TARGET/ffi
else
    TARGET_ARGS=(--target "$TRIPLE")
    BUILT=$TARGET/$TRIPLE/ffi
fi
DIST=$TARGET/dist/$TRIPLE
mkdir -p "$DIST"

# GNU strip for the host; llvm-strip (Debian package llvm) reads every
# target's objects (aarch64 ELF, Mach-O).
if [ "$TRIPLE" = "$HOST" ]; then STRIP=strip; else STRIP=llvm-strip; fi
case "$TRIPLE" in
    *-apple-*) BITCODE=(-R __LLVM,__bitcode -R __LLVM,__cmdline) ;;
    *) BITCODE=(-R .llvmbc -R .llvmcmd) ;;
esac
case "$TRIPLE" in
    *-apple-*) SHARED=libduolando.dylib ;;
    *-windows-*) SHARED=duolando.dll ;;
    *) SHARED=libduolando.so ;;
esac

# Tier-3 targets (visionOS) have no prebuilt std: nightly builds it from
# source (rustup component add rust-src --toolchain nightly).
case "$TRIPLE" in
    *-visionos*) CARGO=(cargo +nightly rustc -Z build-std=std,panic_unwind) ;;
    *) CARGO=(cargo rustc) ;;
esac

t0=$(date +%s)
"${CARGO[@]}" -p duolando-ffi --profile ffi --lib --crate-type staticlib "${TARGET_ARGS[@]}" \
    -- --print native-static-libs
# ELF targets whose linker is here and whose archive CI links and runs
# (x86_64 and aarch64 Linux): the LTO object's per-function sections merged
# by kind (.ci/merge_sections.ld) and the symbols no relocation names dropped: the same
# code, ~0.9 MB less archive; a C host linked against it is within 8 KB of
# one linked against the unmerged archive (docs/C_API.md "Build and link").
case "$TRIPLE" in
    "$HOST") LD=ld ;;
    aarch64-unknown-linux-gnu) LD=aarch64-linux-gnu-ld ;;
    *) LD= ;;
esac
if [ -n "$LD" ] && command -v "$LD" >/dev/null; then
    WORK=$(mktemp -d)
    cp "$BUILT/libduolando.a" "$WORK/lib.a"
    LTO_OBJ=$(ar t "$WORK/lib.a" | grep -E '^duolando-[^.]*\.duolando\..*rcgu\.o$')
    [ "$(wc -l <<<"$LTO_OBJ")" = 1 ] || { echo "c_library.sh: expected one LTO object in the archive, got: $LTO_OBJ"; exit 1; }
    (cd "$WORK" && ar x lib.a "$LTO_OBJ" && "$LD" -r -T "$ROOT/.ci/merge_sections.ld" -o merged.o "$LTO_OBJ" \
        && mv merged.o "$LTO_OBJ" && ar r lib.a "$LTO_OBJ")
    "$STRIP" --strip-unneeded "${BITCODE[@]}" -o "$DIST/libduolando.a" "$WORK/lib.a"
    rm -rf "$WORK"
    echo "staticlib $TRIPLE: sections merged ($LD -r), unneeded symbols stripped"
else
    "$STRIP" --strip-debug "${BITCODE[@]}" -o "$DIST/libduolando.a" "$BUILT/libduolando.a"
fi
echo "staticlib $TRIPLE: $(( $(date +%s) - t0 ))s"
echo "size: $DIST/libduolando.a $(stat -c %s "$DIST/libduolando.a")"

if [ "$KINDS" = both ]; then
    t0=$(date +%s)
    # An install name / SONAME without the build machine's path, so that
    # engines linking the file record just its name (and find it next to
    # their binaries: Unreal's RuntimeDependencies, Unity's Plugins).
    case "$TRIPLE" in
        *-apple-*) NAME_ARG=(-C link-arg=-Wl,-install_name,@rpath/libduolando.dylib) ;;
        *-windows-*) NAME_ARG=() ;;
        *) NAME_ARG=(-C link-arg=-Wl,-soname,libduolando.so) ;;
    esac
    "${CARGO[@]}" -p duolando-ffi --profile ffi --lib --crate-type cdylib "${TARGET_ARGS[@]}" -- "${NAME_ARG[@]}"
    "$STRIP" -o "$DIST/$SHARED" "$BUILT/$SHARED"
    echo "cdylib $TRIPLE: $(( $(date +%s) - t0 ))s"
    echo "size: $DIST/$SHARED $(stat -c %s "$DIST/$SHARED")"
fi
