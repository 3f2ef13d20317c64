#!/usr/bin/env bash
# Rebuild the published models/real-road-fast from this repository's history: its first model, the three adapt
# teachers, the drives' look-checked autolabels, the student dataset and (TRAIN=1) the training run, each step at
# the commit the model card names, then check what can be checked against the published files.
#
#   RAW=DIR FRAMES=DIR OUT=DIR [TRAIN=1] [SEED=0] [PYTHON=.venv/bin/python] bash studies/real-roads/rebuild.sh
#
# RAW: the KITTI raw root fetch.sh lays out (the two drives). FRAMES: CamVid's 367 training images
# (real_dev/make.sh's DEST/camvid/train). OUT: a folder outside the repository; each step writes its own
# subfolder and a step whose subfolder is complete is skipped, so an interrupted rebuild continues.
# Needs a clone with history (the pinned commits). One thread a step, as the card's cells ran.
set -euo pipefail
: "${RAW:?set RAW to the KITTI raw root fetch.sh wrote}" "${FRAMES:?set FRAMES to the 367 CamVid training images}"
: "${OUT:?set OUT to a folder outside the repository}"
REPO=$(cd "$(dirname "$0")/../.." && pwd)
PYTHON=${PYTHON:-$REPO/.venv/bin/python}
SEED=${SEED:-0}
FIRST=732c574 TEACHERS=5e60b3e DATASET=aa6feef TRAINING=11b8e7f   # the card's "How it was made"
TEACHER_SHA=(816dacca82a4dc45ce4baf3498587e2fdb1d2d2b95204479d750a8d02b755b84
             55fe864392e144afc894bf66c4451bc729dd46d87e63f61c0e7ec062300ebe6b
             e853ff5d740d1eff6f3a669e1ecf12a8307563ce329e6d7bbe298c3e7ad8a038)
LABELS_SHA=d6514e938c78eedc178dda5733167fecf722092537314e0bc43539d799dc9670
fail() { echo "rebuild.sh: error: $*" >&2; exit 2; }
[ -d "$RAW/2011_09_26" ] || fail "$RAW holds no 2011_09_26 drives: lay them out with studies/real-roads/fetch.sh first"
[ "$(find "$FRAMES" -maxdepth 1 -name '*.png' 2>/dev/null | wc -l)" -eq 367 ] \
    || fail "$FRAMES does not hold CamVid's 367 training images (real_dev/make.sh's DEST/camvid/train)"
