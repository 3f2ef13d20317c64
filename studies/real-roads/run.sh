#!/usr/bin/env bash
# Real roads, no people (issue 45): the data, the variants' cells and their real-frame evaluation.
#
#   RAW=DIR WORK=DIR [SEEDS="0 1"] [MODELS="unet"] [VARIANTS="R-auto HA-R-auto R-auto-dup S S+R-auto"] \
#   [JOBS=2]  (MODELS: unet, deeplabv3plus, contextnet with the ImageNet Lite0 encoder; fastscnn from scratch)
#   [SIZE=128x416] [RENDERED=TREE] [FREESPACE=freespace] [PYTHON=python] bash studies/real-roads/run.sh
#
# RAW: a KITTI raw root (date folders with calib_*.txt; drives with image_02/03, velodyne_points). WORK: the
# study's working folder (autolabels, splits, rendered frames, run folders). Every step is skipped when its
# output exists, so the script resumes; each cell is `freespace train` + studies/real-roads/evaluate.py.
# RENDERED: a rendered tree (the converged run's same-rigs) that evaluate.py also scores each cell on.
# The two drives come from fetch.sh beside this script. A variant with the suffix -fp (R-auto-fp, S+R-auto-fp)
# trains as its base with `--flip --photometric` (mirror and colour jitter: not in the paper; issue 45's target).
set -euo pipefail
: "${RAW:?set RAW to a KITTI raw root}" "${WORK:?set WORK to a working folder}"
SEEDS=${SEEDS:-"0 1 2 3 4"}
MODELS=${MODELS:-"unet"}
VARIANTS=${VARIANTS:-"R-auto HA-R-auto R-auto-dup S S+R-auto"}
JOBS=${JOBS:-2}
FREESPACE=${FREESPACE:-freespace}
PYTHON=${PYTHON:-python}
HERE=$(cd "$(dirname "$0")" && pwd)
SIZE=${SIZE:-128x416}  # the network input, HxW (another size names its run folders <model>-<size>-<tag>-s<seed>)
COMMON=(--image-size $SIZE --epochs 60 --patience 10 --val-window 3 --min-delta 0.001 --lr 0.01 --batch-size 4
        --no-progress)
LITE0="--encoder-name efficientnet-lite0 --encoder-weights imagenet"  # the pretrained networks' encoder
mkdir -p "$WORK"
AL=$WORK/autolabels SYN=$WORK/syn MIX=$WORK/mix

# 1. labels nobody drew: SGBM where the drive has right images, LiDAR where it has scans, both fused
[ -f "$AL/settings.json" ] || $FREESPACE autolabel --dataset kitti-raw --root "$RAW" --disparity-source fused \
    --cache-dir "$WORK/sgbm-cache" --workers 2 --out "$AL"
# 2. contiguous time blocks per drive: train 70 %, val 10 %, test 20 % (never trained on), 2 frames apart
[ -f "$WORK/splits-raw/test.txt" ] || $FREESPACE datasets split --dataset kitti-raw --root "$RAW" --by time \
    --fractions 0.7,0.1,0.2 --gap 2 --out "$WORK/splits-raw"
# 3. rendered frames with their labels (S): 300 frames at KITTI's aspect, 30 drives
[ -f "$SYN/synth.json" ] || $FREESPACE synth --out "$SYN" --num 300 --width 640 --height 192 --seed 0 --workers 2
# 4. S+R-auto: one generic dataset of links, the rendered frames and the real drives' autolabelled frames;
#    trains on the rendered frames and the real training block, validates and tests on the real blocks
if [ ! -f "$MIX/freespace.yaml" ]; then
    "$PYTHON" "$HERE/mix.py" --syn "$SYN" --raw "$RAW" --autolabels "$AL" --splits "$WORK/splits-raw" --out "$MIX"
fi

cell() {  # model variant seed
    local model=$1 variant=$2 seed=$3 tag run extra=()
    tag=$(echo "$variant" | tr 'A-Z+' 'a-z_')
    run=$WORK/runs/$model-$tag-s$seed
    [ "$SIZE" = 128x416 ] || run=$WORK/runs/$model-$SIZE-$tag-s$seed
    [ -f "$run/real.json" ] && return 0
    [ "${variant%-fp}" != "$variant" ] && extra=(--flip --photometric)
    case ${variant%-fp} in
        S) args=(--dataset synth --root "$SYN") ;;
        R-auto) args=(--dataset kitti-raw --root "$RAW" --labels "$AL" --splits "$WORK/splits-raw") ;;
        HA-R-auto) args=(--dataset kitti-raw --root "$RAW" --labels "$AL" --splits "$WORK/splits-raw"
                         --augment homography --cache-dir "$WORK/sgbm-cache") ;;
        R-auto-dup) args=(--dataset kitti-raw --root "$RAW" --labels "$AL" --splits "$WORK/splits-raw"
                          --augment duplicate --cache-dir "$WORK/sgbm-cache") ;;
        S+R-auto) args=(--dataset generic --root "$MIX" --splits "$MIX/splits") ;;
        *) echo "unknown variant $variant" >&2; return 2 ;;
    esac
    if [ -f "$run/checkpoints/last.ckpt" ] && [ ! -f "$run/metrics.json" ]; then
        # --config: a package pinned before f802195 does not read the run's config.yaml on --resume by itself
        OMP_NUM_THREADS=1 $FREESPACE train --config "$run/config.yaml" --out "$run" --resume > "$run.log" 2>&1 || return 1
    elif [ ! -f "$run/metrics.json" ]; then
        [ "$model" = fastscnn ] || args+=($LITE0)  # Fast-SCNN: its own encoder, trained from scratch
        OMP_NUM_THREADS=1 $FREESPACE train "${args[@]}" "${extra[@]}" --model "$model" --seed "$seed" "${COMMON[@]}" \
            --out "$run" > "$run.log" 2>&1 || return 1
    fi
    OMP_NUM_THREADS=1 "$PYTHON" "$HERE/evaluate.py" ${RENDERED:+--rendered "$RENDERED"} "$run" >> "$run.log" 2>&1
}
export -f cell
export WORK RAW AL SYN MIX FREESPACE PYTHON HERE SIZE LITE0 RENDERED=${RENDERED:-}
export COMMON_TEXT="${COMMON[*]}"
mkdir -p "$WORK/runs"
for seed in $SEEDS; do for model in $MODELS; do for variant in $VARIANTS; do
    echo "$model $variant $seed"
done; done; done | xargs -P "$JOBS" -L 1 bash -c 'COMMON=($COMMON_TEXT); cell "$0" "$1" "$2"'
"$PYTHON" "$HERE/evaluate.py" --table "$WORK/runs" > "$WORK/results.md"
