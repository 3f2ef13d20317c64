"""Inference for deployment: `predict`, `export`, `kitti-submit` (the predictor itself: :mod:`freespace.predictor`)."""

from __future__ import annotations

import io as _io
import json
import logging
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import InputFileError, InvalidOptionError
from freespace.io import (
    IMAGE_SUFFIXES,
    PathLike,
    atomic_write_bytes,
    check_outputs,
    read_image,
    read_kitti_calib,
    staged_folder,
    write_image,
    write_json,
)
from freespace.metrics import to_confidence
from freespace.predictor import Predictor, load_checkpoint

log = logging.getLogger(__name__)

__all__ = ["predict_folder", "export_model", "kitti_submit"]


def _inputs(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise InputFileError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {path}")
        return files
    raise InputFileError(f"input not found: {path}")


def predict_folder(predictor: Predictor, inputs: PathLike, out: PathLike, batch_size: int = 4,
                   progress: bool = True) -> dict[str, Any]:
    """Write ``OUT/<name>.png`` (8-bit road confidence, the input's size), ``OUT/overlays/<name>.png`` and
    ``OUT/summary.json`` (frames, seconds per frame) for every image of ``inputs`` (a file or a folder).

    The folder is written all or nothing and replaces an earlier ``predict`` output there whole."""
    if batch_size < 1:
        raise InvalidOptionError("--batch-size must be ≥ 1")
    check_outputs({"--out": out}, {"--input": inputs})
    files = _inputs(Path(inputs))
    with staged_folder(out, "summary.json", "predict") as staging:
        return _predict_into(predictor, files, staging, batch_size, progress)


def _predict_into(predictor: Predictor, files: list[Path], out: Path, batch_size: int,
                  progress: bool) -> dict[str, Any]:
    from freespace.log import progress_bar

    from freespace.viz import overlay_road

    seconds = 0.0
    bar = progress_bar(None, total=len(files), desc="predict", unit="image", enabled=progress)
    for start in range(0, len(files), batch_size):
        chunk = files[start:start + batch_size]
        images = [read_image(p, what="input image") for p in chunk]
        images = [np.repeat(im[..., None], 3, 2) if im.ndim == 2 else im for im in images]
        t0 = time.perf_counter()
        probs = predictor.predict(images)
        seconds += time.perf_counter() - t0
        for path, image, prob in zip(chunk, images, probs):
            conf = to_confidence(prob)
            write_image(out / f"{path.stem}.png", conf)
            write_image(out / "overlays" / f"{path.stem}.png", overlay_road(image, conf >= 128))
        bar.update(len(chunk))
    bar.close()
    summary = {"frames": len(files), "seconds_per_frame": seconds / len(files), "model": predictor.name,
               "image_size": list(predictor.image_size) if predictor.image_size else None}
    write_json(out / "summary.json", summary)
    return summary


def export_model(checkpoint: PathLike, fmt: str, out: PathLike) -> dict[str, Any]:
    """Export a checkpoint to ONNX (dynamic N, H, W; opset 17) or TorchScript (traced; dynamic H, W),
    validated against PyTorch at the training size and at an odd size. Returns the max abs differences."""
    import torch

    if fmt not in ("onnx", "torchscript"):
        raise InvalidOptionError(f"--format must be onnx or torchscript, got {fmt!r}")
    check_outputs({"--out": out}, {"--checkpoint": checkpoint})
    model, hp = load_checkpoint(checkpoint)
    size = tuple(hp.get("image_size") or (384, 1248))
    example = torch.rand(1, 3, *size)
    checks = [torch.rand(1, 3, *size), torch.rand(2, 3, size[0] - 7, size[1] - 13)]
    out = Path(out)
    meta = {"model": hp["model"], "image_size": json.dumps(list(size)), "producer": "freespace"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp) / "model"
        if fmt == "onnx":
            import warnings

            import onnx
            import onnxruntime as ort

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                torch.onnx.export(model, (example,), str(tmp_path), dynamo=False, opset_version=17,
                                  input_names=["image"], output_names=["logits"],
                                  dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}, "logits": {0: "n", 2: "h", 3: "w"}})
            proto = onnx.load(str(tmp_path))
            for k, v in meta.items():
                proto.metadata_props.add(key=k, value=v)
            data = proto.SerializeToString()
            session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])

            def run(x: torch.Tensor) -> np.ndarray:
                return session.run(None, {"image": x.numpy()})[0]
        else:
            with torch.no_grad():
                traced = torch.jit.trace(model, example, check_trace=False)
            buf = _io.BytesIO()
            torch.jit.save(traced, buf, _extra_files={"freespace.json": json.dumps(meta)})
            data = buf.getvalue()
            loaded = torch.jit.load(_io.BytesIO(data))

            def run(x: torch.Tensor) -> np.ndarray:
                with torch.no_grad():
                    return loaded(x).numpy()
        diffs = []
        with torch.no_grad():
            for x in checks:
                diffs.append(float(np.abs(run(x) - model(x).numpy()).max()))
    atomic_write_bytes(out, data)
    return {"format": fmt, "path": str(out), "max_abs_diff": max(diffs), "checked_sizes": [list(x.shape) for x in checks]}


def kitti_submit(checkpoint: PathLike, root: PathLike, out: PathLike, progress: bool = True) -> dict[str, Any]:
    """Predict the KITTI road testing split and write the benchmark's bird's-eye-view confidence maps
    (``OUT/<cat>_road_<id>.png``, 800×400) and ``OUT/submission.zip`` holding them.

    Every calibration file is read before any prediction; the folder is written all or nothing and
    replaces an earlier submission there whole."""
    from freespace.data.kitti_road import KittiRoad

    check_outputs({"--out": out}, {"--checkpoint": checkpoint, "--root": root})
    ds = KittiRoad(root, "testing", disparity_mode="none")
    missing = [f.name for f in ds.frames if f.calib is None]
    if missing:
        raise InputFileError(f"{len(missing)} testing frames have no calibration (first: {missing[0]}); the BEV "
                             f"transform needs data_road/testing/calib/<frame>.txt")
    calibs = [read_kitti_calib(f.calib) for f in ds.frames]  # type: ignore[arg-type]  # every file checked first
    predictor = Predictor(checkpoint=checkpoint)
    with staged_folder(out, "submission.zip", "kitti-submit") as staging:
        names = _submit_into(predictor, ds, calibs, staging, progress)
    return {"frames": len(names), "zip": str(Path(out) / "submission.zip")}


def _submit_into(predictor: Predictor, ds: Any, calibs: list[dict[str, np.ndarray]], out: Path,
                 progress: bool) -> list[str]:
    from freespace.log import progress_bar

    from freespace.bev import to_bev

    names = []
    for i, frame in enumerate(progress_bar(ds.frames, desc="kitti-submit", unit="frame", enabled=progress)):
        image = ds.load(i, right=False, label=False, disparity=False).left
        conf = to_confidence(predictor.predict([image])[0])
        bev = to_bev(conf, calibs[i])
        name = f"{frame.category}_road_{frame.name.split('_')[1]}.png"
        write_image(out / name, bev)
        names.append(name)
    buf = _io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in names:
            zf.write(out / name, arcname=name)
    atomic_write_bytes(out / "submission.zip", buf.getvalue())
    return names
