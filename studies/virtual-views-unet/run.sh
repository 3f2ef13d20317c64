#!/usr/bin/env bash
# Virtual views against X and HA-X (BENCHMARKS.md): U-Net light, 3 seeds, 192x256, in- and out-of-distribution.
# Usage: bash run.sh WORK_DIR   (with the project's .venv active, or FREESPACE=/path/to/.venv/bin/freespace)
set -euo pipefail
DIR=$(cd "$(dirname "$0")" && pwd)  # this script's folder (protocol.yaml: the variants, gains and test set)
FS=${FREESPACE:-freespace}
mkdir -p "$1" && cd "$1"
[ -d syn ] || $FS synth --out syn --num 100 --width 256 --height 192 --frames-per-scenario 5 --seed 0
[ -d shifted ] || $FS synth --out shifted --num 40 --width 256 --height 192 --frames-per-scenario 5 --seed 1 \
    --max-roll 6 --camera-heights 1.0,2.6 --pitches=-5,5 --baselines 0.2,2.0
$FS reproduce --dataset synth --root syn --protocol "$DIR/protocol.yaml" --models unet \
    --seeds 3 --epochs 10 --patience 5 --batch-size 4 --image-size 192x256 --out res
