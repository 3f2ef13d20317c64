"""Inference for deployment: `predict` (images, folders, globs, videos; sharded), `export`, `kitti-submit`
(the predictor itself: :mod:`freespace.inference.predictor`)."""

from __future__ import annotations

import dataclasses
import hashlib
import io as _io
import itertools
import json
import logging
import os
import queue
import tempfile
import threading
import time
import warnings
import zipfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, param
from freespace.evaluation.metrics import to_confidence
from freespace.inference.predictor import Predictor, load_checkpoint
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, atomic_write_bytes, check_outputs, check_suffix, check_writable, write_json
from freespace.io.kitti import read_kitti_calib
from freespace.io.outdir import OwnedFolder, claim_folder
from freespace.io.video import FrameSource, VideoFrame, VideoWriter, open_frames
from freespace.runtime.shard import select_shard

log = logging.getLogger(__name__)

__all__ = ["predict_folder", "predict_video", "export_model", "to_float16", "kitti_submit"]

#: the size (H, W) of the example input an export is traced and checked with when the checkpoint states no
#: training size: KITTI road's
EXPORT_EXAMPLE_SIZE = (384, 1248)
#: the suffixes an export's file may end in, by format
EXPORT_SUFFIXES = {"onnx": (".onnx",), "torchscript": (".pt", ".pth")}


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


def _shard_source(source: FrameSource, shard: tuple[int, int]) -> FrameSource:
    """The images of shard ``K/N`` of an image source, by file stem (:func:`freespace.runtime.shard.select_shard`)."""
    if source.kind == "video":
        raise InvalidOptionError(f"{param('shard')} splits folders and globs of images by file name; a video is one "
                                 f"output: predict it without {param('shard')} (or split it into frames first)")
    keep = set(select_shard((p.stem for p in source.paths), *shard))
    paths = tuple(p for p in source.paths if p.stem in keep)
    return dataclasses.replace(source, paths=paths, count=len(paths))


def _shard_marker(shard: tuple[int, int]) -> str:
    return f"summary.shard-{shard[0]}-of-{shard[1]}.json"


#: what made a ``predict`` output folder (:func:`_run_record`): the shards of one run share it, others are refused
RUN_RECORD = "predict.json"


#: predictions a pipeline holds waiting to be written (its writer always has the next one at hand); decoded
#: frames waiting for the network are one batch. So memory stays flat however long the input.
WRITE_QUEUE = 2

_END = object()


class _Stop(Exception):
    """Raised inside a pipeline thread when another thread failed: it stops quietly."""


def _put(q: queue.Queue, item: Any, stop: threading.Event) -> None:
    """``q.put(item)``, giving up (:class:`_Stop`) once ``stop`` is set, so that no thread blocks for ever on a
    full queue whose consumer has died."""
    while not stop.is_set():
        try:
            q.put(item, timeout=0.05)
            return
        except queue.Full:
            continue
    raise _Stop


def _get(q: queue.Queue, stop: threading.Event) -> Any:
    """``q.get()``, giving up (:class:`_Stop`) once ``stop`` is set."""
    while not stop.is_set():
        try:
            return q.get(timeout=0.05)
        except queue.Empty:
            continue
    raise _Stop


def _stages(predictor: Any) -> tuple[Callable[[np.ndarray], Any], Callable[[list[Any]], list[np.ndarray]],
                                     Callable[[np.ndarray, tuple[int, int]], np.ndarray]]:
    """``(prepare, infer, restore)`` of a predictor (:class:`Predictor`'s own three steps; a stand-in with only
    ``predict(images)`` runs whole in the network's place)."""
    if all(hasattr(predictor, a) for a in ("prepare", "infer", "restore")):
        return predictor.prepare, predictor.infer, predictor.restore
    return (lambda image: image), predictor.predict, (lambda prob, size: prob)


@dataclasses.dataclass
class RunStats:
    """What a prediction run measured: ``frames`` written, ``network_seconds`` (wall time inside the
    network's calls) and ``wall_seconds`` (first frame read → last output written)."""

    frames: int = 0
    network_seconds: float = 0.0
    wall_seconds: float = 0.0


