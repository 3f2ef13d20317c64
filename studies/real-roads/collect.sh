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
    dest=$HERE/runs/$(basename "$run")
    if [ -f "$dest/metrics.json" ] && ! cmp -s "$run/metrics.json" "$dest/metrics.json"; then
        echo "kept $dest: its record is of another run of that cell (a rerun, or another commit); rename one" >&2
        continue
    fi
    mkdir -p "$dest/splits"
    for f in config.yaml inputs.json metrics.csv metrics.json real.json rendered.json; do
        [ -f "$run/$f" ] && cp "$run/$f" "$dest/$f"
    done
    cp "$run"/splits/*.txt "$dest/splits/"
done
"${PYTHON:-python}" "$HERE/evaluate.py" --table "$HERE/runs" > "$HERE/results.md.tmp" && mv "$HERE/results.md.tmp" "$HERE/results.md"
