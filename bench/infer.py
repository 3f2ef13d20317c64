"""Per-frame inference at KITTI size (1242×375, padded inside the model) for every network, beside the
paper's 0.06 s for HA-DeepLabv3+ (on a GPU). On the CPU with PyTorch and with ONNX Runtime (exported like
`freespace export`); with ``--device cuda`` with PyTorch on the GPU, in float32 and under float16 autocast
(each call synchronised; ``--size 384x1248`` is the paper's input). Prints the figures and writes them to
BENCHMARKS.md, or to ``--section-file`` (a machine whose BENCHMARKS.md does not come back).

    .venv/bin/python bench/infer.py [--preset light] [--repeat 3] [--device cuda] [--size HxW] [--section-file F]
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
from _common import machine, section_text, timeit, write_section  # noqa: E402
from freespace.models import create_model, list_models  # noqa: E402

H, W = 375, 1242
PAPER_SECONDS = "The paper reports 0.06 s per frame for HA-DeepLabv3+ on a GPU."


def cpu_rows(x: torch.Tensor, preset: str, repeat: int) -> list[str]:
    """``| model | PyTorch s | ONNX Runtime s | max abs difference |`` per network, on the CPU."""
    import onnxruntime as ort

    rows = []
    for name in list_models():
        model = create_model(name, preset=preset).eval()
        with torch.inference_mode():
            t_torch = timeit(lambda: model(x), repeat, warmup=1)
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            path = f"{tmp}/m.onnx"
            torch.onnx.export(model, (x,), path, dynamo=False, opset_version=17, input_names=["image"],
                              dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}})
            session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
            xn = x.numpy()
            t_ort = timeit(lambda: session.run(None, {"image": xn}), repeat, warmup=1)
            with torch.inference_mode():
                diff = float(np.abs(session.run(None, {"image": xn})[0] - model(x).numpy()).max())
        rows.append(f"| {name} | {t_torch:.3f} | {t_ort:.3f} | {diff:.1e} |")
        print(rows[-1], flush=True)
    return rows


def gpu_rows(x: torch.Tensor, preset: str, repeat: int) -> list[str]:
    """``| model | float32 ms | float16-autocast ms | max abs difference |`` per network, on the GPU (each
    call ends with ``torch.cuda.synchronize()``, so a time is the whole frame's; 5 warm-up calls)."""
    x = x.cuda()
    rows = []
    for name in list_models():
        rows.append(_gpu_row(name, x, preset, repeat))
        print(rows[-1], flush=True)
        torch.cuda.empty_cache()  # the network is gone with _gpu_row's frame
    return rows


def _gpu_row(name: str, x: torch.Tensor, preset: str, repeat: int) -> str:
    """One network's row of :func:`gpu_rows` (x already on the GPU)."""
    model = create_model(name, preset=preset).eval().cuda()

    def call(half: bool) -> torch.Tensor:
        with torch.inference_mode(), torch.autocast("cuda", dtype=torch.float16, enabled=half):
            y = model(x)
        torch.cuda.synchronize()
        return y

    t32 = timeit(lambda: call(False), repeat, warmup=5)
    t16 = timeit(lambda: call(True), repeat, warmup=5)
    diff = float((call(True).float() - call(False)).abs().max())
    return f"| {name} | {t32 * 1000:.1f} | {t16 * 1000:.1f} | {diff:.1e} |"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--preset", default="light")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--size", default=f"{H}x{W}", help="input HxW (default KITTI's 375x1242)")
    parser.add_argument("--section-file", help="write the section here instead of into BENCHMARKS.md")
    args = parser.parse_args()
    h, w = (int(v) for v in args.size.split("x"))
    torch.manual_seed(0)
    x = torch.rand(1, 3, h, w)
    command = " ".join(["python bench/infer.py", *sys.argv[1:]])
    if args.device == "cuda":
        rows = gpu_rows(x, args.preset, args.repeat)
        body = f"""Machine: {torch.cuda.get_device_name()} (CUDA {torch.version.cuda}), host {machine()}, \
PyTorch {torch.__version__}.
Command: `{command}` (batch 1, 3×{h}×{w} in, logits out, median of {args.repeat} after five warm-ups, each call
synchronised). {PAPER_SECONDS}

| model ({args.preset}) | PyTorch GPU float32 ms/frame | float16 autocast ms/frame | max abs difference |
|---|---:|---:|---:|
""" + "\n".join(rows) + "\n"
        name = f"Inference on a GPU (bench/infer.py, {args.preset}, {h}×{w})"
    else:
        import onnxruntime as ort

        rows = cpu_rows(x, args.preset, args.repeat)
        body = f"""Machine: {machine()}, PyTorch {torch.__version__} ({torch.get_num_threads()} threads), \
ONNX Runtime {ort.__version__}.
Command: `{command}` (batch 1, 3×{h}×{w} in, logits out, median of {args.repeat} after one warm-up).
GPU: none (`--device cuda` on a machine with one). {PAPER_SECONDS}

| model ({args.preset}) | PyTorch CPU s/frame | ONNX Runtime CPU s/frame | max abs difference |
|---|---:|---:|---:|
""" + "\n".join(rows) + "\n"
        name = f"Inference (bench/infer.py, {args.preset})"
    print(body)
    if args.section_file:
        Path(args.section_file).write_text(section_text(name, body))
    else:
        write_section(name, body)


if __name__ == "__main__":
    main()