def run_frames(predictor: Any, frames: Iterable[VideoFrame], batch_size: int,
               write: Callable[[VideoFrame, np.ndarray], None], *, pipeline: bool = True,
               on_batch: Callable[[int], None] | None = None) -> RunStats:
    """Predict every frame and hand ``write(frame, probability at the frame's size)`` each one, in order.

    With ``pipeline`` three threads overlap: a reader decodes frames and prepares the network's input
    (:meth:`Predictor.prepare`: resize, scale), the calling thread runs the network on batches of
    ``batch_size`` (:meth:`Predictor.infer`), and a writer upsamples the probabilities
    (:meth:`Predictor.restore`) and calls ``write``. OpenCV's decoders and encoders and ONNX Runtime (or
    PyTorch) release the GIL, so on two cores decoding and writing run beside the network. The queues
    between them hold at most one batch of decoded frames and :data:`WRITE_QUEUE` predictions: memory does
    not grow with the input's length. Without ``pipeline`` the same steps run one after another in the calling
    thread (same batches, same outputs). An error in any thread stops the others and is raised here.

    Args:
        frames: decoded lazily (e.g. a :class:`~freespace.io.video.FrameSource`). batch_size: ≥ 1.
        on_batch: called with the number of frames of each batch after the network (a progress bar).

    Returns:
        :class:`RunStats`.
    """
    prepare, infer, restore = _stages(predictor)
    stats = RunStats()
    t_start = time.perf_counter()

    def network(batch: list[tuple[VideoFrame, Any]]) -> list[np.ndarray]:
        t0 = time.perf_counter()
        probs = infer([x for _, x in batch])
        stats.network_seconds += time.perf_counter() - t0
        if on_batch is not None:
            on_batch(len(batch))
        return probs

    def finish(frame: VideoFrame, prob: np.ndarray) -> None:
        write(frame, restore(prob, frame.image.shape[:2]))
        stats.frames += 1

    if not pipeline:
        it = iter(frames)
        while batch := [(f, prepare(f.image)) for f in itertools.islice(it, batch_size)]:
            for (frame, _), prob in zip(batch, network(batch)):
                finish(frame, prob)
        stats.wall_seconds = time.perf_counter() - t_start
        return stats

    stop = threading.Event()
    inbox: queue.Queue = queue.Queue(maxsize=batch_size)
    outbox: queue.Queue = queue.Queue(maxsize=WRITE_QUEUE)
    errors: list[BaseException] = []

    def guard(fn: Callable[[], None]) -> Callable[[], None]:
        def run() -> None:
            try:
                fn()
            except _Stop:
                pass
            except BaseException as exc:  # handed to the calling thread, which raises it
                errors.append(exc)
                stop.set()
        return run

    def reader() -> None:
        for frame in frames:
            _put(inbox, (frame, prepare(frame.image)), stop)
        _put(inbox, _END, stop)

    def writer() -> None:
        while (item := _get(outbox, stop)) is not _END:
            finish(*item)

    threads = [threading.Thread(target=guard(reader), name="freespace-read", daemon=True),
               threading.Thread(target=guard(writer), name="freespace-write", daemon=True)]
    for t in threads:
        t.start()
    try:
        done = False
        while not done:
            batch = []
            while len(batch) < batch_size:
                item = _get(inbox, stop)
                if item is _END:
                    done = True
                    break
                batch.append(item)
            if batch:
                for (frame, _), prob in zip(batch, network(batch)):
                    _put(outbox, (frame, prob), stop)
        _put(outbox, _END, stop)
        threads[1].join()
    except _Stop:
        pass
    finally:  # after the end, or on an error anywhere (Ctrl-C included): the threads stop, then it is raised
        stop.set()
        for t in threads:
            t.join()
    if errors:
        raise errors[0]
    stats.wall_seconds = time.perf_counter() - t_start
    return stats


def fast_overlay(image: np.ndarray, road: np.ndarray) -> np.ndarray:
    """The same pixels as :func:`freespace.evaluation.viz.overlay_road` (magenta, α = 0.45) for an ``H×W×3
    uint8`` image and a ``bool H×W`` road mask, from a 256-entry table per channel instead of float
    arithmetic on the road's pixels (measured: 9 against 25 CPU ms on a 1242×375 frame)."""
    out = image.copy()
    np.copyto(out, cv2.LUT(image, _OVERLAY_LUT), where=road[:, :, None])
    return out


