"""DUpsampling against DeepLabv3+ trained on the same budget (issue 13): a small rendered set, the
trainer's optimiser (SGD, lr 0.001, momentum 0.9), the same epochs, batch and seed; prints the
validation accuracy, precision, recall and F-score of the road class and writes them to BENCHMARKS.md.

    .venv/bin/python bench/dupsampling.py [--train 32 --val 16 --size 96x128 --epochs 25 --seeds 0]

``tests/test_models.py`` trains both the same way (its own copy of this loop, slow) and asserts DUpsampling ≥ 90 %
of DeepLabv3+'s F-score.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, write_section  # noqa: E402
from freespace.data.synthetic import render_sample  # noqa: E402
from freespace.data.synthetic.scene import SynthConfig  # noqa: E402
from freespace.evaluation.metrics import confusion_counts  # noqa: E402
from freespace.models import create_model, main_logits  # noqa: E402


def render_set(first: int, count: int, size: tuple[int, int], seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Frames ``first … first+count−1`` of the built-in renderer at ``size`` = (H, W): images
    ``N×3×H×W`` float in [0, 1] and labels ``N×H×W`` int64 (1 = road; every pixel valid)."""
    config = SynthConfig(width=size[1], height=size[0], frames_per_scenario=4)
    samples = [render_sample(i, seed, config) for i in range(first, first + count)]
    images = torch.from_numpy(np.stack([s.left for s in samples])).permute(0, 3, 1, 2).float() / 255
    labels = torch.from_numpy(np.stack([s.label.road for s in samples])).long()
    return images, labels


def train_and_score(name: str, train: tuple[torch.Tensor, torch.Tensor], val: tuple[torch.Tensor, torch.Tensor],
                    epochs: int, batch: int = 4, lr: float = 1e-3, seed: int = 0) -> dict[str, float]:
    """Train ``name`` (light preset, from scratch) and return its validation metrics of the last epoch
    (fractions: accuracy, precision, recall, f_score, iou) and the training seconds."""
    torch.manual_seed(seed)
    model = create_model(name)
    model.prepare(train[1])
    opt = torch.optim.SGD(model.parameters(), lr=lr, momentum=0.9)
    order = torch.Generator().manual_seed(seed)
    t0 = time.perf_counter()
    for _ in range(epochs):
        model.train()
        for idx in torch.randperm(len(train[0]), generator=order).split(batch):
            opt.zero_grad()
            loss = model.loss(model(train[0][idx]), train[1][idx])["total"]
            loss.backward()
            opt.step()
    seconds = time.perf_counter() - t0
    model.eval()
    with torch.no_grad():
        pred = torch.cat([main_logits(model(x)).argmax(1) for x in val[0].split(8)])
    metrics = confusion_counts(pred.numpy() == 1, val[1].numpy() == 1).metrics()
    return {**{k: metrics[k] for k in ("accuracy", "precision", "recall", "f_score", "iou")}, "seconds": seconds}


def compare(n_train: int = 32, n_val: int = 16, size: tuple[int, int] = (96, 128), epochs: int = 25,
            seed: int = 0) -> dict[str, dict[str, float]]:
    """Both networks on the same rendered frames and budget: ``{"deeplabv3plus": ..., "dupsampling": ...}``.
    Training frames come from the first scenarios, validation frames from later ones (4 frames a drive)."""
    train = render_set(0, n_train, size, seed)
    val = render_set(n_train, n_val, size, seed)
    return {name: train_and_score(name, train, val, epochs, seed=seed) for name in ("deeplabv3plus", "dupsampling")}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--train", type=int, default=32)
    parser.add_argument("--val", type=int, default=16)
    parser.add_argument("--size", default="96x128")
    parser.add_argument("--epochs", type=int, default=25)
    parser.add_argument("--seeds", default="0")
    parser.add_argument("--no-write", action="store_true", help="print only, leave BENCHMARKS.md alone")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        result = compare(args.train, args.val, size, args.epochs, seed)  # type: ignore[arg-type]
        for name, m in result.items():
            rows.append(f"| {seed} | {name} | {100 * m['accuracy']:.1f} | {100 * m['precision']:.1f} | "
                        f"{100 * m['recall']:.1f} | {100 * m['f_score']:.1f} | {100 * m['iou']:.1f} | "
                        f"{m['seconds']:.0f} |")
            print(rows[-1], flush=True)
    body = f"""Machine: {machine()}, PyTorch {torch.__version__}, {torch.get_num_threads()} threads.
Command: `.venv/bin/python bench/dupsampling.py --train {args.train} --val {args.val} --size {args.size} \
--epochs {args.epochs} --seeds {args.seeds}` (light presets, from scratch, SGD lr 0.001 momentum 0.9, batch 4,
no augmentation; validation on later drives; %).

| seed | model | accuracy | precision | recall | F-score | IoU | training (s) |
|---|---|---:|---:|---:|---:|---:|---:|
""" + "\n".join(rows) + "\n"
    print(body)
    if not args.no_write:
        write_section("DUpsampling against DeepLabv3+ on the same budget (bench/dupsampling.py)", body)


if __name__ == "__main__":
    main()
