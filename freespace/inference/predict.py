"""Inference for deployment: `predict` (images, folders, globs, videos; sharded), `export`, `kitti-submit`
(the predictor itself: :mod:`freespace.inference.predictor`)."""

from __future__ import annotations

import dataclasses
import io as _io
import itertools
import json
import logging
import tempfile
import time
import warnings
import zipfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import InputFileError, InvalidOptionError, param
from freespace.evaluation.metrics import to_confidence
from freespace.inference.predictor import Predictor, load_checkpoint
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, atomic_write_bytes, check_outputs, check_writable, write_json
from freespace.io.kitti import read_kitti_calib
from freespace.io.outdir import claim_folder
from freespace.io.video import FrameSource, VideoFrame, VideoWriter, open_frames
from freespace.shard import select_shard

log = logging.getLogger(__name__)

__all__ = ["predict_folder", "predict_video", "export_model", "kitti_submit"]

#: the size (H, W) of the example input an export is traced and checked with when the checkpoint states no
#: training size: KITTI road's
EXPORT_EXAMPLE_SIZE = (384, 1248)


def _input_paths(source: FrameSource) -> dict[str, Path]:
    """The input files or folders of ``source`` for :func:`freespace.io.files.check_outputs`: the video, the
    folder, the image, or the folders a glob's images lie in (an output may not lie in any of them)."""
    if source.kind == "folder":
        folders = [Path(source.spec)]
    elif source.kind == "glob":
        folders = sorted({p.parent for p in source.paths})
    else:
        return {"input": source.paths[0]}
    return {"input" if i == 0 else f"input[{i}]": p for i, p in enumerate(folders)}


def _batches(frames: Iterable[VideoFrame], size: int) -> Iterator[list[VideoFrame]]:
    """Consecutive lists of ``size`` frames (the last may be shorter), drawn lazily: only one batch of
    decoded frames is held at a time."""
    it = iter(frames)
    while batch := list(itertools.islice(it, size)):
        yield batch


def _shard_source(source: FrameSource, shard: tuple[int, int]) -> FrameSource:
    """The images of shard ``K/N`` of an image source, by file stem (:func:`freespace.shard.select_shard`)."""
    if source.kind == "video":
        raise InvalidOptionError(f"{param('shard')} splits folders and globs of images by file name; a video is one "
                                 f"output: predict it without {param('shard')} (or split it into frames first)")
    keep = set(select_shard((p.stem for p in source.paths), *shard))
    paths = tuple(p for p in source.paths if p.stem in keep)
    return dataclasses.replace(source, paths=paths, count=len(paths))


def _shard_marker(shard: tuple[int, int]) -> str:
    return f"summary.shard-{shard[0]}-of-{shard[1]}.json"


def predict_folder(predictor: Predictor, inputs: PathLike, out: PathLike, batch_size: int = 4,
                   progress: bool = True, shard: tuple[int, int] | None = None) -> dict[str, Any]:
    """Write ``OUT/<name>.png`` (8-bit road confidence, the input's size), ``OUT/overlays/<name>.png`` and
    ``OUT/summary.json`` for every frame of ``inputs``.

    Args:
        inputs: an image, a folder of images, a glob of images or a video (frames named
            ``<video stem>_<index>``; :func:`freespace.io.video.open_frames`), decoded one batch at a time.
        out: the output folder (:mod:`freespace.io.outdir`), written all or nothing: it replaces the files of
            an earlier ``predict`` output there. With ``shard`` only that shard's frames are written, beside
            the other shards' in the same folder, and its summary is ``summary.shard-K-of-N.json``.
        batch_size: frames per network call (≥ 1). shard: ``(K, N)``, 1-based (:mod:`freespace.shard`);
            images only.

    Returns:
        The summary: ``frames``, ``seconds_per_frame`` (the network), ``frames_per_second`` (end to end:
        decoding, network, writing), ``model``, ``image_size``, ``shard``.
    """
    if batch_size < 1:
        raise InvalidOptionError(f"{param('batch_size')} must be ≥ 1")
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"input": inputs})
    source = open_frames(inputs)
    check_outputs({"out": out}, _input_paths(source))
    if shard is not None:
        source = _shard_source(source, shard)
    with claim_folder(out, "predict", shared=shard is not None) as folder, \
            folder.staged(replace=shard is None) as staging:
        return _predict_into(predictor, source, staging, batch_size, progress, shard)


def _summary(predictor: Predictor, frames: int, seconds: float, wall: float, **extra: Any) -> dict[str, Any]:
    return {"frames": frames, "seconds_per_frame": seconds / frames if frames else None,
            "frames_per_second": frames / wall if frames and wall > 0 else None, "model": predictor.name,
            "image_size": list(predictor.resize_to) if predictor.resize_to is not None else None, **extra}