def _overlay_lut() -> np.ndarray:
    values = np.arange(256, dtype=np.float32)[:, None]
    tint = np.array((255, 0, 255), np.float32)
    return (values * (1 - 0.45) + tint * 0.45).astype(np.uint8).reshape(256, 1, 3)


_OVERLAY_LUT = _overlay_lut()


def predict_folder(predictor: Predictor, inputs: PathLike, out: PathLike, batch_size: int = 4,
                   progress: bool = True, shard: tuple[int, int] | None = None, overlays: bool = True,
                   pipeline: bool = True) -> dict[str, Any]:
    """Write ``OUT/<name>.png`` (8-bit road confidence, the input's size), ``OUT/overlays/<name>.png``,
    ``OUT/summary.json`` and ``OUT/predict.json`` (:data:`RUN_RECORD`: what made it) for every frame of ``inputs``.

    Args:
        inputs: an image, a folder of images, a glob of images or a video (frames named
            ``<video stem>_<index>``; :func:`freespace.io.video.open_frames`), decoded one batch at a time.
        out: the output folder (:mod:`freespace.io.outdir`), written all or nothing: it replaces the files of
            an earlier ``predict`` output there. With ``shard`` only that shard's frames are written, beside
            the other shards' in the same folder, and its summary is ``summary.shard-K-of-N.json``; the first
            shard writes ``predict.json``, a shard made otherwise (another model, input, N or overlays) is
            refused, and the shard that completes the N writes ``summary.json`` (all frames).
        batch_size: frames per network call (≥ 1). shard: ``(K, N)``, 1-based (:mod:`freespace.runtime.shard`);
            images only.
        overlays: also write ``overlays/`` (an RGB PNG per frame: its encoding costs about three times the
            mask's; leave them out for real time).
        pipeline: decode, predict and write in three overlapped threads (:func:`run_frames`); the outputs
            are the same either way.

    Returns:
        The summary: ``frames``, ``seconds_per_frame`` (the network), ``frames_per_second`` (end to end:
        first frame read to last file written), ``network_share`` (the network's part of that time),
        ``model``, ``image_size``, ``shard``.
    """
    if batch_size < 1:
        raise InvalidOptionError(f"{param('batch_size')} must be ≥ 1")
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"input": inputs})
    source = open_frames(inputs)
    check_outputs({"out": out}, _input_paths(source))
    frames = _shard_source(source, shard) if shard is not None else source
    record = _run_record(predictor, source, shard, overlays)
    with claim_folder(out, "predict", shared=shard is not None) as folder:
        if shard is not None:
            _join_run(folder, record)
        with folder.staged(replace=shard is None) as staging:
            if shard is None:
                write_json(staging / RUN_RECORD, record)
            summary = _predict_into(predictor, frames, staging, batch_size, progress, shard, overlays, pipeline)
        if shard is not None:
            _join_summaries(folder, shard[1])
    return summary


def _run_record(predictor: Predictor, source: FrameSource, shard: tuple[int, int] | None,
                overlays: bool) -> dict[str, Any]:
    """What makes a ``predict`` output folder (:data:`RUN_RECORD`): the model (its name, size and the SHA-256
    of its file), the input (its path, absolute, links resolved; a glob as written, absolute) and its frame
    names (count and SHA-256, before sharding), the number of shards (None: one whole run) and overlays."""
    from freespace.data.label_tree import file_sha256

    path = getattr(predictor, "path", None)
    spec = os.path.abspath(source.spec) if source.kind == "glob" else os.path.realpath(source.spec)
    names = "\n".join(sorted(p.stem for p in source.paths)).encode("utf-8")
    size = getattr(predictor, "resize_to", None)
    return {"model": getattr(predictor, "name", None), "model_sha256": file_sha256(path) if path else None,
            "image_size": list(size) if size is not None else None, "input": spec, "frames": len(source.paths),
            "frames_sha256": hashlib.sha256(names).hexdigest(), "shards": shard[1] if shard else None,
            "overlays": overlays}


