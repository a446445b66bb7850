#!/usr/bin/env bash
# Size budget of the C library as it ships (issue #37 §3): builds the host
# library the way docs/C_API.md "Build and link" says (.ci/c_library.sh:
# profile ffi, stripped), prints both sizes and FAILS when
#   libduolando.so (stripped)                 > 2,000,000 bytes
#   libduolando.a  (--strip-debug, no bitcode) > 4,000,000 bytes
# so that growth fails CI. Then checks that the stripped files are still a
# working library: their duo_* symbols == the header's functions, and the C
# host test (tests/c/test_duolando.c) linked against each one passes.
# Called by .ci/run. Honours CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
HOST=$(rustc -vV | sed -n 's/^host: //p')
DIST=$TARGET/dist/$HOST
SO_MAX=2000000
A_MAX=4000000
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT

bash .ci/c_library.sh "$HOST" both

so=$(stat -c %s "$DIST/libduolando.so")
a=$(stat -c %s "$DIST/libduolando.a")
echo "libduolando.so stripped: $so bytes (budget $SO_MAX)"
echo "libduolando.a stripped:  $a bytes (budget $A_MAX)"
fail=0
[ "$so" -le "$SO_MAX" ] || { echo "FAIL: libduolando.so is over its budget"; fail=1; }
[ "$a" -le "$A_MAX" ] || { echo "FAIL: libduolando.a is over its budget"; fail=1; }
[ "$fail" = 0 ] || { echo "(what grew: nm --size-sort -S $TARGET/ffi/libduolando.a | tail -40)"; exit 1; }

echo "--- stripped libraries: header functions == exported duo_* symbols"
gcc -fpreprocessed -dD -E -P include/duolando.h 2>/dev/null \
    | grep -oE '\bduo_[a-z0-9_]+[[:space:]]*\(' | sed -E 's/[[:space:]]*\($//' | sort -u > "$OUT/header.txt"
nm -D --defined-only "$DIST/libduolando.so" | awk '$2 == "T" && $3 ~ /^duo_/ {print $3}' | sort -u > "$OUT/dynamic.txt"
nm --defined-only "$DIST/libduolando.a" 2>/dev/null | awk '$2 == "T" && $3 ~ /^duo_/ {print $3}' | sort -u > "$OUT/static.txt"
diff -u "$OUT/header.txt" "$OUT/dynamic.txt" || { echo "stripped .so and header disagree"; exit 1; }
diff -u "$OUT/header.txt" "$OUT/static.txt" || { echo "stripped .a and header disagree"; exit 1; }
echo "$(wc -l < "$OUT/header.txt") functions in both"

echo "--- C host test against the stripped libraries (static link line of docs/C_API.md)"
CFLAGS="-std=c99 -Wall -Wextra -Werror -pedantic -O2 -Iinclude"
gcc $CFLAGS tests/c/test_duolando.c "$DIST/libduolando.a" -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc -o "$OUT/test_static"
gcc $CFLAGS tests/c/test_duolando.c -L"$DIST" -lduolando -lpthread -lm -Wl,-rpath,"$DIST" -o "$OUT/test_dynamic"
# Each tool's output is captured before grep reads it: `tool | grep -q` under
# pipefail fails at random when grep exits at its first match and the tool's
# next write meets a closed pipe (SIGPIPE; ld.so writes ldd's lines one by one).
so_dyn=$(readelf -d "$DIST/libduolando.so")
grep -q 'SONAME.*\[libduolando.so\]' <<<"$so_dyn" || { echo "libduolando.so has no SONAME libduolando.so"; exit 1; }
test_dyn=$(readelf -d "$OUT/test_dynamic")
grep -q 'NEEDED.*\[libduolando.so\]' <<<"$test_dyn" || { echo "test_dynamic does not need plain libduolando.so"; exit 1; }
test_ldd=$(ldd "$OUT/test_dynamic")
grep -qF "$DIST/libduolando.so" <<<"$test_ldd" || { echo "test_dynamic does not load $DIST/libduolando.so:"; echo "$test_ldd"; exit 1; }
"$OUT/test_static" "$ROOT"
"$OUT/test_dynamic" "$ROOT"
echo "test executable, static link, stripped: $(strip -o "$OUT/s" "$OUT/test_static" && stat -c %s "$OUT/s") bytes"
echo "size: OK"
