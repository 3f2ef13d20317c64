"""What one training epoch costs, per network and variant, at the sizes of a planned `reproduce` run.

Trains each configuration for ``--epochs`` epochs (``freespace train`` in a fresh process, one thread unless
``--threads``) on ``--root`` and reports the seconds of its last epoch (training and validation, from the
run's metrics.csv) and the set-up time (data, DS-Generator views, first epoch's decoding). The plan of a
long run (docs/results/converged/plan.md) is made from these figures.

Usage: python bench/epoch_cost.py --root DATASET [--cells NAME=MODEL:ENCODER:WEIGHTS:HxW ...] [--write]
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import machine, write_section

#: the configurations of the converged run (issue 23): name = model:encoder:weights:HxW (empty = preset's)
CELLS = {
    "deeplabv3plus-lite0": "deeplabv3plus:efficientnet-lite0:imagenet:320x416",
    "denseaspp": "denseaspp:::224x288",
    "unet-lite0": "unet:efficientnet-lite0:imagenet:192x256",
    "dupsampling-lite0": "dupsampling:efficientnet-lite0:imagenet:192x256",
    "segnet": "segnet:::192x256",
}


def run(root: Path, spec: str, augment: str, epochs: int, threads: int, batch: int) -> tuple[float, float]:
    """``(seconds of the last epoch, seconds before the first epoch's training)`` of one short run."""
    model, encoder, weights, size = spec.split(":")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "-m", "freespace.cli", "train", "--dataset", "synth", "--root", str(root), "--model",
               model, "--image-size", size, "--epochs", str(epochs), "--batch-size", str(batch), "--augment", augment,
               "--no-progress", "--out", str(out)]
        cmd += ["--encoder-name", encoder] if encoder else []
        cmd += ["--encoder-weights", weights] if weights else []
        env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        wall = time.perf_counter() - t0
        rows = list(csv.DictReader((out / "metrics.csv").open()))
    seconds = [float(r["seconds"]) for r in rows]
    return seconds[-1], wall - sum(seconds)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--root", type=Path, required=True, help="the rendered training set of the run")
    p.add_argument("--cells", nargs="*", help="NAME=MODEL:ENCODER:WEIGHTS:HxW (default: the converged run's)")
    p.add_argument("--variants", default="none,homography", help="--augment values to time (default none,homography)")
    p.add_argument("--epochs", type=int, default=2)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--batch-size", type=int, default=2)
    p.add_argument("--write", action="store_true", help="write the section of BENCHMARKS.md")
    args = p.parse_args()
    cells = dict(c.split("=", 1) for c in args.cells) if args.cells else CELLS
    header = machine()
    lines = ["| configuration | augment | size | s / epoch (train + val) | other (start, views, tests) s |",
             "|---|---|---|---:|---:|"]
    for name, spec in cells.items():
        for augment in args.variants.split(","):
            epoch, other = run(args.root, spec, augment, args.epochs, args.threads, args.batch_size)
            lines.append(f"| {name} | {augment} | {spec.rsplit(':', 1)[1]} | {epoch:.1f} | {other:.1f} |")
            print(lines[-1], flush=True)
    body = (f"Machine: {header}. `python bench/epoch_cost.py --root {args.root} --epochs {args.epochs} --threads "
            f"{args.threads} --batch-size {args.batch_size}`: the last of {args.epochs} epochs of `freespace train` "
            f"on the run's training set, one process with {args.threads} thread(s).\n\n" + "\n".join(lines))
    print(body)
    if args.write:
        write_section("Epoch cost of the converged run (bench/epoch_cost.py)", body)


if __name__ == "__main__":
    main()
