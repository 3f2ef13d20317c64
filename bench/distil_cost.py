"""What a teacher costs a training step (`freespace train --teacher`): seconds per step of the student alone and
with a teacher run on every batch, on the CPU. By default the published fast recipe's student (ContextNet, its
context branch an EfficientNet-Lite0) and the accurate recipe's network as teacher (a Lite2 U-Net), at 288×960,
batch 4: the distillation plan of studies/real-roads. Weights are random (the cost does not depend on them; no
download); the labels leave a band at the top don't care, as a road label does the sky. Prints the figures and, with
``--write-benchmarks``, writes them to BENCHMARKS.md.

    .venv/bin/python bench/distil_cost.py [--size 288x960] [--batch 4] [--repeat 5] [--threads 2]
        [--write-benchmarks]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, timeit, write_section  # noqa: E402
from freespace.engine.module import RoadModule  # noqa: E402
from freespace.engine.option_values import parse_size  # noqa: E402
from freespace.labels import IGNORE_INDEX  # noqa: E402
from freespace.models import create_model  # noqa: E402

STUDENT = ("contextnet", {"preset": "light", "encoder_name": "efficientnet-lite0"})
TEACHER = ("unet", {"preset": "light", "encoder_name": "efficientnet-lite2"})


def step_seconds(size: tuple[int, int], batch: int, repeat: int, teacher: bool) -> float:
    """Median seconds of one training step (forward, losses, backward, SGD step) of the student at ``size``
    (H, W) on a batch of ``batch`` random frames, with the teacher attached when ``teacher``."""
    torch.manual_seed(0)
    module = RoadModule(*STUDENT, lr=0.01, momentum=0.9, weight_decay=0.0, image_size=list(size))
    module.log = lambda *a, **k: None  # no trainer here
    if teacher:
        module.attach_teacher(create_model(TEACHER[0], **TEACHER[1]))
    module.net.to(memory_format=torch.channels_last).train()
    opt = torch.optim.SGD(module.net.parameters(), lr=0.01, momentum=0.9)
    label = (torch.rand(batch, *size) > 0.5).long()
    label[:, : size[0] // 4] = IGNORE_INDEX
    batch_ = {"image": torch.rand(batch, 3, *size).contiguous(memory_format=torch.channels_last), "label": label}

    def step() -> None:
        opt.zero_grad()
        module.training_step(batch_, 0).backward()
        opt.step()

    return timeit(step, repeat, warmup=1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", default="288x960", help="HxW of the training batches")
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--repeat", type=int, default=5, help="steps timed (the median is reported)")
    p.add_argument("--threads", type=int, default=2, help="torch threads")
    p.add_argument("--write-benchmarks", action="store_true", help="write the section of BENCHMARKS.md")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    size = parse_size(args.size)
    alone = step_seconds(size, args.batch, args.repeat, teacher=False)
    taught = step_seconds(size, args.batch, args.repeat, teacher=True)
    body = (f"Machine: {machine()}; {args.threads} torch threads.\n\n"
            f"One training step (forward, losses, backward, SGD step; median of {args.repeat}) of the fast recipe's "
            f"student ({STUDENT[0]}, {STUDENT[1]['encoder_name']}) at {size[0]}×{size[1]}, batch {args.batch}, "
            f"with and without a teacher ({TEACHER[0]}, {TEACHER[1]['encoder_name']}) run on every batch; random "
            f"weights and frames.\n\n"
            f"| | seconds a step | × |\n|---|---:|---:|\n"
            f"| student alone | {alone:.3f} | 1.00 |\n"
            f"| with the teacher (`--teacher`) | {taught:.3f} | {taught / alone:.2f} |\n\n"
            f"Command: `.venv/bin/python bench/distil_cost.py --size {args.size} --batch {args.batch} "
            f"--repeat {args.repeat} --threads {args.threads} --write-benchmarks`.")
    print(body)
    if args.write_benchmarks:
        write_section("What a teacher costs a training step (bench/distil_cost.py)", body)


if __name__ == "__main__":
    main()