[ -x "$PYTHON" ] || fail "no Python at $PYTHON: run make test once (it sets up .venv), or set PYTHON"
out=$(realpath -m "$OUT")/
for inside in "$REPO" "$(realpath -m "$RAW")" "$(realpath -m "$FRAMES")"; do
    case "$out" in
        "$inside"/*) fail "OUT $OUT lies inside $inside (the repository or an input): choose a folder outside it" ;;
    esac
done
for c in $FIRST $TEACHERS $DATASET $TRAINING; do
    git -C "$REPO" cat-file -e "$c^{commit}" 2>/dev/null || fail "commit $c is not in $REPO: rebuild from a full clone"
done
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
mkdir -p "$OUT/src"
# the code of commit C, unpacked once under OUT/src/C (the repository itself is not touched)
source_of() {
    local dir=$OUT/src/$1
    if [ ! -e "$dir/.done" ]; then
        rm -rf "$dir" && mkdir -p "$dir"
        git -C "$REPO" archive "$1" freespace studies | tar -x -C "$dir"
        touch "$dir/.done"
    fi
    echo "$dir"
}
# freespace at commit C: freespace_at C ARGS...
freespace_at() {
    local src; src=$(source_of "$1"); shift
    (cd "$src" && PYTHONPATH=$src "$PYTHON" -c 'import sys; from freespace.cli import main; sys.exit(main())' "$@")
}
step() { echo "rebuild.sh: $(date -u +%H:%M:%S) $*"; }

if [ ! -s "$OUT/first/model.onnx" ]; then
    step "the first model ($FIRST)"
    mkdir -p "$OUT/first.part"
    for f in model.onnx model.ckpt README.md; do
        git -C "$REPO" show "$FIRST:models/real-road-fast/$f" > "$OUT/first.part/$f"
    done
    rm -rf "$OUT/first" && mv -T "$OUT/first.part" "$OUT/first"
fi
for s in 0 1 2; do
    t=$OUT/teachers/t$s
    if [ ! -s "$t/model.onnx" ]; then
        step "teacher $s: adapt at $TEACHERS"
        rm -rf "$t"  # what an interrupted step left
        freespace_at $TEACHERS adapt --model "$OUT/first" --input "$FRAMES" --out "$t" --seed $s --threads 1 \
            --across-time off
    fi
    got=$(sha256sum "$t/model.onnx" | cut -d' ' -f1)
    [ "$got" = "${TEACHER_SHA[$s]}" ] \
        || { echo "rebuild.sh: teacher $s differs from the published one ($got, not ${TEACHER_SHA[$s]})" >&2; exit 1; }
done
step "the three teachers are the published ones, bit for bit"
if [ ! -e "$OUT/autolabels-look/.done" ]; then
    step "the drives' autolabels, carried along time, look-checked (at $DATASET)"
    rm -rf "$OUT/single" "$OUT/autolabels" "$OUT/autolabels-look"
    freespace_at $DATASET autolabel --dataset kitti-raw --root "$RAW" --disparity-source fused --out "$OUT/single"
    freespace_at $DATASET autolabel --propagate-from "$OUT/single" --dataset kitti-raw --root "$RAW" \
        --disparity-source fused --out "$OUT/autolabels"
    freespace_at $DATASET autolabel --dataset kitti-raw --root "$RAW" --look-from "$OUT/autolabels" \
        --out "$OUT/autolabels-look"
    touch "$OUT/autolabels-look/.done"
fi
if [ ! -s "$OUT/mix/report.json" ]; then
    step "the student dataset (at $DATASET)"
    src=$(source_of $DATASET)
    rm -rf "$OUT/mix"
    # PYTHONPATH: a script's folder, not the working one, heads sys.path; freespace must be the commit's, not the venv's
    (cd "$src" && PYTHONPATH=$src "$PYTHON" studies/real-roads/student.py --raw "$RAW" \
        --autolabels "$OUT/autolabels-look" --splits studies/real-roads/splits-raw --frames "$FRAMES" \
        --teacher "$OUT/teachers/t0" --teacher "$OUT/teachers/t1" --teacher "$OUT/teachers/t2" --drive-copies 3 \
        --carry --complete --release 0.1 --release-far 0.4 --look 0.45,0.70 --out "$OUT/mix")
fi
got=$("$PYTHON" -c 'import json, sys; print(json.load(open(sys.argv[1]))["labels_sha256"])' "$OUT/mix/report.json")
if [ "$got" = "$LABELS_SHA" ]; then
    step "the student dataset's labels are the published ones (labels_sha256 $got)"
else
    step "the student dataset's labels_sha256 is $got, not the published $LABELS_SHA: at $DATASET the look" \
        "check's classifier starts from torch's per-process random state (the card: a few 8x8 cells differ)"
fi
[ "${TRAIN:-0}" = 1 ] || { step "done (TRAIN=1 trains seed $SEED too)"; exit 0; }
run=$OUT/run-s$SEED
if [ ! -s "$run/checkpoints/best.ckpt" ] || [ ! -s "$run/metrics.json" ]; then
    step "training seed $SEED (at $TRAINING; about 45 minutes on one thread)"
    resume=(); [ -e "$run/checkpoints/last.ckpt" ] && resume=(--resume)
    freespace_at $TRAINING train --dataset generic --root "$OUT/mix" \
        --splits "$OUT/mix/splits" --model contextnet --encoder-name efficientnet-lite0 --encoder-weights imagenet \
        --image-size 288x960 --epochs 16 --patience 10 --val-window 3 --min-delta 0.001 --lr 0.01 --batch-size 4 \
        --flip --photometric --seed "$SEED" --no-progress "${resume[@]}" --out "$run"
fi
step "done: $run (score it with bench/real_bench.py --model NAME=$run/checkpoints/best.ckpt)"
