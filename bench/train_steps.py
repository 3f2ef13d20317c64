"""Where a training step's time goes in `freespace train`: decoding a frame (PNG read + resize, paid once
per frame thanks to the decoded cache), the conventional augmentation, the conversion to tensors and
collation, the forward pass with the losses, and backward + SGD step — per batch, on the CPU, for U-Net
light at 192×256 by default. Also the whole step as `freespace train` runs it (Lightning, one epoch of a
short run). Prints the figures and writes them to BENCHMARKS.md.

    .venv/bin/python bench/train_steps.py [--model unet] [--size 192x256] [--batch 4] [--frames 16]
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, timeit, write_section  # noqa: E402
from freespace.data.registry import get_dataset  # noqa: E402
from freespace.data.synthetic import SynthConfig, write_dataset  # noqa: E402
from freespace.data.torch_dataset import RoadSegmentationDataset  # noqa: E402
from freespace.engine.config import TrainConfig  # noqa: E402
from freespace.engine.option_values import parse_size  # noqa: E402
from freespace.engine.train import run_training  # noqa: E402
from freespace.labels import IGNORE_INDEX  # noqa: E402
from freespace.models import create_model  # noqa: E402


def components(root: Path, model_name: str, size: tuple[int, int], batch: int, repeat: int) -> dict[str, float]:
    """Seconds per batch of each part of a training step (medians over ``repeat``)."""
    ds = get_dataset("synth", root, disparity_source="none")
    names = [f.name for f in ds.labelled().frames]
    cold = RoadSegmentationDataset(ds, names, size=size)  # no cache: every call decodes
    warm = RoadSegmentationDataset(ds, names, size=size, affine=True, cache=True)
    for i in range(len(names)):
        warm.decoded(i)
    plain = RoadSegmentationDataset(ds, names, size=size, cache=True)
    for i in range(len(names)):
        plain.decoded(i)
    idx = list(range(batch))
    out = {
        "decode (PNG read + resize), once per frame": timeit(lambda: [cold.decoded(i) for i in idx], repeat, warmup=0),
        "cached sample → tensors (no augmentation)": timeit(lambda: [plain[(0, i)] for i in idx], repeat, warmup=0),
        "cached sample + augmentation → tensors": timeit(lambda: [warm[(1, i)] for i in idx], repeat, warmup=0),
    }
    samples = [warm[(1, i)] for i in idx]
    out["collate"] = timeit(lambda: torch.utils.data.default_collate(samples), repeat, warmup=0)
    torch.manual_seed(0)
    model = create_model(model_name).train()
    opt = torch.optim.SGD(model.parameters(), lr=0.001, momentum=0.9)
    b = torch.utils.data.default_collate(samples)
    x, y = b["image"], b["label"]
    model.loss(model(x), y, IGNORE_INDEX)["total"].backward()  # warm-up

    def forward() -> torch.Tensor:
        return model.loss(model(x), y, IGNORE_INDEX)["total"]

    backward_seconds = []

    def backward() -> None:
        loss = forward()
        opt.zero_grad()
        t0 = time.perf_counter()
        loss.backward()
        opt.step()
        backward_seconds.append(time.perf_counter() - t0)

    out["forward + losses"] = timeit(forward, repeat, warmup=0)
    for _ in range(repeat):
        backward()
    out["backward + SGD step"] = float(np.median(backward_seconds))
    return out


def train_step(root: Path, model_name: str, size: tuple[int, int], batch: int,
               epochs: int, lr_schedule: str = "constant") -> tuple[float, int, int]:
    """`freespace train` with ``lr_schedule``: seconds of the fastest epoch after the first (its training steps and
    its validation, as metrics.csv times them), the training steps per epoch and the validation frames."""
    with tempfile.TemporaryDirectory() as tmp:
        config = TrainConfig(dataset="synth", root=str(root), out=f"{tmp}/run", model=model_name, epochs=epochs,
                             batch_size=batch, image_size=size, patience=epochs, lr_schedule=lr_schedule)
        metrics = run_training(config, progress=False)
        rows = list(csv.DictReader(open(f"{tmp}/run/metrics.csv")))
    steps = -(-metrics["frames"]["train"] // batch)
    return min(float(r["seconds"]) for r in rows[1:]), steps, metrics["frames"]["val"]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--model", default="unet")
    parser.add_argument("--size", default="192x256")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--lr-schedules", default="constant",
                        help="comma-separated learning-rate schedules to time `freespace train` with; a name "
                             "repeated is timed again, alternately, and its fastest run kept")
    parser.add_argument("--label", default="", help="a note for the section title (e.g. before/after)")
    args = parser.parse_args()
    size = parse_size(args.size)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "data"
        write_dataset(root, args.frames, config=SynthConfig(width=640, height=480, frames_per_scenario=2),
                      progress=False)
        parts = components(root, args.model, size, args.batch, args.repeat)
        schedules = args.lr_schedules.split(",")
        timed: dict[str, tuple[float, int, int]] = {}
        for name in schedules:  # a name given again is timed again, alternately; its fastest run is kept
            timed[name] = min(timed.get(name, (float("inf"), 0, 0)),
                              train_step(root, args.model, size, args.batch, args.epochs, name))
    total = sum(v for k, v in parts.items() if not k.startswith(("decode", "cached sample →")))
    rows = [f"| {k} | {1000 * v:.1f} |" for k, v in parts.items()]
    body = f"""Machine: {machine()}, PyTorch {torch.__version__}, {torch.get_num_threads()} threads.
Command: `.venv/bin/python bench/train_steps.py --model {args.model} --size {args.size} --batch {args.batch} \
--frames {args.frames} --epochs {args.epochs} --lr-schedules {args.lr_schedules}`
({args.model} light, {args.frames} rendered 640×480 frames resized to {args.size}, medians of {args.repeat}).

| part of one training step (batch {args.batch}) | ms per batch |
|---|---:|
""" + "\n".join(rows) + f"""
| **sum of augmentation, collation, forward, backward** | **{1000 * total:.1f}** |

""" + "\n".join(f"`freespace train --lr-schedule {name}` on the same frames: the fastest epoch after the first of "
                f"{args.epochs} took {epoch:.2f} s for {steps} training steps, the validation of {val} frames and the "
                f"two checkpoint writes (best.ckpt, last.ckpt)." for name, (epoch, steps, val) in timed.items()) + "\n"
    print(body)
    write_section(f"Where a training step's time goes (bench/train_steps.py){args.label}", body)


if __name__ == "__main__":
    main()