def _join_run(folder: OwnedFolder, record: dict[str, Any]) -> None:
    """Let a shard into ``folder``: write ``record`` (:func:`_run_record`) there when it holds nothing yet,
    else refuse when its record differs (another model, input, number of shards, overlays; a whole run) or it
    has none; one shard at a time (:meth:`OwnedFolder.alone`).

    Raises:
        InvalidOptionError: naming the settings that differ.
    """
    path = folder.path / RUN_RECORD
    with folder.alone():
        try:
            old = json.loads(path.read_text())
        except FileNotFoundError:
            old = {} if folder.entries() else None
        except (OSError, ValueError):
            old = {}
        if old is None:
            folder.record([RUN_RECORD])
            write_json(path, record)
            return
        differ = [k for k in record if not isinstance(old, dict) or old.get(k) != record[k]]
        if differ:
            made = ("; ".join(f"{k} {_short(old.get(k))} → {_short(record[k])}" for k in differ)
                    if isinstance(old, dict) and old else f"no readable {RUN_RECORD} says how")
            raise InvalidOptionError(f"{param('out')} {folder.path} holds predictions made otherwise ({made}); give "
                                     f"every shard the same model, input, {param('shard')} count and overlays, or "
                                     f"choose another {param('out')} (a run without {param('shard')} replaces them)")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "…"


def _join_summaries(folder: OwnedFolder, n: int) -> None:
    """Write ``summary.json`` of a sharded run once every one of its ``n`` shard summaries is in ``folder``:
    ``frames`` (all shards), ``seconds_per_frame`` (the network, over all frames), ``model``, ``image_size``,
    ``shards``."""
    with folder.alone():
        try:
            parts = [json.loads((folder.path / _shard_marker((k, n))).read_text()) for k in range(1, n + 1)]
            frames = sum(p["frames"] for p in parts)
            network = sum((p["seconds_per_frame"] or 0.0) * p["frames"] for p in parts)
            summary = {"frames": frames, "seconds_per_frame": network / frames if frames else None,
                       "model": parts[0]["model"], "image_size": parts[0]["image_size"], "shards": n}
        except (OSError, ValueError, KeyError, TypeError):
            return  # a shard still to run (or a summary that is not one)
        folder.record(["summary.json"])
        write_json(folder.path / "summary.json", summary)


def _summary(predictor: Predictor, stats: RunStats, **extra: Any) -> dict[str, Any]:
    n, wall = stats.frames, stats.wall_seconds
    return {"frames": n, "seconds_per_frame": stats.network_seconds / n if n else None,
            "frames_per_second": n / wall if n and wall > 0 else None, "seconds": wall,
            "network_share": stats.network_seconds / wall if n and wall > 0 else None, "model": predictor.name,
            "image_size": list(predictor.resize_to) if predictor.resize_to is not None else None, **extra}


def _predict_into(predictor: Predictor, source: FrameSource, out: Path, batch_size: int, progress: bool,
                  shard: tuple[int, int] | None, overlays: bool = True, pipeline: bool = True) -> dict[str, Any]:
    from freespace.runtime.log import progress_bar

    bar = progress_bar(None, total=len(source), desc="predict", unit="frame", enabled=progress)

    def write(frame: VideoFrame, prob: np.ndarray) -> None:
        conf = to_confidence(prob)
        write_image(out / f"{frame.name}.png", conf)
        if overlays:
            write_image(out / "overlays" / f"{frame.name}.png", fast_overlay(frame.image, conf >= 128))

    stats = run_frames(predictor, source, batch_size, write, pipeline=pipeline, on_batch=bar.update)
    bar.close()
    extra = {"shard": f"{shard[0]}/{shard[1]}"} if shard else {}
    summary = _summary(predictor, stats, **extra)
    write_json(out / (_shard_marker(shard) if shard else "summary.json"), summary)
    return summary


