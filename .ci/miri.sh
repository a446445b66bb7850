#!/usr/bin/env bash
# Miri over core's unit tests that touch unsafe code (the SIMD kernels, run
# with AVX2/FMA enabled at compile time so Miri executes the x86
# intrinsics paths it can emulate) or byte casting (arena carving, weight
# views, the activation quantiser). Each test runs on its own under a time
# limit: Miri is ~1000x slower than native, and a test that exceeds the
# limit is reported as TIMEOUT and one Miri cannot interpret (inline asm,
# unsupported intrinsics) as UNSUPP; neither is a failure. An error (UB,
# a failed assertion) fails the script.
#
#   bash .ci/miri.sh [SECONDS_PER_TEST]     (default 300; not part of .ci/run)
#
# Figures of the last local run: docs/ROBUSTNESS.md §4.
set -uo pipefail
cd "$(dirname "$0")/.."
limit=${1:-300}
rustup toolchain install nightly --profile minimal >/dev/null 2>&1 || true
rustup +nightly component add miri rust-src >/dev/null
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-target/miri}
# F16C is left out: Miri cannot emulate `vcvtps2ph` (the f16 variants are
# then not selected, and run natively in `cargo test`).
export RUSTFLAGS="-C target-feature=+avx2,+fma"
cargo +nightly miri setup >/dev/null
tests=(
  input::tests::
  tests::arena::
  tests::engine::binding_reads_exactly_the_schema
  tests::simd::
  kernels::simd::tests::
  tests::kernels::linear_matches_naive
  tests::kernels::attention_band_and_tiled_causal
  tests::motion_sampler::
)
# Expand the prefixes into single test names.
cargo +nightly miri test -q -p duolando-core --lib --no-run >/dev/null 2>&1
all=$(cargo +nightly miri test -q -p duolando-core --lib -- --list 2>/dev/null | sed -n 's/: test$//p')
pass=0; fail=0; slow=0; unsupp=0
for t in $all; do
  hit=0; for p in "${tests[@]}"; do [[ $t == $p* ]] && hit=1; done
  [[ $hit == 1 ]] || continue
  s=$(date +%s)
  timeout "$limit" cargo +nightly miri test -q -p duolando-core --lib -- --exact "$t" >/tmp/miri-one.log 2>&1
  rc=$?; d=$(( $(date +%s) - s ))
  if [[ $rc == 0 ]]; then echo "ok       ${d}s  $t"; pass=$((pass+1))
  elif [[ $rc == 124 ]]; then echo "TIMEOUT  ${d}s  $t"; slow=$((slow+1))
  elif grep -q "unsupported operation" /tmp/miri-one.log; then
    # Miri cannot run it (e.g. libm's inline-asm sqrtf): not a finding.
    echo "UNSUPP   ${d}s  $t: $(grep -m1 -A1 'unsupported operation' /tmp/miri-one.log | tail -1 | tr -s ' ')"; unsupp=$((unsupp+1))
  else echo "FAIL     ${d}s  $t"; tail -30 /tmp/miri-one.log; fail=$((fail+1)); fi
done
echo "miri: $pass passed, $fail failed, $slow over ${limit}s, $unsupp unsupported by Miri"
[[ $fail == 0 ]]
