#!/usr/bin/env bash
# Bailando demo model from scratch on CPU: procedural data -> the authors' SepVQVAER and
# CrossCondGPT2AC trained -> $WORK/bailando_demo.duo (+ demo music), evaluated on held-out takes;
# INSTALL=1 copies them over assets/. See docs/DEMO_MODEL.md, "Bailando demo model".
#
#   tools/train/bailando/train_all.sh          # from the repository root
#
# Environment (all optional): PY (python with torch, numpy, scipy, safetensors, pyyaml; default
# /work/venv/bin/python), BIN (the duolando binary; default $CARGO_TARGET_DIR or target,
# /release/duolando, built if missing), CHECKOUT (lisiyao21/Bailando checkout with models/;
# default /tmp/bailando, extracted from MIRROR=/work/.mirror/lisiyao21+Bailando/repo if absent),
# MINUTES / SEED (synthetic data; default 40 / 1), SYNTH_ARGS (`synth` flags; default
# "--beat-grid-frames 4"), PREP_ARGS (prepare_data.py flags; default "--fold-heading"), VQ_ARGS
# (train_vqvae.py flags; default "--no-yaw"), SYNTH, DATA, WORK (default /tmp/bailando_*
# names that include minutes and seed), VQ_STEPS / ROOT_STEPS / GPT_STEPS, GPT_ARGS (train_gpt.py
# flags; default "--headings 1 --repeat-weight 1.0 --skip-start 16"), FLAT_ROOT=0 to keep the
# root decoder's vertical velocity (default: retrained without it, codebooks frozen, after the
# GPT), STREAM (evaluate.py --stream flags; default "--preset reference --topk 3 --rng-seed 1":
# the demo is sampled), DEMO_TAKE (held-out take whose first 20 s of music ship as the demo
# music; default ChaCha_30_01), EVAL=0 to skip the evaluation, INSTALL=1.
# Every training stage: torch.set_num_threads(1) under nice -n 10.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/../../.." && pwd)"
PY="${PY:-/work/venv/bin/python}"
MINUTES="${MINUTES:-40}"
SEED="${SEED:-1}"
SYNTH="${SYNTH:-/tmp/bailando_synth_m${MINUTES}_s${SEED}}"
DATA="${DATA:-/tmp/bailando_data_m${MINUTES}_s${SEED}}"
WORK="${WORK:-/tmp/bailando_train_m${MINUTES}_s${SEED}}"
CHECKOUT="${CHECKOUT:-/tmp/bailando}"
MIRROR="${MIRROR:-/work/.mirror/lisiyao21+Bailando/repo}"
DEMO_TAKE="${DEMO_TAKE:-ChaCha_30_01}"
BIN="${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/duolando}"
T="$ROOT/tools/train/bailando"
NICE="nice -n 10"
mkdir -p "$WORK"
START=$(date +%s)
stamp() { echo "[$(( $(date +%s) - START )) s] $*" | tee -a "$WORK/timings.txt"; }

[ -x "$BIN" ] || (cd "$ROOT" && cargo build --release -p duolando)
if [ ! -f "$CHECKOUT/models/cross_cond_gpt2_ac.py" ]; then
    mkdir -p "$CHECKOUT"
    git -C "$MIRROR" archive HEAD models configs | tar -x -C "$CHECKOUT"
fi
[ -d "$SYNTH/motion" ] || "$BIN" synth --minutes "$MINUTES" --seed "$SEED" ${SYNTH_ARGS---beat-grid-frames 4} --out "$SYNTH"
[ -f "$DATA/index.json" ] || "$PY" "$T/prepare_data.py" --synth "$SYNTH" --out "$DATA" --bin "$BIN" \
    ${PREP_ARGS---fold-heading} > "$WORK/prepare.log"
stamp "data ready: $DATA"

