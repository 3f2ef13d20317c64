"""Per-frame inference at KITTI size (1242×375, padded inside the model) on the CPU for every network,
with PyTorch and with ONNX Runtime (exported like `freespace export`), beside the paper's 0.06 s for
HA-DeepLabv3+ (on a GPU). Prints the figures and writes them to BENCHMARKS.md.

    .venv/bin/python bench/infer.py [--preset light] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, timeit, write_section  # noqa: E402

from freespace.models import create_model, list_models  # noqa: E402

H, W = 375, 1242


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--preset", default="light")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    import onnxruntime as ort

    torch.manual_seed(0)
    x = torch.rand(1, 3, H, W)
    rows = []
    for name in list_models():
        model = create_model(name, preset=args.preset).eval()
        with torch.inference_mode():
            t_torch = timeit(lambda: model(x), args.repeat, warmup=1)
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            path = f"{tmp}/m.onnx"
            torch.onnx.export(model, (x,), path, dynamo=False, opset_version=17, input_names=["image"],
                              dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}})
            session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
            xn = x.numpy()
            t_ort = timeit(lambda: session.run(None, {"image": xn}), args.repeat, warmup=1)
            with torch.inference_mode():
                diff = float(np.abs(session.run(None, {"image": xn})[0] - model(x).numpy()).max())
        rows.append(f"| {name} | {t_torch:.3f} | {t_ort:.3f} | {diff:.1e} |")
        print(rows[-1], flush=True)
    gpu = "no GPU was lent to this session" if not torch.cuda.is_available() else "see below"
    body = f"""Machine: {machine()}, PyTorch {torch.__version__} ({torch.get_num_threads()} threads), ONNX Runtime {ort.__version__}.
Command: `.venv/bin/python bench/infer.py --preset {args.preset} --repeat {args.repeat}` (batch 1, 3×375×1242 in, logits out,
median of {args.repeat} after one warm-up). GPU: {gpu}. The paper reports 0.06 s per frame for HA-DeepLabv3+ on a GPU.

| model ({args.preset}) | PyTorch CPU s/frame | ONNX Runtime CPU s/frame | max abs difference |
|---|---:|---:|---:|
""" + "\n".join(rows) + "\n"
    print(body)
    write_section(f"Inference (bench/infer.py, {args.preset})", body)


if __name__ == "__main__":
    main()
