"""What one training epoch costs, per network and variant, at the sizes of a planned `reproduce` run.

Trains each configuration for ``--epochs`` epochs (``freespace train`` in a fresh process, one thread unless
``--threads``) on ``--root`` and reports the seconds of its last epoch (training and validation, from the
run's metrics.csv) and the set-up time (data, DS-Generator views, first epoch's decoding). The plan of a
long run (studies/converged/plan.md) is made from these figures.

With ``--before CHECKOUT`` (a source tree of the code before a speed-up, e.g. a git worktree) each
configuration is also run with that code, alternately with this one, and the table gives both and their ratio.

Usage: python bench/epoch_cost.py --root DATASET [--cells NAME=MODEL:ENCODER:WEIGHTS:HxW ...] [--before DIR] [--write]
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

from _common import ROOT, machine, write_section

#: the configurations of the converged run (issue 23): name = model:encoder:weights:HxW (empty = preset's)
CELLS = {
    "deeplabv3plus-lite0": "deeplabv3plus:efficientnet-lite0:imagenet:320x416",
    "denseaspp": "denseaspp:::224x288",
    "unet-lite0": "unet:efficientnet-lite0:imagenet:192x256",
    "dupsampling-lite0": "dupsampling:efficientnet-lite0:imagenet:192x256",
    "segnet": "segnet:::192x256",
}


def run(root: Path, spec: str, augment: str, epochs: int, threads: int, batch: int,
        code: Path | None = None) -> tuple[float, float]:
    """``(seconds of the last epoch, seconds before the first epoch's training)`` of one short run, with the
    package of the source tree ``code`` (default: the installed one)."""
    model, encoder, weights, size = spec.split(":")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "-m", "freespace.cli", "train", "--dataset", "synth", "--root", str(root), "--model",
               model, "--image-size", size, "--epochs", str(epochs), "--batch-size", str(batch), "--augment", augment,
               "--no-progress", "--out", str(out)]
        cmd += ["--encoder-name", encoder] if encoder else []
        cmd += ["--encoder-weights", weights] if weights else []
        env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
        if code is not None:
            env["PYTHONPATH"] = str(code)
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
    p.add_argument("--before", type=Path, help="a source tree of the code before a speed-up, timed alternately")
    p.add_argument("--write", action="store_true", help="write the section of BENCHMARKS.md")
    args = p.parse_args()
    cells = dict(c.split("=", 1) for c in args.cells) if args.cells else CELLS
    header = machine()
    lines = (["| configuration | augment | size | s / epoch before | s / epoch after | after / before |",
              "|---|---|---|---:|---:|---:|"] if args.before else
             ["| configuration | augment | size | s / epoch (train + val) | other (start, views, tests) s |",
              "|---|---|---|---:|---:|"])
    for name, spec in cells.items():
        for augment in args.variants.split(","):
            size = spec.rsplit(":", 1)[1]
            epoch, other = run(args.root, spec, augment, args.epochs, args.threads, args.batch_size)
            if args.before:
                before, _ = run(args.root, spec, augment, args.epochs, args.threads, args.batch_size, args.before)
                lines.append(f"| {name} | {augment} | {size} | {before:.1f} | {epoch:.1f} | {epoch / before:.2f} |")
            else:
                lines.append(f"| {name} | {augment} | {size} | {epoch:.1f} | {other:.1f} |")
            print(lines[-1], flush=True)
    command = (f"`python bench/epoch_cost.py --root {args.root} --epochs {args.epochs} --threads {args.threads} "
               f"--batch-size {args.batch_size}{f' --before {args.before}' if args.before else ''}`")
    before = f" Before: the code at {_commit(args.before)}; after: {_commit(ROOT)}." if args.before else ""
    body = (f"Machine: {header}. {command}: the last of {args.epochs} epochs of `freespace train` on the run's "
            f"training set, one process with {args.threads} thread(s).{before}\n\n" + "\n".join(lines))
    print(body)
    if args.write:
        name = "Epoch cost before and after a speed-up" if args.before else "Epoch cost of the converged run"
        write_section(f"{name} (bench/epoch_cost.py)", body)


def _commit(tree: Path) -> str:
    """The short commit of the git checkout ``tree`` (or its path, when it is not one)."""
    done = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 else str(tree)


if __name__ == "__main__":
    main()
