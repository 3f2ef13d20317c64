#!/usr/bin/env bash
# Issue 23 §5 on a lent GPU machine (PyTorch installed there, no network, minutes of GPU time): the six networks'
# inference time per frame at the paper's 1248×384 on the GPU, then paper-scale cells: the `paper` presets
# (ResNet-101 DeepLabv3+, ...; from scratch, as no weights for their backbones can be installed offline) on the
# converged run's data at its native 320×416, with the converged run's protocol (lr 0.01, batch 2, patience 20 on
# the 3-epoch mean of the validation F-score, least improvement 0.001, cap 200; test sets shifted, matched and
# same-rigs). DeepLabv3+'s X, HA-X and X-dup of seed 0 first, then the other networks' HA-X and X-dup, three
# cells at a time, each started only while more than MIN_LEFT seconds are left; cells still training at the
# deadline are stopped and kept unfinished (their per-epoch CSV tells the epoch cost).
#
# Usage, in the repository root of the GPU machine: OUT=DIR BUDGET=SECONDS bash studies/gpu/run.sh
#   OUT: where the results go (log.txt, infer_*.md, datacheck.txt, cells.tgz: every run folder's small files,
#   never checkpoints); BUDGET: seconds from the start to the end of the script (default 540). Optional:
#   WHEELS (default .whl: wheels of the packages the machine lacks, installed into /tmp/site; empty: none),
#   WORK (default gpuwork: the data, made there when missing, and the run folders), PYTHON (default python3),
#   FS (default: $PYTHON -m freespace.cli), CELLS (the queue, "net,variant,seed ..."), PRESET (default paper),
#   CAP, PATIENCE, MIN_LEFT (default 120), PARALLEL (default 3).
# Do it all in one call: files the script leaves in WORK were not all there in the next call (session 17).
set -uo pipefail
T0=$(date +%s)
OUT=${OUT:?give OUT=DIR}
mkdir -p "$OUT"
DEADLINE=$((T0 + ${BUDGET:-540}))
REPO=$(pwd)
PY=${PYTHON:-python3}
exec > >(tee -a "$OUT/log.txt") 2>&1
say() { echo "[$(($(date +%s) - T0)) s] $*"; }

WHEELS=${WHEELS-.whl}
if [ -n "$WHEELS" ] && [ -d "$WHEELS" ]; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "$WHEELS"/*.whl \
    || { say "wheels failed"; exit 1; }
  export PYTHONPATH=/tmp/site:$REPO
fi
export PYTHONUNBUFFERED=1
FS=${FS:-"$PY -m freespace.cli"}
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null
$PY -c "import torch, freespace, segmentation_models_pytorch, albumentations
print('torch', torch.__version__, 'cuda', torch.cuda.is_available() and torch.cuda.get_device_name(),
      'cudnn tf32', torch.backends.cudnn.allow_tf32, 'matmul tf32', torch.backends.cuda.matmul.allow_tf32)" \
  || { say "the packages do not import"; exit 1; }

WORK=${WORK:-gpuwork}
mkdir -p "$WORK" && cd "$WORK" || exit 1
say "data (in the background)"
(
  r() { [ -d "$1" ] || $FS synth --out "$@" --width 416 --height 320 --frames-per-scenario 5 --workers 3 > /dev/null; }
  r syn --num 100 --seed 0 & r same-rigs --num 200 --seed 2 &
  r shifted --num 60 --seed 1 --max-roll 15 --camera-heights 0.6,4.5 --pitches -8,8 --baselines 0.2,2.0 &
  r matched --num 60 --seed 1 & wait
  [ -d autolabels ] || $FS autolabel --dataset synth --root syn --disparity-source sgbm --workers 4 --out autolabels \
    > /dev/null
) &
DATA=$!

say "inference at 384x1248"
for preset in paper light; do
  timeout 150 $PY "$REPO/bench/infer.py" --device cuda --preset $preset --size 384x1248 --repeat 30 \
    --section-file "$OUT/infer_$preset.md" > /dev/null || say "inference ($preset) failed"
done
wait $DATA || { say "data failed"; exit 1; }
say "data made"
$PY "$REPO/studies/converged/datacheck.py" . "$REPO/studies/converged" > "$OUT/datacheck.txt" 2>&1
say "datacheck exit $?: $(tail -1 "$OUT/datacheck.txt")"

PRESET=${PRESET:-paper}
COMMON="--dataset synth --root syn --protocol $REPO/studies/gpu/protocol.yaml --seeds 20 --epochs ${CAP:-200} --patience ${PATIENCE:-20} --val-window 3
        --min-delta 0.001 --lr 0.01 --batch-size 2 --image-size 320x416 --preset $PRESET --workers 2 --no-progress"
say "smoke: one epoch of deeplabv3plus HA-X on 25 frames"
if ! $FS reproduce $COMMON --max-frames 25 --epochs 1 --only deeplabv3plus,HA-X,0 --out smoke > "$OUT/smoke.txt" 2>&1
then
  say "smoke failed: $(tail -3 "$OUT/smoke.txt")"; exit 3
fi
say "smoke passed"

CELLS=${CELLS:-"deeplabv3plus,X,0 deeplabv3plus,HA-X,0 deeplabv3plus,X-dup,0 unet,HA-X,0 unet,X-dup,0
  dupsampling,HA-X,0 dupsampling,X-dup,0 denseaspp,HA-X,0 denseaspp,X-dup,0 segnet,HA-X,0 segnet,X-dup,0
  gscnn,HA-X,0 gscnn,X-dup,0"}
mkdir -p logs
declare -A PIDS=()
reap() { local c; for c in "${!PIDS[@]}"; do kill -0 "${PIDS[$c]}" 2>/dev/null && continue
  wait "${PIDS[$c]}"; say "$c ended, exit $?: $(tail -1 "logs/$c.log")"; unset "PIDS[$c]"; done; }
for c in $CELLS; do
  while [ ${#PIDS[@]} -ge "${PARALLEL:-3}" ]; do
    sleep 2; reap; [ "$(date +%s)" -lt $((DEADLINE - 25)) ] || break 2
  done
  if [ $((DEADLINE - $(date +%s))) -le "${MIN_LEFT:-120}" ]; then say "not started (time): $c"; continue; fi
  OMP_NUM_THREADS=2 $FS reproduce $COMMON --only "$c" --out res > "logs/$c.log" 2>&1 &
  PIDS[$c]=$!
  say "started $c"
done
while [ ${#PIDS[@]} -gt 0 ] && [ "$(date +%s)" -lt $((DEADLINE - 25)) ]; do sleep 2; reap; done
for c in "${!PIDS[@]}"; do say "stopped at the deadline: $c"; kill "${PIDS[$c]}"; done
[ ${#PIDS[@]} -eq 0 ] || wait "${PIDS[@]}"
$FS reproduce --tables --protocol "$REPO/studies/gpu/protocol.yaml" --out res > logs/tables.log 2>&1 || say "tables failed: $(tail -1 logs/tables.log)"
tar czf "$OUT/cells.tgz" --exclude='checkpoints' --exclude='generated' --exclude='*lock*' --exclude='*.tmp' \
  res/runs res/results.md res/results.csv res/gains.csv res/index.json logs 2>/dev/null
say "done"
