#!/usr/bin/env bash
# The converged run (issue 23; plan and costs in plan.md beside this file): the claim in the paper's regime.
# DeepLabv3+ (EfficientNet-Lite0, ImageNet weights, output stride 16) at 320x416, DenseASPP at 224x288 (their
# intact sizes), U-Net and DUpsampling (Lite0, ImageNet) and SegNet (no offline weights for VGG) at 192x256;
# variants X, HA-X, X-dup, X-long; 10 seeds (SEEDS=N for N, and for CELLS past seed 9); each run to early
# stopping (patience 20 on the 3-epoch mean of the validation F-score, cap 200 epochs; X-long 40 and 400; lr
# and least improvement from the pilot in plan.md: LR=0.01 MIN_DELTA=0.001 PATIENCE=20 CAP=200; sessions 1-3
# ran patience 10, cap 100); test sets: test, shifted (rigs the training set never had, much wider than the
# evidence run's), matched (shifted's scenes with the training rigs), same-rigs (200 frames of new drives with
# the training rigs; the primary endpoint's set).
#
# Cells run seed-major (every network and variant of seed 0 first, ...), two at a time with one thread each,
# as `reproduce --only` cells in WORK/res. A cell interrupted by the end of a session resumes from its
# last.ckpt the next time. After each finished cell its small files (config, per-epoch CSV, metrics, splits,
# test-set metrics; never checkpoints or views) are copied to RES/runs/ beside this script, and the tables are
# rebuilt there; on a new machine the copied cells are restored into WORK first, so they are not run again.
#
# Training on labels nobody drew (issue 22 §3): NETS="unet dupsampling" VARIANTS="X-auto X-mix" bash run.sh WORK
# The same on autolabels from the padded matcher (SGBM version 2, made beforehand with a freespace at ca4bddf or
# later: freespace autolabel --dataset synth --root syn --disparity-source sgbm --out autolabels2):
#   RES=res-auto2 AUTOLABELS=autolabels2 CELLS="unet,X-auto,0 ..." bash run.sh WORK
# The control of pretraining (X with the Lite encoders from scratch, kept in res-scratch/ beside this script):
#   RES=res-scratch WEIGHTS= NETS="unet dupsampling" VARIANTS=X bash run.sh WORK
# LR and MIN_DELTA set the learning rate and early stopping's least improvement (defaults 0.001 and 0, the
# session-1 pilot's), PATIENCE and CAP the patience and the epoch cap (defaults 10 and 100; X-long doubles
# both); plan.md names the values the run fixes. A larger PATIENCE or CAP extends the finished cells exactly.
# X-long starts as X's run of the seed continued (reproduce copies X's folder with its checkpoints and extends
# it), so X's cell must have finished in this WORK first; an X-long queued beside its X fails until X is done.
# Usage: bash run.sh WORK [STOP_AT]   (FREESPACE=/path/to/.venv/bin/freespace, PYTHON=its python; STOP_AT: a
#        `date` time after which no new cell starts, e.g. "14:10", or "2026-11-26 00:50" past midnight;
#        CELLS="net,variant,seed ..." to run only those; JOBS=1 for one cell at a time (default 2); KEEP=DIR
#        to keep the finished cells elsewhere than beside this script). Run it from a git worktree pinned at one commit (git worktree add --detach DIR
#        COMMIT), so that other work does not change the code under the cells; the commit of each session's
#        cells is in plan.md.
set -euo pipefail
DIR=$(cd "$(dirname "$0")" && pwd)  # this script's folder, taken before the cd into WORK below
FS=${FREESPACE:-freespace}
HERE=${KEEP:-$DIR}  # where finished cells are kept (default: beside this script)
RES=${RES:-res-final}                # the reproduce folder in WORK, and its copy in KEEP/RES
WEIGHTS=${WEIGHTS-imagenet}          # the Lite encoders' initial weights; WEIGHTS= (empty) for from scratch
HERE="$HERE/$RES"
WORK=$1
STOP_AT=$(date -d "${2:-tomorrow}" +%s)
# a bare "00:50" given at 22:40 is today's, already past: every cell would be skipped without a word
[ "$STOP_AT" -gt "$(date +%s)" ] || { echo "STOP_AT '$2' is already past; give a later time, or a date too" \
    "(e.g. \"$(date -d tomorrow +%F) ${2}\") when it is past midnight" >&2; exit 2; }
mkdir -p "$WORK" && cd "$WORK" && mkdir -p logs
[ -d syn ] || $FS synth --out syn --num 100 --width 416 --height 320 --frames-per-scenario 5 --seed 0 --workers 2
[ -d same-rigs ] || $FS synth --out same-rigs --num 200 --width 416 --height 320 --frames-per-scenario 5 --seed 2 \
    --workers 2
