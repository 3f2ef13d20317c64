"""Prediction for deployment: `predict` (images, folders, globs, videos; sharded) through a pipelined runner
(the predictor itself: :mod:`freespace.inference.predictor`; export: :mod:`freespace.inference.export`; the KITTI
submission: :mod:`freespace.inference.submission`)."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import os
import queue
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.errors import InvalidOptionError, param
from freespace.evaluation.metrics import to_confidence
from freespace.inference.predictor import Predictor
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, check_outputs, check_suffix, check_writable, shown_path, write_json
from freespace.io.outdir import OwnedFolder, claim_folder
from freespace.io.video import FrameSource, VideoFrame, VideoWriter, is_video_path, open_frames
from freespace.limits import MAX_BATCH_SIZE, check_threads
from freespace.runtime.shard import parse_shard, select_shard

__all__ = ["predict", "predict_folder", "predict_video", "predict_report", "run_frames", "fast_overlay"]


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


def _check_batch_size(batch_size: int) -> None:
    """Refuse a ``batch_size`` that is no whole number in 1…:data:`~freespace.limits.MAX_BATCH_SIZE` (a batch is
    held in memory whole)."""
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or not 1 <= batch_size <= MAX_BATCH_SIZE:
        raise InvalidOptionError(f"{param('batch_size')} must be an integer in 1…{MAX_BATCH_SIZE}, got {batch_size!r}")


def _shard_marker(shard: tuple[int, int]) -> str:
    return f"summary.shard-{shard[0]}-of-{shard[1]}.json"


#: what made a ``predict`` output folder (:func:`_run_record`): the shards of one run share it, others are refused
RUN_RECORD = "predict.json"
#: the formats of ``overlays/``: lossless PNG, or JPEG for speed
OVERLAY_FORMATS = ("png", "jpg")


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


#: the stages of a prediction run, in order, as its profile names them: reading and decoding a frame, fitting it to
#: the network's input, the network, bringing the probability back to the frame's size, writing the outputs
STAGES = ("decode", "preprocess", "network", "postprocess", "write")


@dataclasses.dataclass
class RunStats:
    """What a prediction run measured: ``frames`` written, ``network_seconds`` (wall time inside the
    network's calls) and ``wall_seconds`` (first frame read → last output written)."""

    frames: int = 0
    network_seconds: float = 0.0
    wall_seconds: float = 0.0
    #: each stage's own wall seconds, summed over the frames (:data:`STAGES`): in a pipeline the stages run in
    #: three threads at once, so their sum exceeds the wall time by what the overlap saved
    stage_seconds: dict[str, float] = dataclasses.field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))

    def profile(self) -> dict[str, float | None]:
        """Milliseconds per frame of each stage (:data:`STAGES`) and of the whole run (``end_to_end``)."""
        n = self.frames
        out: dict[str, float | None] = {k: 1000 * v / n if n else None for k, v in self.stage_seconds.items()}
        out["end_to_end"] = 1000 * self.wall_seconds / n if n else None
        return out


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
    prepare_frame, infer, restore = _stages(predictor)
    stats = RunStats()
    spent = stats.stage_seconds
    t_start = time.perf_counter()

    def decoded() -> Iterator[VideoFrame]:
        it = iter(frames)
        while True:
            t0 = time.perf_counter()
            frame = next(it, None)
            spent["decode"] += time.perf_counter() - t0
            if frame is None:
                return
            yield frame

    def prepare(image: np.ndarray) -> Any:
        t0 = time.perf_counter()
        x = prepare_frame(image)
        spent["preprocess"] += time.perf_counter() - t0
        return x

    def network(batch: list[tuple[VideoFrame, Any]]) -> list[np.ndarray]:
        t0 = time.perf_counter()
        probs = infer([x for _, x in batch])
        stats.network_seconds += time.perf_counter() - t0
        spent["network"] = stats.network_seconds
        if on_batch is not None:
            on_batch(len(batch))
        return probs

    def finish(frame: VideoFrame, prob: np.ndarray) -> None:
        t0 = time.perf_counter()
        full = restore(prob, frame.image.shape[:2])
        t1 = time.perf_counter()
        write(frame, full)
        spent["postprocess"] += t1 - t0
        spent["write"] += time.perf_counter() - t1
        stats.frames += 1

    (_run_pipelined if pipeline else _run_serially)(decoded(), batch_size, prepare, network, finish)
    stats.wall_seconds = time.perf_counter() - t_start
    return stats


#: a batch of ``(frame, prepared network input)`` → the network's probabilities, one per frame
_Network = Callable[[list[tuple[VideoFrame, Any]]], list[np.ndarray]]


