"""Publish a real-roads cell as a model of the repository (issue 45 §4): ``models/<name>/``.

    python studies/real-roads/publish.py RUN NAME --raw RAW [--fp16]

Writes ``models/NAME/model.onnx`` (``freespace export``, float16 with ``--fp16``), ``examples/`` (two real
KITTI raw frames of the drives' test blocks, never trained on, with their licence) and ``failures.jpg`` (the
model's masks on the two KITTI stereo 2015 frames: true positives green, false negatives red, false positives
blue), and prints the card's figures from ``RUN/real.json`` and ``RUN/metrics.json``. The card itself
(``README.md``) is written by hand from them.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))  # evaluate.py beside it

#: the example frames (drive, frame): in the test blocks of their drives
EXAMPLES = (("2011_09_26_drive_0001_sync", "0000000100"), ("2011_09_26_drive_0000_sync", "0000000070"))
LICENSE = """The example frames are KITTI raw data (2011_09_26, drives 0001 and the second drive of that day, left
colour camera image_02), by Andreas Geiger, Philip Lenz, Christoph Stiller and Raquel Urtasun, Karlsruhe
Institute of Technology and Toyota Technological Institute at Chicago: https://www.cvlibs.net/datasets/kitti/
Licence: Creative Commons Attribution-NonCommercial-ShareAlike 3.0 (CC BY-NC-SA 3.0),
https://creativecommons.org/licenses/by-nc-sa/3.0/
"""


def failures(run: Path, out: Path) -> None:
    """The TP/FN/FP picture of the model on the full-mask real frames (JPEG, half resolution)."""
    import cv2

    from evaluate import THRESHOLD
    from freespace.evaluation.metrics import confusion_counts
    from freespace.evaluation.real_frames import available
    from freespace.evaluation.viz import caption, grid, overlay_errors
    from freespace.inference.predictor import Predictor
    from freespace.io.codecs import read_image

    frames = [f for f in available() if f.kind == "mask"]
    images = [read_image(f.image) for f in frames]
    probs = Predictor(checkpoint=run / "checkpoints" / "best.ckpt").predict(images)
    tiles = []
    for f, im, p in zip(frames, images, probs):
        pred = p >= THRESHOLD
        m = confusion_counts(pred, f.road).metrics()
        tiles.append([caption(overlay_errors(im, pred, f.road), f"KITTI 2015 {f.name}: F {100 * m['f_score']:.1f}, "
                                                                 f"recall {100 * m['recall']:.1f}")])
    picture = grid(tiles, width=900)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(picture, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
    out.write_bytes(data.tobytes())


def _inputs(run: Path, raw: Path) -> dict[str, Path]:
    """Every file the model folder is made from, checked before anything is written: the run's best checkpoint,
    ``real.json`` and ``metrics.json``, and the example frames under ``raw`` (by their names in ``examples/``)."""
    needed = {"checkpoint": run / "checkpoints" / "best.ckpt", "real.json": run / "real.json",
              "metrics.json": run / "metrics.json"}
    drives = {p.name: p for p in raw.rglob("*_drive_*_sync") if p.is_dir()} if raw.is_dir() else {}
    examples = {f"{drive[:-5]}_{frame}.png": drives.get(drive, raw / drive) / "image_02" / "data" / f"{frame}.png"
                for drive, frame in EXAMPLES}
    missing = [f"{what} {path}" for what, path in {**needed, **examples}.items() if not path.is_file()]
    if missing:
        raise SystemExit(f"publish.py: error: {missing[0]} not found"
                         f"{f' (and {len(missing) - 1} more)' if len(missing) > 1 else ''}"
                         f"; nothing written (give the run folder and the KITTI raw root with drives "
                         f"{', '.join(d for d, _ in EXAMPLES)})")
    return examples


def publish(run: Path, name: str, raw: Path, fp16: bool = False) -> Path:
    """Make ``models/NAME/`` (model.onnx, examples/, failures.jpg) in a staging folder beside it, moved into place
    once complete: a failure leaves no model folder (no model without its examples and pictures)."""
    import tempfile

    folder = ROOT / "models" / name
    if folder.exists():
        raise SystemExit(f"publish.py: error: {folder} exists; remove it first")
    examples = _inputs(run, raw)
    stage = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=folder.parent))
    try:
        (stage / "examples").mkdir()
        subprocess.run([sys.executable, "-m", "freespace.cli", "export", "--checkpoint",
                        str(run / "checkpoints" / "best.ckpt"), "--format", "onnx", "--out", str(stage / "model.onnx"),
                        *(["--fp16"] if fp16 else [])], check=True)
        for target, source in examples.items():
            shutil.copyfile(source, stage / "examples" / target)
        (stage / "examples" / "LICENSE").write_text(LICENSE)
        failures(run, stage / "failures.jpg")
        stage.chmod(0o755)
        stage.rename(folder)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return folder


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("name")
    ap.add_argument("--raw", type=Path, required=True, help="the KITTI raw root the examples come from")
    ap.add_argument("--fp16", action="store_true")
    a = ap.parse_args()
    folder = publish(a.run, a.name, a.raw, a.fp16)
    real = json.loads((a.run / "real.json").read_text())
    metrics = json.loads((a.run / "metrics.json").read_text())
    print(json.dumps({"real": real, "test_on_autolabels": {k: metrics.get(k) for k in
                      ("f_score", "precision", "recall", "iou", "best_epoch", "epochs_run")},
                      "onnx_bytes": (folder / "model.onnx").stat().st_size,
                      "examples_bytes": sum(p.stat().st_size for p in (folder / "examples").glob("*.png"))}, indent=1))
    print("mean F (masks)", np.mean([v["f_score"] for v in real["frames"].values() if v["kind"] == "mask"]))


if __name__ == "__main__":
    main()
