#!/usr/bin/env bash
# Fuzz smoke: every cargo-fuzz target of fuzz/ for a short run from the
# committed seeds (fuzz/seeds/<target>/), so a regression that crashes a
# target on known-interesting inputs, or soon after, fails CI. Long runs
# are local (docs/ROBUSTNESS.md §2, §7).
#
#   bash .ci/fuzz.sh                  # DUO_FUZZ_SECONDS per target (default 30)
#
# -malloc_limit_mb makes any single allocation over 512 MB a crash: no
# input may make the decoder, converter or session allocate in proportion
# to an unvalidated number. -rss_limit_mb bounds the whole process.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
secs=${DUO_FUZZ_SECONDS:-30}
rustup toolchain install nightly --profile minimal >/dev/null 2>&1
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked
fi
targets=(duo_parse duo_struct convert session solo_session transflower_session)
cargo +nightly fuzz build -O
# Each libFuzzer run is one process on one core: two targets at a time.
fuzz_one() { # target log: prepares the corpus, runs, prints the stats
  local t=$1 log=$2 rc
  mkdir -p "corpus/$t"
  cp -n seeds/"$t"/* "corpus/$t/" 2>/dev/null || true
  if [[ $t == duo_parse ]]; then
    # Whole valid files are large; take them from the fixtures, not seeds/.
    cp ../tests/fixtures/tiny/model.duo "corpus/$t/fixture-tiny.duo"
    cp ../tests/fixtures/tiny2/model.duo "corpus/$t/fixture-tiny2.duo"
    cp ../tests/fixtures/bailando_btiny/model.duo "corpus/$t/fixture-btiny.duo"
    cp ../tests/fixtures/transflower_paper/model.duo "corpus/$t/fixture-transflower-paper.duo"
  fi
  echo "--- fuzz $t for ${secs}s ($(ls "corpus/$t" | wc -l) inputs)" >"$log.head"
  rm -rf "artifacts/$t"
  rc=0
  cargo +nightly fuzz run -O "$t" "corpus/$t" -- \
    -max_total_time="$secs" -rss_limit_mb=2048 -malloc_limit_mb=512 -timeout=30 -print_final_stats=1 >"$log" 2>&1 || rc=$?
  # A crash, leak, OOM or timeout exits non-zero (and writes an artifact);
  # so does a run that could not start. Either fails CI.
  if [[ $rc == 0 ]] && ls "artifacts/$t"/* >/dev/null 2>&1; then rc=1; fi
  return "$rc"
}
logs=$(mktemp -d)
failed=()
for ((i = 0; i < ${#targets[@]}; i += 2)); do
  pair=("${targets[@]:i:2}")
  pids=()
  for t in "${pair[@]}"; do fuzz_one "$t" "$logs/$t" & pids+=($!); done
  for j in "${!pair[@]}"; do
    t=${pair[j]}
    rc=0; wait "${pids[j]}" || rc=$?
    cat "$logs/$t.head"
    grep -E "^Done|stat::number_of_executed_units|stat::average_exec_per_sec|ERROR|panicked|SUMMARY|Test unit written" "$logs/$t" || true
    if [[ $rc != 0 ]]; then
      tail -40 "$logs/$t"
      echo "fuzz target $t failed (exit $rc): see fuzz/artifacts/$t"
      failed+=("$t")
    fi
  done
done
[[ ${#failed[@]} == 0 ]] || { echo "fuzz smoke failed: ${failed[*]}"; exit 1; }
echo "fuzz smoke passed"