def _run_serially(frames: Iterable[VideoFrame], batch_size: int, prepare: Callable[[np.ndarray], Any],
                  network: _Network, finish: Callable[[VideoFrame, np.ndarray], None]) -> None:
    """:func:`run_frames` in the calling thread: ``prepare`` a batch of frames, run ``network`` on it, ``finish``
    each frame with its probability, in order."""
    it = iter(frames)
    while batch := [(f, prepare(f.image)) for f in itertools.islice(it, batch_size)]:
        for (frame, _), prob in zip(batch, network(batch)):
            finish(frame, prob)


def _run_pipelined(frames: Iterable[VideoFrame], batch_size: int, prepare: Callable[[np.ndarray], Any],
                   network: _Network, finish: Callable[[VideoFrame, np.ndarray], None]) -> None:
    """:func:`run_frames` in three threads: a reader (``prepare``), the calling thread (``network`` on batches)
    and a writer (``finish``), joined by bounded queues; an error in any of them stops the others and is
    raised here, after they have stopped."""
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
        for batch in _batches(inbox, batch_size, stop):
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


def _batches(inbox: queue.Queue, batch_size: int, stop: threading.Event) -> Iterator[list[Any]]:
    """The items of ``inbox`` in lists of ``batch_size`` (the last one shorter, none empty) until its end mark."""
    while True:
        batch = []
        while len(batch) < batch_size:
            item = _get(inbox, stop)
            if item is _END:
                if batch:
                    yield batch
                return
            batch.append(item)
        yield batch


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
                   pipeline: bool = True, overlay_format: str = "png") -> dict[str, Any]:
    """Write ``OUT/<name>.png`` (8-bit road confidence, the input's size), ``OUT/overlays/<name>.png`` (or ``.jpg``),
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
        overlay_format: ``png`` (lossless) or ``jpg`` (JPEG at OpenCV's quality 95: about an eighth of a 1080p
            PNG's encoding time), recorded in ``predict.json``.
        pipeline: decode, predict and write in three overlapped threads (:func:`run_frames`); the outputs
            are the same either way.

    Returns:
        The summary: ``frames``, ``seconds_per_frame`` (the network), ``frames_per_second`` (end to end:
        first frame read to last file written), ``network_share`` (the network's part of that time),
        ``model``, ``image_size``, ``shard``.
    """
    _check_batch_size(batch_size)
    if overlay_format not in OVERLAY_FORMATS:
        raise InvalidOptionError(f"{param('overlay_format')} must be one of {', '.join(OVERLAY_FORMATS)}, got "
                                 f"{overlay_format!r}")
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"input": inputs})
    source = open_frames(inputs)
    check_outputs({"out": out}, _input_paths(source))
    frames = _shard_source(source, shard) if shard is not None else source
    record = {**_run_record(predictor, source, shard, overlays), "overlay_format": overlay_format if overlays else None}
    with claim_folder(out, "predict", shared=shard is not None) as folder:
        if shard is not None:
            _join_run(folder, record)
        with folder.staged(replace=shard is None) as staging:
            if shard is None:
                write_json(staging / RUN_RECORD, record)
            summary = _predict_into(predictor, frames, staging, batch_size, progress, shard,
                                    overlay_format if overlays else None, pipeline)
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
    names = b"\n".join(sorted(os.fsencode(p.stem) for p in source.paths))  # any name, as its bytes (and tta)
    size = getattr(predictor, "resize_to", None)
    name = getattr(predictor, "name", None)
    return {"model": shown_path(name) if isinstance(name, str) else name,  # as its JSON file holds them
            "model_sha256": file_sha256(path) if path else None,
            "image_size": list(size) if size is not None else None, "input": shown_path(spec),
            "frames": len(source.paths),
            "frames_sha256": hashlib.sha256(names).hexdigest(), "shards": shard[1] if shard else None,
            "overlays": overlays, "tta": getattr(predictor, "tta", False),
            "crop_top": getattr(predictor, "crop_top", 0.0)}


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
            "image_size": list(predictor.resize_to) if predictor.resize_to is not None else None,
            "tta": getattr(predictor, "tta", False), "crop_top": getattr(predictor, "crop_top", 0.0),
            "profile_ms_per_frame": stats.profile(), **extra}


def _predict_into(predictor: Predictor, source: FrameSource, out: Path, batch_size: int, progress: bool,
                  shard: tuple[int, int] | None, overlays: str | None = "png", pipeline: bool = True) -> dict[str, Any]:
    from freespace.runtime.log import progress_bar

    bar = progress_bar(None, total=len(source), desc="predict", unit="frame", enabled=progress)

    def write(frame: VideoFrame, prob: np.ndarray) -> None:
        conf = to_confidence(prob)
        write_image(out / f"{frame.name}.png", conf)
        if overlays:
            write_image(out / "overlays" / f"{frame.name}.{overlays}", fast_overlay(frame.image, conf >= 128))

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

    _check_batch_size(batch_size)
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


