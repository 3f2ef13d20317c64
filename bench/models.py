"""Parameters and CPU forward time of the six networks at 1248×384 (KITTI size padded to /32), and the
overhead of our U-Net and DeepLabv3+ over the plain segmentation-models-pytorch model of the same
configuration (target ≈ 1.0). Prints the figures and writes them to BENCHMARKS.md.

    .venv/bin/python bench/models.py [--presets light,paper] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, write_section  # noqa: E402
from freespace.models import create_model, list_models  # noqa: E402
from freespace.models.smp_models import PRESETS, smp_kwargs  # noqa: E402

SIZE = (384, 1248)


def seconds(model: torch.nn.Module, repeat: int) -> float:
    x = torch.rand(1, 3, *SIZE)
    with torch.inference_mode():
        model(x)
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            model(x)
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--presets", default="light,paper")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    import segmentation_models_pytorch as smp

    torch.manual_seed(0)
    rows, ratios = [], []
    for preset in args.presets.split(","):
        for name in list_models():
            model = create_model(name, preset=preset).eval()
            params = sum(p.numel() for p in model.parameters()) / 1e6
            t = seconds(model, args.repeat)
            rows.append(f"| {name} | {preset} | {params:.1f} | {t:.3f} |")
            print(rows[-1], flush=True)
            if name in PRESETS:
                cls = {"unet": smp.Unet, "deeplabv3plus": smp.DeepLabV3Plus}[name]
                plain = cls(encoder_weights=None, classes=2, **smp_kwargs(name, PRESETS[name][preset])).eval()
                t_plain = seconds(plain, args.repeat)
                ratios.append(f"| {name} | {preset} | {t:.3f} | {t_plain:.3f} | {t / t_plain:.2f} |")
                print(ratios[-1], flush=True)
    body = f"""Machine: {machine()}, PyTorch {torch.__version__}, {torch.get_num_threads()} threads.
Command: `.venv/bin/python bench/models.py --presets {args.presets} --repeat {args.repeat}` (batch 1, 3×384×1248,
`torch.inference_mode`, median of {args.repeat} after one warm-up).

| model | preset | parameters (M) | CPU forward (s) |
|---|---|---:|---:|
""" + "\n".join(rows) + """

Ours (normalisation + padding inside the model) against the plain smp model of the same configuration:

| model | preset | ours (s) | plain smp (s) | ratio |
|---|---|---:|---:|---:|
""" + "\n".join(ratios) + "\n"
    print(body)
    write_section("Segmentation networks (bench/models.py)", body)


if __name__ == "__main__":
    main()
