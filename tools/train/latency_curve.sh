#!/usr/bin/env bash
# Latency chosen at training time (issue 41 §3; docs/DEMO_MODEL.md "Latency chosen at training
# time"): the demo recipe's tokenisers trained once, the follower GPT trained at several
# look-aheads on them, each converted to .duo, then tools/train/latency_curve.py scores every
# model against the TRUE follower of the held-out takes: the look_forward-29 model cut to each
# look-ahead in S mode, and each model trained for that look-ahead.
#
#   tools/train/latency_curve.sh          # from the repository root
#
# Environment (all optional): PY, BIN (the duolando binary), DATA (default /tmp/duo_synth_m60_s1,
# written by `duolando synth --minutes 60 --seed 1` when missing), WORK (default
# /tmp/duo_latency_m60_s1), LOOK_FORWARDS (default "29 4 1 8": 29 is the cut model),
# ENC_FUTURE / DEC_FUTURE (default 2 / 2, the interactive preset's), MODEL29 (score this .duo as
# the 29-token model instead of training one, e.g. assets/demo.duo: then its tokenisers are not
# the others'), PAR (GPT trainings run at once, default 1). Every stage single-threaded under
# nice, as train_all.sh. Nothing is installed; the .duo files stay in $WORK/lf*/demo.duo.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
PY="${PY:-/work/venv/bin/python}"
BIN="${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/duolando}"
DATA="${DATA:-/tmp/duo_synth_m60_s1}"
WORK="${WORK:-/tmp/duo_latency_m60_s1}"
LOOK_FORWARDS="${LOOK_FORWARDS:-29 4 1 8}"
PAR="${PAR:-1}"
NICE="nice -n 10"
T="$ROOT/tools/train"
mkdir -p "$WORK"
[ -d "$DATA/motion" ] || "$BIN" synth --minutes 60 --seed 1 --out "$DATA"
cd "$T"
[ -f "$WORK/motion_vqvae.pt" ] || $NICE "$PY" train_vqvae.py --data "$DATA" --out "$WORK/motion_vqvae.pt" --steps 3000 --batch 8 --lr 6e-4
[ -f "$WORK/transl_vqvae.pt" ] || $NICE "$PY" train_transl.py --data "$DATA" --out "$WORK/transl_vqvae.pt" --steps 1500

gpt() {  # one look_forward: train, export, convert
    local lf="$1" o="$WORK/lf$1"
    mkdir -p "$o"
    ln -sf "$WORK/motion_vqvae.pt" "$o/motion_vqvae.pt"
    ln -sf "$WORK/transl_vqvae.pt" "$o/transl_vqvae.pt"
    [ -f "$o/follower_gpt.pt" ] || $NICE "$PY" train_gpt.py --data "$DATA" --vqvae "$WORK/motion_vqvae.pt" \
        --transl "$WORK/transl_vqvae.pt" --out "$o/follower_gpt.pt" --steps 1800 --batch 16 --look-forward "$lf" \
        > "$o/gpt.log"
    $NICE "$PY" export.py --ckpt "$o" --out "$o/export" --data "$DATA" --assets "$o/assets" --take Quickstep_20_01 > /dev/null
    "$BIN" convert --config "$o/export/follower_gpt.yaml" --gpt "$o/export/gpt.safetensors" \
        --vqvae "$o/export/vqvae.safetensors" --transl "$o/export/transl.safetensors" --dtype f16 -o "$o/demo.duo"
}
n=0
for lf in $LOOK_FORWARDS; do
    if [ "$lf" = 29 ] && [ -n "${MODEL29:-}" ]; then continue; fi
    gpt "$lf" &
    n=$((n + 1))
    if [ "$n" -ge "$PAR" ]; then wait -n; n=$((n - 1)); fi
done
wait

M29="${MODEL29:-$WORK/lf29/demo.duo}"
TRAINED=()
LAS=()
for lf in $LOOK_FORWARDS; do
    [ "$lf" = 29 ] && continue
    TRAINED+=(--trained "$lf=$WORK/lf$lf/demo.duo")
    LAS+=("$lf")
done
LAS_CSV="$(IFS=,; echo "${LAS[*]}")"
$NICE "$PY" latency_curve.py --data "$DATA" --bin "$BIN" --out "$WORK/eval" --model29 "$M29" "${TRAINED[@]}" \
    --lookaheads "$LAS_CSV" --enc-future "${ENC_FUTURE:-2}" --dec-future "${DEC_FUTURE:-2}" \
    --json "$WORK/latency.json"
echo "figures: $WORK/latency.json"