# shifted: rigs far outside the training set's (roll ±15°, camera 0.6–4.5 m, pitch ±8°, baseline 0.2–2.0 m);
# matched: the same 60 scenes (same seed: the renderer draws every rig value from the same stream) with the
# training rigs, so that shifted − matched is the viewpoint's own cost, scene for scene
[ -d shifted ] || $FS synth --out shifted --num 60 --width 416 --height 320 --frames-per-scenario 5 --seed 1 \
    --workers 2 --max-roll 15 --camera-heights 0.6,4.5 --pitches -8,8 --baselines 0.2,2.0
[ -d matched ] || $FS synth --out matched --num 60 --width 416 --height 320 --frames-per-scenario 5 --seed 1 \
    --workers 2
# labels nobody drew (issue 22: X-auto, X-mix), from SGBM on the rendered pairs: what a user without exact
# disparities has (against the human labels: precision 98.7 %, recall 99.0 %, 68.6 % of the pixels covered)
[ -d autolabels ] || $FS autolabel --dataset synth --root syn --disparity-source sgbm --out autolabels
# the data are made anew on a new machine: they must be those of the cells already finished (datacheck.py beside
# this script: labels, disparities, calibrations and rig tables byte for byte, as session 2 made them; images
# and autolabels within a CPU's float rounding), or the run would mix two datasets. The autolabels must be made by
# the package at f341a7f: since ca4bddf (the padded matcher) `autolabel` makes other ones, which the check refuses;
# from a later pin, make them first in WORK with a worktree at f341a7f on PYTHONPATH (session 21, plan.md)
PY=${PYTHON:-$(dirname "$(command -v "$FS")")/python}
$PY "$DIR/datacheck.py" . "$DIR" || exit 1

NETS=${NETS:-"unet dupsampling segnet denseaspp deeplabv3plus"}
VARIANTS=${VARIANTS:-"X HA-X X-dup X-long"}
SEEDS=${SEEDS:-10}
export FS WORK HERE STOP_AT RES WEIGHTS
# the variants' gains, the primary endpoint and the test sets (shifted, matched, same-rigs): protocol.yaml
COMMON="--dataset synth --root syn --protocol $DIR/protocol.yaml --seeds $SEEDS
        --epochs ${CAP:-100} --patience ${PATIENCE:-10} --val-window 3 --min-delta ${MIN_DELTA:-0}
        --lr ${LR:-0.001} --batch-size 2 --no-progress --out $RES"
export COMMON

SYNC=$DIR/sync.py
export PY SYNC
# restore the cells finished on another machine (their small files; a finished cell is never trained again)
$PY "$SYNC" restore "$HERE" "$RES"

cell() {  # net,variant,seed
  IFS=, read -r net variant seed <<< "$1"
  [ "$(date +%s)" -lt "$STOP_AT" ] || { echo "$(date +%T) not started (STOP_AT) $1"; return 0; }
  case $net in
    deeplabv3plus) opts="--image-size 320x416 --encoder-name efficientnet-lite0" ;;
    denseaspp) opts="--image-size 224x288" ;;
    unet|dupsampling) opts="--image-size 192x256 --encoder-name efficientnet-lite0" ;;
    segnet) opts="--image-size 192x256" ;;
  esac
  case $net in deeplabv3plus|unet|dupsampling) opts="$opts${WEIGHTS:+ --encoder-weights $WEIGHTS}" ;; esac
  # the autolabels only for the variants that train on them (reproduce refuses a label tree no cell reads)
  case $variant in X-auto|X-mix) opts="$opts --autolabels ${AUTOLABELS:-autolabels}" ;; esac
  log="logs/$RES-$(echo "$1" | tr , _).log"
  if OMP_NUM_THREADS=1 $FS reproduce $COMMON $opts --only "$1" > "$log" 2>&1; then
    run=$(grep -o 'runs/[^:]*' "$log" | tail -1)
    if $PY "$SYNC" save "$RES" "${run#runs/}" "$HERE"; then echo "$(date +%T) done $1"
    else echo "$(date +%T) FAILED to keep $1 (see $WORK/$log)"; fi
  else
    echo "$(date +%T) FAILED $1 (see $WORK/$log)"
  fi
}
export -f cell

if [ -n "${CELLS:-}" ]; then
  printf '%s\n' $CELLS
else
  for s in $(seq 0 $((SEEDS - 1))); do for n in $NETS; do for v in $VARIANTS; do echo "$n,$v,$s"; done; done; done
fi | xargs -P "${JOBS:-2}" -I{} bash -c 'cell {}'

# the tables of every finished cell, copied beside this script
$FS reproduce --tables --protocol "$DIR/protocol.yaml" --out "$RES" > "logs/$RES-tables.log" 2>&1 || { tail -3 "logs/$RES-tables.log"; exit 1; }
cp "$RES"/results.md "$RES"/results.csv "$RES"/gains.csv "$RES"/index.json "$HERE/"
mkdir -p "$HERE/figures" && cp "$RES"/figures/gains_*.png "$HERE/figures/" 2>/dev/null || true