def predict_video(predictor: Predictor, inputs: PathLike, out: PathLike, batch_size: int = 4,
                  progress: bool = True, pipeline: bool = True) -> dict[str, Any]:
    """Write the road overlay (predicted road tinted magenta, as ``predict``'s ``overlays/``) of every frame
    of ``inputs`` as one MP4 video ``out``.

    Args:
        inputs: a video, a folder or a glob of images (one size; :func:`freespace.io.video.open_frames`),
            decoded lazily, through bounded queues: memory does not grow with the length.
        out: the ``.mp4`` file, written atomically (:class:`freespace.io.video.VideoWriter`), at the input's
            frame rate (10 frames per second for images); never one of the inputs.
        pipeline: decode, predict and encode in three overlapped threads (:func:`run_frames`).

    Returns:
        ``frames``, ``seconds_per_frame`` (the network), ``frames_per_second`` (end to end: decoding,
        network, encoding), ``network_share``, ``fps`` (the video's frame rate), ``model``, ``image_size``.
    """
    from freespace.runtime.log import progress_bar

    if batch_size < 1:
        raise InvalidOptionError(f"{param('batch_size')} must be ≥ 1")
    out = check_writable(out)
    check_outputs({"out": out}, {"input": inputs})
    check_suffix(out, (".mp4",))
    source = open_frames(inputs)
    check_outputs({"out": out}, _input_paths(source))
    bar = progress_bar(None, total=len(source), desc="predict", unit="frame", enabled=progress)
    t_start = time.perf_counter()
    with VideoWriter(out, fps=source.fps) as writer:
        stats = run_frames(predictor, source, batch_size,
                           lambda frame, prob: writer.write(fast_overlay(frame.image, to_confidence(prob) >= 128)),
                           pipeline=pipeline, on_batch=bar.update)
    stats.wall_seconds = time.perf_counter() - t_start  # the video's file finished and in place
    bar.close()
    return _summary(predictor, stats, fps=source.fps, path=str(out))


def export_model(checkpoint: PathLike, fmt: str, out: PathLike, calibration: PathLike | None = None,
                 fp16: bool = False) -> dict[str, Any]:
    """Export a checkpoint to ONNX (dynamic N, H, W; opset 17) or TorchScript (traced; dynamic H, W),
    validated against PyTorch at the training size and at an odd size. Returns the max abs differences.

    With ``fp16`` (ONNX only) the file written is the float16 model (:func:`to_float16`: weights and
    computation in float16, the ``image`` input and ``logits`` output kept float32, so that
    :class:`Predictor` and ``freespace predict --onnx`` take it as any export; the metadata kept), about
    half the size. Its road probabilities are compared with the checkpoint's (PyTorch, float32) on the
    check inputs: the result's ``fp16`` entry gives the largest difference and the share of pixels whose
    road/non-road decision (p ≥ 0.5) is the same; a difference above :data:`FP16_MAX_PROB_DIFF` (or not
    finite: a float16 overflow) refuses the export and writes nothing.

    With ``calibration`` (ONNX only: a folder, glob or video of real frames) the file written is the int8
    model (:func:`freespace.inference.quantize.quantize_int8`, calibrated on up to
    :data:`~freespace.inference.quantize.CALIBRATION_FRAMES` of them at the training size), and the result's
    ``int8`` entry says how its masks agree with the float32 model's on those frames
    (:func:`~freespace.inference.quantize.compare_models`).
    """
    if fmt not in ("onnx", "torchscript"):
        raise InvalidOptionError(f"{param('fmt')} must be onnx or torchscript, got {fmt!r}")
    if calibration is not None and fmt != "onnx":
        raise InvalidOptionError(f"int8 quantisation ({param('calibration')}) is for {param('fmt')} onnx")
    if fp16 and fmt != "onnx":
        raise InvalidOptionError(f"{param('fp16')} is for {param('fmt')} onnx (a float16 ONNX model); leave it out "
                                 f"for {fmt}")
    if fp16 and calibration is not None:
        raise InvalidOptionError(f"{param('fp16')} and int8 quantisation ({param('calibration')}) exclude each other: "
                                 f"a model is exported in float16 or in int8; leave out one of them")
    check_writable(out)
    check_outputs({"out": out}, {"checkpoint": checkpoint, **({"calibration": calibration} if calibration else {})})
    check_suffix(out, EXPORT_SUFFIXES[fmt])
    import torch

    model, hp = load_checkpoint(checkpoint)
    size = tuple(hp.get("image_size") or EXPORT_EXAMPLE_SIZE)
    calib_inputs = None
    if calibration is not None:  # read before the export: a bad folder fails fast
        from freespace.inference.quantize import calibration_inputs

        calib_inputs = calibration_inputs(calibration, size)
    gen = torch.Generator().manual_seed(0)  # the same check inputs every time: a refusal is repeatable
    example = torch.rand(1, 3, *size, generator=gen)
    checks = [torch.rand(1, 3, *size, generator=gen), torch.rand(2, 3, size[0] - 7, size[1] - 13, generator=gen)]
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
            references = [model(x).numpy() for x in checks]
        for x, ref in zip(checks, references):
            diffs.append(float(np.abs(run(x) - ref).max()))
    if not np.isfinite(diffs).all():  # NaN or infinite class scores: of the checkpoint or of the export
        raise CorruptFileError(f"the model {checkpoint} gives NaN or infinite class scores on the check inputs, so it "
                               f"predicts no road probability; it is broken (e.g. an overflow): train it anew")
    result = {"format": fmt, "path": str(out), "max_abs_diff": max(diffs),
              "checked_sizes": [list(x.shape) for x in checks]}
    if fp16:
        half = to_float16(data, {**meta, "precision": "float16 (weights and computation; image and logits float32)"})
        result["fp16"] = _check_float16(half, [x.numpy() for x in checks], references, checkpoint)
        data = half
    if calib_inputs is not None:
        from freespace.inference.quantize import compare_models, quantize_int8

        quantized = quantize_int8(data, calib_inputs, {**meta, "quantization": "int8 static, QDQ, per-channel weights, "
                                                                             f"{len(calib_inputs)} calibration frames"})
        result["int8"] = compare_models(data, quantized, calib_inputs)
        data = quantized
    atomic_write_bytes(out, data)
    return result


