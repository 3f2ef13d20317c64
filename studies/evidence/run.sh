#!/usr/bin/env bash
# The evidence run of the protocol (BENCHMARKS.md, "Does the augmentation help?"): U-Net, SegNet and DUpsampling
# (light presets) at 96x128, variants X, HA-X, X-dup and HV-X, 10 seeds, the usual test split and a shifted-rig set.
# Cells run in seed-major order, two at a time with one thread each (reproduce --only), so that whatever finished
# is balanced over the networks; the last command collects them.
# A third test set, same-rigs (200 frames of 40 new drives rendered with the training rigs, the same for every
# seed), was added once 7 of the 10 seeds had finished, when the 20-frame test split's paired spread showed that
# +-1.5 points was out of reach on it; it evaluates the same checkpoints and changes no training.
# Usage: bash run.sh WORK_DIR   (with the project's .venv active, or FREESPACE=/path/to/.venv/bin/freespace)
set -euo pipefail
DIR=$(cd "$(dirname "$0")" && pwd)  # this script's folder (protocol.yaml: the variants, gains and reference line)
FS=${FREESPACE:-freespace}
SEEDS=${SEEDS:-10}
mkdir -p "$1" && cd "$1" && mkdir -p logs
[ -d syn ] || $FS synth --out syn --num 100 --width 320 --height 240 --frames-per-scenario 5 --seed 0 --workers 2
[ -d shifted ] || $FS synth --out shifted --num 60 --width 320 --height 240 --frames-per-scenario 5 --seed 1 \
    --workers 2 --max-roll 6 --camera-heights 1.0,2.6 --pitches=-5,5 --baselines 0.2,2.0
[ -d same-rigs ] || $FS synth --out same-rigs --num 200 --width 320 --height 240 --frames-per-scenario 5 --seed 2 \
    --workers 2
OPTS="--dataset synth --root syn --protocol $DIR/protocol.yaml --test-root shifted --seeds $SEEDS --epochs 10 --patience 5 --batch-size 2 --image-size 96x128 --no-progress --out res"
for s in $(seq 0 $((SEEDS - 1))); do for n in unet segnet dupsampling; do for v in X HA-X X-dup HV-X; do
    echo "$n,$v,$s"; done; done; done |
  OMP_NUM_THREADS=1 xargs -P 2 -I{} sh -c "$FS reproduce $OPTS --only {} > logs/\$(echo {} | tr , _).log 2>&1 \
      && echo \"\$(date +%T) done {}\" || echo \"\$(date +%T) FAILED {}\""
# every finished run on same-rigs too (training skipped), then the tables and figures of all three test sets
$FS reproduce ${OPTS/--test-root shifted/--test-root shifted --test-root same-rigs=same-rigs} \
    --models unet,segnet,dupsampling --variants X,HA-X,X-dup,HV-X