def _predict_into(predictor: Predictor, source: FrameSource, out: Path, batch_size: int, progress: bool,
                  shard: tuple[int, int] | None) -> dict[str, Any]:
    from freespace.log import progress_bar

    from freespace.evaluation.viz import overlay_road

    seconds, frames, t_start = 0.0, 0, time.perf_counter()
    bar = progress_bar(None, total=len(source), desc="predict", unit="frame", enabled=progress)
    for batch in _batches(source, batch_size):
        t0 = time.perf_counter()
        probs = predictor.predict([f.image for f in batch])
        seconds += time.perf_counter() - t0
        for frame, prob in zip(batch, probs):
            conf = to_confidence(prob)
            write_image(out / f"{frame.name}.png", conf)
            write_image(out / "overlays" / f"{frame.name}.png", overlay_road(frame.image, conf >= 128))
        frames += len(batch)
        bar.update(len(batch))
    bar.close()
    extra = {"shard": f"{shard[0]}/{shard[1]}"} if shard else {}
    summary = _summary(predictor, frames, seconds, time.perf_counter() - t_start, **extra)
    write_json(out / (_shard_marker(shard) if shard else "summary.json"), summary)
    return summary


def predict_video(predictor: Predictor, inputs: PathLike, out: PathLike, batch_size: int = 4,
                  progress: bool = True) -> dict[str, Any]:
    """Write the road overlay (predicted road tinted magenta, as ``predict``'s ``overlays/``) of every frame
    of ``inputs`` as one MP4 video ``out``.

    Args:
        inputs: a video, a folder or a glob of images (one size; :func:`freespace.io.video.open_frames`),
            decoded one batch of ``batch_size`` frames at a time: memory does not grow with the length.
        out: the ``.mp4`` file, written atomically (:class:`freespace.io.video.VideoWriter`), at the input's
            frame rate (10 frames per second for images); never one of the inputs.

    Returns:
        ``frames``, ``seconds_per_frame`` (the network), ``frames_per_second`` (end to end: decoding,
        network, encoding), ``fps`` (the video's frame rate), ``model``, ``image_size``.
    """
    from freespace.log import progress_bar

    from freespace.evaluation.viz import overlay_road

    if batch_size < 1:
        raise InvalidOptionError(f"{param('batch_size')} must be ≥ 1")
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise InvalidOptionError(f"{param('out')} {out}: a video output must end in .mp4 (or give a folder for PNGs)")
    check_writable(out)
    check_outputs({"out": out}, {"input": inputs})
    source = open_frames(inputs)
    check_outputs({"out": out}, _input_paths(source))
    seconds, t_start = 0.0, time.perf_counter()
    bar = progress_bar(None, total=len(source), desc="predict", unit="frame", enabled=progress)
    with VideoWriter(out, fps=source.fps) as writer:
        for batch in _batches(source, batch_size):
            t0 = time.perf_counter()
            probs = predictor.predict([f.image for f in batch])
            seconds += time.perf_counter() - t0
            for frame, prob in zip(batch, probs):
                writer.write(overlay_road(frame.image, to_confidence(prob) >= 128))
            bar.update(len(batch))
    bar.close()
    return _summary(predictor, writer.frames, seconds, time.perf_counter() - t_start, fps=source.fps,
                    path=str(out))


def export_model(checkpoint: PathLike, fmt: str, out: PathLike) -> dict[str, Any]:
    """Export a checkpoint to ONNX (dynamic N, H, W; opset 17) or TorchScript (traced; dynamic H, W),
    validated against PyTorch at the training size and at an odd size. Returns the max abs differences."""
    if fmt not in ("onnx", "torchscript"):
        raise InvalidOptionError(f"{param('fmt')} must be onnx or torchscript, got {fmt!r}")
    check_writable(out)
    check_outputs({"out": out}, {"checkpoint": checkpoint})
    import torch

    model, hp = load_checkpoint(checkpoint)
    size = tuple(hp.get("image_size") or EXPORT_EXAMPLE_SIZE)
    example = torch.rand(1, 3, *size)
    checks = [torch.rand(1, 3, *size), torch.rand(2, 3, size[0] - 7, size[1] - 13)]
    out = Path(out)
    meta = {"model": hp["model"], "image_size": json.dumps(list(size)), "producer": "freespace"}
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        if not log.isEnabledFor(logging.DEBUG):  # torch's deprecations and tracer notes, unless -v
            warnings.simplefilter("ignore")
        tmp_path = Path(tmp) / "model"
        if fmt == "onnx":
            import onnx
            import onnxruntime as ort

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
    replaces the files of an earlier submission there (:mod:`freespace.io.outdir`)."""
    from freespace.data.kitti_road import KittiRoad

    check_writable(out, folder=True)
    check_outputs({"out": out}, {"checkpoint": checkpoint, "root": root})
    ds = KittiRoad(root, "testing", disparity_source="none")
    missing = [f.name for f in ds.frames if f.calib is None]
    if missing:
        raise InputFileError(f"{len(missing)} testing frames have no calibration (first: {missing[0]}); the BEV "
                             f"transform needs data_road/testing/calib/<frame>.txt")
    calibs = [read_kitti_calib(f.calib) for f in ds.frames]  # type: ignore[arg-type]  # every file checked first
    predictor = Predictor(checkpoint=checkpoint)
    with claim_folder(out, "kitti-submit") as folder, folder.staged() as staging:
        names = _submit_into(predictor, ds, calibs, staging, progress)
    return {"frames": len(names), "zip": str(Path(out) / "submission.zip")}


def _submit_into(predictor: Predictor, ds: Any, calibs: list[dict[str, np.ndarray]], out: Path,
                 progress: bool) -> list[str]:
    from freespace.log import progress_bar

    from freespace.evaluation.bev import to_bev

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