#: the largest road probability difference a float16 export may have from its checkpoint on the check inputs
FP16_MAX_PROB_DIFF = 0.05


def to_float16(model: bytes, metadata: dict[str, str]) -> bytes:
    """The float16 version of the float32 ONNX ``model`` (onnxruntime's ``convert_float_to_float16``): weights
    and computation in float16, the graph's input and output kept float32 (``keep_io_types``: a cast after
    the input and before the output), so that it is called as the float32 model is; ``metadata`` is set on
    it (replacing what it had)."""
    import onnx
    from onnxruntime.transformers.float16 import convert_float_to_float16

    proto = convert_float_to_float16(onnx.load_from_string(model), keep_io_types=True)
    del proto.metadata_props[:]
    for k, v in metadata.items():
        proto.metadata_props.add(key=k, value=v)
    return proto.SerializeToString()


def _road_probability(logits: np.ndarray) -> np.ndarray:
    """Softmax road probability (``N×H×W``, float64) of ``N×C×H×W`` class scores."""
    logits = logits.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # infinite logits (a float16 overflow) give NaN: refused
        e = np.exp(logits - logits.max(1, keepdims=True))
        return e[:, 1] / e.sum(1)


def _check_float16(model: bytes, inputs: list[np.ndarray], references: list[np.ndarray],
                   checkpoint: PathLike) -> dict[str, Any]:
    """Run the float16 ONNX ``model`` on ``inputs`` (``float32 N×3×H×W``) and compare its road probabilities
    with the checkpoint's logits ``references``: ``max_prob_diff`` and ``mask_agreement`` (p ≥ 0.5).

    Raises:
        InvalidOptionError: the difference exceeds :data:`FP16_MAX_PROB_DIFF` or is not finite.
    """
    import onnxruntime as ort

    session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
    diff, same, total = 0.0, 0, 0
    for x, ref in zip(inputs, references):
        a, b = _road_probability(ref), _road_probability(session.run(None, {"image": x})[0])
        d = float(np.abs(a - b).max())
        diff = d if not np.isfinite(d) else max(diff, d)
        same, total = same + int(((a >= 0.5) == (b >= 0.5)).sum()), total + a.size
    if not diff <= FP16_MAX_PROB_DIFF:  # NaN too: a float16 overflow
        raise InvalidOptionError(f"{checkpoint}: in float16 the road probabilities differ from the checkpoint's by up "
                                 f"to {diff:.3g} (allowed {FP16_MAX_PROB_DIFF}); export it without {param('fp16')}")
    return {"max_prob_diff": diff, "mask_agreement": same / total, "tolerance": FP16_MAX_PROB_DIFF}


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
    from freespace.evaluation.bev import to_bev
    from freespace.runtime.log import progress_bar

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