def predict(inputs: PathLike, out: PathLike, *, checkpoint: PathLike | None = None, onnx: PathLike | None = None,
            threads: int | None = None, batch_size: int = 4, shard: str | tuple[int, int] | None = None,
            overlays: bool = True, progress: bool = True, tta: bool = False,
            overlay_format: str = "png", crop_top: float = 0.0) -> dict[str, Any]:
    """``freespace predict``: the road confidence PNGs and overlays of every frame of ``inputs`` in the folder
    ``out`` (:func:`predict_folder`), or, when ``out`` names a video (``.mp4``), the overlaid video
    (:func:`predict_video`), with the model of ``checkpoint`` or ``onnx`` (one of them).

    ``out`` is checked before the model is loaded. ``shard`` (``"K/N"`` or ``(K, N)``, 1-based) and
    ``overlays=False`` are for a folder ``out`` only. ``threads``: the network's CPU threads (None: the cores
    this process may use; else 1…:func:`~freespace.limits.max_workers`, checked first). ``tta``: each frame seen
    with its light normalised and averaged with its mirror image (:class:`~freespace.inference.predictor.Predictor`;
    two network passes a frame), recorded in the output's run record and summary; ``crop_top``, likewise: the top
    ``crop_top × H`` rows of every frame left out of the network's input and scored 0 (a region of interest).

    Returns:
        The run's summary (:func:`predict_folder` or :func:`predict_video`).

    Raises:
        InvalidOptionError: ``shard`` or ``overlays=False`` with a video ``out``, a bad ``shard`` or ``threads``,
            an ``out`` that may not be written.
    """
    check_threads(threads)  # before anything else
    video = is_video_path(out)
    check_writable(out, folder=not video)  # before the model is loaded
    check_outputs({"out": out}, {"input": inputs, "checkpoint": checkpoint, "onnx": onnx})
    if video:
        check_suffix(out, (".mp4",))
    if isinstance(shard, str):
        shard = parse_shard(shard)
    if video and shard:
        raise InvalidOptionError(f"{param('shard')} writes frames into a folder; a video {param('out')} is one file: "
                                 f"leave out {param('shard')}")
    if overlay_format != "png" and (video or not overlays):
        raise InvalidOptionError(f"{param('overlay_format')} is the format of a folder's overlays/; "
                                 f"{'a video is one file' if video else 'they are left out'}: leave it out")
    if video and not overlays:
        raise InvalidOptionError(f"{param('no_overlays')} leaves out the overlay PNGs of a folder {param('out')}; a "
                                 f"video {param('out')} is the overlay: leave out {param('no_overlays')}")
    predictor = Predictor(checkpoint=checkpoint, onnx=onnx, threads=threads, tta=tta, crop_top=crop_top)
    if video:
        return predict_video(predictor, inputs, out, batch_size=batch_size, progress=progress)
    return predict_folder(predictor, inputs, out, batch_size=batch_size, progress=progress, shard=shard,
                          overlays=overlays, overlay_format=overlay_format)


def predict_report(summary: dict[str, Any], out: PathLike, shard: str | None = None, profile: bool = False) -> str:
    """One line on a :func:`predict` run (``summary``: its return value) into ``out``: frames, frames per second
    end to end, the network's time per frame and share; ``shard``: the run's ``"K/N"`` as given. With ``profile``
    a second line: each stage's milliseconds per frame (``summary["profile_ms_per_frame"]``)."""
    out = shown_path(out)  # a name of any bytes: printable
    if not summary["frames"]:
        return f"0 frames in shard {shard} → {out}"
    line = (f"{summary['frames']} frames in {summary['seconds']:.2f} s: {summary['frames_per_second']:.1f} frames per "
            f"second end to end (first frame read to last written); the network "
            f"{summary['seconds_per_frame'] * 1000:.1f} ms per frame, {100 * summary['network_share']:.0f} % of the "
            f"time" + (f" (shard {shard})" if shard else "") + f" → {out}")
    if not profile:
        return line
    ms = summary["profile_ms_per_frame"]
    stages = ", ".join(f"{k} {ms[k]:.1f}" for k in STAGES)
    return (line + f"\nprofile, ms per frame (each stage's own time; in the pipeline they overlap across threads): "
                   f"{stages}; end to end {ms['end_to_end']:.1f}")
