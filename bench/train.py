"""Training speed: images/s of one training step (forward, losses, backward, SGD) per network at a stated
size on the CPU, and the 2-process DDP speed-up of a whole `freespace train` epoch. Prints the figures and
writes them to BENCHMARKS.md.

    .venv/bin/python bench/train.py [--size 192x384] [--batch 4] [--label " — after"]
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, write_section  # noqa: E402
from freespace.data.synthetic import SynthConfig, write_dataset  # noqa: E402
from freespace.engine.option_values import parse_size  # noqa: E402
from freespace.models import create_model, list_models  # noqa: E402


def step_rate(name: str, size: tuple[int, int], batch: int, steps: int = 4) -> float:
    torch.manual_seed(0)
    model = create_model(name).train()
    opt = torch.optim.SGD(model.parameters(), lr=0.001, momentum=0.9)
    x = torch.rand(batch, 3, *size)
    y = (torch.rand(batch, *size) > 0.5).long()

    def step() -> None:
        opt.zero_grad()
        model.loss(model(x), y)["total"].backward()
        opt.step()

    step()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return steps * batch / (time.perf_counter() - t0)


def epoch_seconds(root: Path, devices: int, size: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [str(Path(sys.executable).with_name("freespace")), "train", "--dataset", "synth", "--root", str(root),
               "--model", "unet", "--epochs", "3", "--batch-size", "4", "--image-size", size, "--no-progress",
               "--out", f"{tmp}/run"]
        if devices > 1:
            cmd += ["--devices", str(devices), "--strategy", "ddp"]
        subprocess.run(cmd, check=True, capture_output=True)
        rows = list(csv.DictReader(open(f"{tmp}/run/metrics.csv")))
        return min(float(r["seconds"]) for r in rows[1:])  # skip the first epoch (image decoding)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", default="192x384")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--label", default="", help="a note for the section title (e.g. before/after)")
    args = parser.parse_args()
    size = parse_size(args.size)
    rows = []
    for name in list_models():
        rate = step_rate(name, size, args.batch)
        rows.append(f"| {name} | {rate:.1f} |")
        print(rows[-1], flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "data"
        write_dataset(root, 40, config=SynthConfig(width=384, height=192, frames_per_scenario=2), progress=False)
        one, two = epoch_seconds(root, 1, args.size), epoch_seconds(root, 2, args.size)
    body = f"""Machine: {machine()}, PyTorch {torch.__version__}, {torch.get_num_threads()} threads.
Command: `.venv/bin/python bench/train.py --size {args.size} --batch {args.batch}` (light presets, CPU).

| model | training images/s at {args.size} (batch {args.batch}) |
|---|---:|
""" + "\n".join(rows) + f"""

`freespace train` (U-Net light, 40 rendered frames at {args.size}: 24 train / 8 val / 8 test, batch 4), the fastest
of epochs 2–3: 1 process {one:.2f} s, 2 DDP processes (gloo) {two:.2f} s — speed-up {one / two:.2f}× on this \
2-core machine:
one process already keeps both cores busy with PyTorch's intra-op threads, so a second process has no core to add;
DDP pays off with more cores or GPUs.
"""
    print(body)
    write_section(f"Training (bench/train.py){args.label}", body)


if __name__ == "__main__":
    main()