cd "$T"
# a stage whose checkpoint exists in $WORK is reused (delete it, or use another WORK, to retrain)
[ -f "$WORK/vqvae.pt" ] || $NICE "$PY" train_vqvae.py --data "$DATA" --checkout "$CHECKOUT" --out "$WORK/vqvae.pt" \
    --steps "${VQ_STEPS:-3000}" --root-steps "${ROOT_STEPS:-800}" ${VQ_ARGS---no-yaw} 2>&1 | tee "$WORK/vqvae.log"
stamp "VQ-VAE trained"
[ -f "$WORK/gpt.pt" ] || $NICE "$PY" train_gpt.py --data "$DATA" --checkout "$CHECKOUT" --vqvae "$WORK/vqvae.pt" --out "$WORK/gpt.pt" \
    --steps "${GPT_STEPS:-2000}" ${GPT_ARGS---headings 1 --repeat-weight 1.0 --skip-start 16} 2>&1 | tee "$WORK/gpt.log"
stamp "GPT trained"
VQ="$WORK/vqvae.pt"
if [ "${FLAT_ROOT:-1}" != 0 ]; then
    # The root decoder again without vertical velocity (a sampled dance drifted up or down by
    # 0.1-0.7 m in 20 s); the codebooks frozen, so the GPT's codes stay valid.
    [ -f "$WORK/vqvae_flat.pt" ] || $NICE "$PY" train_vqvae.py --data "$DATA" --checkout "$CHECKOUT" --out "$WORK/vqvae_flat.pt" \
        --root-steps "${ROOT_STEPS:-800}" ${VQ_ARGS---no-yaw} --flat-root-y --root-only "$WORK/vqvae.pt" 2>&1 | tee "$WORK/vqvae_flat.log"
    VQ="$WORK/vqvae_flat.pt"
    stamp "root decoder retrained without vertical velocity"
fi
"$PY" export.py --vqvae "$VQ" --gpt "$WORK/gpt.pt" --out "$WORK/export" --data "$DATA" --demo-take "$DEMO_TAKE"
"$BIN" convert --config "$WORK/export/actor_critic_demo.yaml" --gpt "$WORK/export/gpt.safetensors" \
    --vqvae "$WORK/export/vqvae.safetensors" --dtype f16 -o "$WORK/bailando_demo.duo"
SEEDS=$("$PY" -c "import json,sys; s=json.load(open(sys.argv[1]))['seed_tokens']; print(f'{s[0]},{s[1]}')" "$WORK/export/meta.json")
stamp "exported, seed tokens $SEEDS"
if [ "${EVAL:-1}" != 0 ]; then
    $NICE "$PY" evaluate.py --data "$DATA" --synth "$SYNTH" --duo "$WORK/bailando_demo.duo" --seed-tokens "$SEEDS" \
        --vqvae "$VQ" --checkout "$CHECKOUT" --bin "$BIN" --out "$WORK/eval" --json "$WORK/eval.json" \
        --stream "${STREAM---preset reference --topk 3 --rng-seed 1}" 2>&1 | tee "$WORK/eval.log"
    stamp "evaluated"
fi
"$BIN" generate --model "$WORK/bailando_demo.duo" --music "$WORK/export/bailando_demo_music.npy" \
    --seed-tokens "$SEEDS" --mode exact --out "$WORK/demo_run"
# The demo music as audio: the first 20 s of the take's 3840 Hz WAV (what its features came from).
"$PY" -c "import sys; from scipy.io import wavfile; sr, x = wavfile.read(sys.argv[1]); wavfile.write(sys.argv[2], sr, x[:20 * sr])" \
    "$DATA/wav/$DEMO_TAKE.wav" "$WORK/bailando_demo_music.wav"
if [ "${INSTALL:-0}" = 1 ]; then
    cp "$WORK/bailando_demo.duo" "$WORK/bailando_demo_music.wav" "$ROOT/assets/"
    echo "seed tokens $SEEDS: set DEMO_SOLO_SEED in std-adapters/src/cli/dance/solo.rs to them"
    ls -l "$ROOT/assets"
else
    ls -l "$WORK/bailando_demo.duo" "$WORK/export/bailando_demo_music.npy"
    echo "not installed (INSTALL=1 copies them over assets/)"
fi
