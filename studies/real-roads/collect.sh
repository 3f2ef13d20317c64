#!/usr/bin/env bash
# Copy finished cells' records (config, inputs, per-epoch CSV, metrics, real.json, rendered.json, splits; never
# checkpoints, logs or runtime files) from a working folder's runs/ into runs/ beside this script, then rebuild
# results.md from them:  WORK=DIR [PYTHON=python] bash studies/real-roads/collect.sh
set -euo pipefail
: "${WORK:?set WORK to the working folder of the study}"
HERE=$(cd "$(dirname "$0")" && pwd)
for run in "$WORK"/runs/*/; do
    run=${run%/}
    [ -f "$run/real.json" ] || continue  # unfinished, or not evaluated yet
    name=$(basename "$run")
    dest=$HERE/runs/$name
    if [ -f "$dest/metrics.json" ] && ! cmp -s "$run/metrics.json" "$dest/metrics.json"; then
        echo "kept $dest: its record is of another run of that cell (a rerun, or another commit); rename one" >&2
        continue
    fi
    missing=""
    for f in config.yaml metrics.json splits/train.txt; do [ -f "$run/$f" ] || missing="$missing $f"; done
    if [ -n "$missing" ]; then
        echo "skipped $run: no$missing (a record is copied whole or not at all)" >&2
        continue
    fi
    # copied into a hidden staging folder (the table reads */real.json only), then moved into place whole
    part=$HERE/runs/.$name.part
    rm -rf "$part" && mkdir -p "$part/splits"
    for f in config.yaml inputs.json metrics.csv metrics.json real.json rendered.json; do
        if [ -f "$run/$f" ]; then cp "$run/$f" "$part/$f"; fi
    done
    cp "$run"/splits/*.txt "$part/splits/"
    rm -rf "$dest" && mv -T "$part" "$dest"
done
"${PYTHON:-python}" "$HERE/evaluate.py" --table "$HERE/runs" > "$HERE/results.md.tmp" && mv "$HERE/results.md.tmp" "$HERE/results.md"
