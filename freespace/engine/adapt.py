"""``freespace adapt``: self-training of a published road model on a user's unlabelled frames.

A model trained on one city and camera loses road on another. Adapt fits it to the user's frames without a
label, by **mean-teacher self-training in rounds**:

- the *teacher* starts as the published model (its ``model.ckpt``, a weights-only checkpoint) and follows the
  student as an exponential moving average of its weights (``ema``), so it moves slowly;
- at the start of each round (one pass over the frames) the teacher labels every frame (ONNX Runtime on a
  float32 export of the teacher, ~10× a PyTorch forward on a CPU): its road probability on the frame and on its
  mirror image, averaged, both seen with their light normalised (a gamma to a mean brightness of
  :data:`LABEL_BRIGHTNESS` and a local contrast equalisation, :func:`normalise_light`, which finds most of the
  road that the published model misses at dusk); pixels with ``p > threshold`` are road, ``p < 1 − threshold``
  not road, the rest ignored;
- the *student* learns those labels on strongly augmented views (random scale and crop of half the frame's
  width, :data:`CROP_WIDTH`; mirror, brightness, contrast, saturation, gamma, blur, noise:
  :func:`strong_views`), with cross entropy on the confident pixels;
  its batch norms keep the published statistics (frozen: a published model's are folded into its
  convolutions, and batches of a few frames would give noisy ones);
- with ``source`` (frames of the model's own training drives, which its card names) a quarter of each batch
  comes from those frames, labelled once by the published model: what the model knew is rehearsed, not
  forgotten.

**Collapse guard.** Without a label a self-trained model can drift to all road or no road. A few of the user's
frames are held out of training; after every round, and before anything is written, the teacher's road share
on them is compared with the published model's: below :data:`MIN_ROAD_SHARE`, above :data:`MAX_ROAD_SHARE`,
or more than ``max_drift`` from the start, and (with ``source``) a mask agreement with the published model
on the source frames below :data:`MIN_SOURCE_AGREEMENT`, end the run with one line (:class:`CollapseError`)
and nothing written.

The written folder is a model folder like the published ones (:func:`freespace.engine.adapt_io.write_model_folder`):
the float16 ``model.onnx`` (exported as ``freespace export`` does in float16: the same input size and speed),
``model.ckpt`` (what adapt continues from), ``README.md`` (the card), ``before_after.jpg``, and the run's
``config.json``, ``rounds.csv`` and ``summary.json``. It is written all or nothing (:mod:`freespace.io.outdir`).
"""

from __future__ import annotations

import copy
import io as _io
import logging
import math
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.data.photometry import strong_photometry
from freespace.engine.adapt_io import CHECKPOINT, Frames, frame_paths, read_frames, write_model_folder
from freespace.errors import FreespaceError, InputFileError, InvalidOptionError, check_seed, param
from freespace.io.files import PathLike, check_outputs, check_writable, missing_input
from freespace.limits import MAX_BATCH_SIZE, MAX_EPOCHS, bounded_float, bounded_int

log = logging.getLogger(__name__)

__all__ = ["adapt", "AdaptSettings", "BOUNDS", "CollapseError", "strong_views", "road_probabilities", "pseudo_labels",
           "normalise_light", "MIN_FRAMES", "MIN_ROAD_SHARE", "MAX_ROAD_SHARE", "MIN_SOURCE_AGREEMENT"]

#: frames adapt needs at least (after unreadable ones are skipped): fewer teach a camera nothing
MIN_FRAMES = 20
#: the collapse guard's bounds on the road share of the held-out frames (fractions of their pixels)
MIN_ROAD_SHARE, MAX_ROAD_SHARE = 0.01, 0.95
#: the collapse guard's least share of source pixels whose mask still agrees with the published model's
MIN_SOURCE_AGREEMENT = 0.9
#: ignored pixels of a pseudo-label
IGNORE = 255
#: the student's views are crops of this share of the frame's width, at the frame's scale: half the cost of a
#: step (the network is fully convolutional; the published model sees whole frames as before)
CROP_WIDTH = 0.5
#: the teacher labels a frame after a gamma that brings its mean brightness to this (in [0, 1]; the published
#: model's KITTI frames average 0.35) and a local contrast equalisation (:func:`normalise_light`): seeing CamVid's
#: dusk frames so, the first published ``real-road-fast``'s F there (commit 732c574) rises from 0.35 to 0.76, on
#: its daylight ones it stays 0.88 (chosen on those development frames; the student still learns the frames as
#: they are)
LABEL_BRIGHTNESS = 0.40


#: the bounds of adapt's numeric options (the command line's types too)
BOUNDS = {"epochs": bounded_int(1, MAX_EPOCHS), "minutes": bounded_float(0, 10_000, low_open=True),
          "threshold": bounded_float(0.5, 0.999), "lr": bounded_float(0, 1, low_open=True),
          "batch_size": bounded_int(2, MAX_BATCH_SIZE), "ema": bounded_float(0, 0.9999),
          "max_drift": bounded_float(0, 1, low_open=True)}


class CollapseError(FreespaceError):
    """The student drifted to all road, no road, or far from the published model: nothing was written."""


@dataclass(frozen=True)
class AdaptSettings:
    """The options of one adapt run (see :func:`adapt`); :meth:`check` refuses values out of :data:`BOUNDS`."""

    epochs: int = 4
    minutes: float | None = None
    threshold: float = 0.9
    lr: float = 1e-4
    batch_size: int = 8
    ema: float = 0.99
    max_drift: float = 0.3
    seed: int = 0

    def check(self) -> AdaptSettings:
        """These settings, each option checked against :data:`BOUNDS` (whole numbers made ``int``).

        Raises:
            InvalidOptionError: an option out of bounds (named, with its bounds).
        """
        check_seed(self.seed)
        values = {}
        for name, bound in BOUNDS.items():
            value = getattr(self, name)
            if value is None:
                continue
            try:
                values[name] = bound.kind(bound.check(value))
            except InvalidOptionError as exc:
                raise InvalidOptionError(f"{param(name)} {exc}") from None
        return replace(self, **values)


def _model_folder(model: PathLike) -> tuple[Path, Path]:
    """The model folder and its checkpoint, checked to exist.

    Raises:
        InputFileError: no such folder, or it holds no :data:`CHECKPOINT`.
    """
    folder = Path(model)
    if not folder.is_dir():
        raise missing_input(folder, "model folder", "folder")
    ckpt = folder / CHECKPOINT
    if not ckpt.is_file():
        raise InputFileError(f"{param('model')} {folder} has no checkpoint ({CHECKPOINT}); adapt continues from a "
                             f"model folder's weights: give one that carries them (models/real-road-fast does)")
    return folder, ckpt


def _teacher_session(net: Any, size: tuple[int, int], threads: int) -> Any:
    """An ONNX Runtime session of a float32 export of ``net`` (in eval mode) at ``size`` = (h, w), any batch."""
    import onnxruntime as ort
    import torch

    from freespace.inference.predictor import session_options

    buf = _io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the tracer's notes
        torch.onnx.export(net.eval(), (torch.zeros(1, 3, *size),), buf, dynamo=False, opset_version=17,
                          input_names=["image"], output_names=["logits"],
                          dynamic_axes={"image": {0: "n"}, "logits": {0: "n"}})
    return ort.InferenceSession(buf.getvalue(), session_options(threads), providers=["CPUExecutionProvider"])


def normalise_light(image: np.ndarray) -> np.ndarray:
    """The teacher's view of an ``H×W×3 uint8`` RGB frame: a gamma that brings its mean brightness to
    :data:`LABEL_BRIGHTNESS`, then CLAHE (clip limit 2, 8×8 tiles) on the lightness (CIE Lab's L)."""
    x = np.clip(image.astype(np.float32) / 255.0, 1e-6, 1.0)
    gamma = math.log(LABEL_BRIGHTNESS) / math.log(min(max(float(x.mean()), 1e-3), 0.999))
    lab = cv2.cvtColor((x ** gamma * 255.0).astype(np.uint8), cv2.COLOR_RGB2LAB)
    lab[..., 0] = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(np.ascontiguousarray(lab[..., 0]))
    return cv2.cvtColor(lab, cv2.COLOR_LAB2RGB)


def road_probabilities(session: Any, images: np.ndarray, batch: int = 8, normalise: bool = False) -> np.ndarray:
    """The road probability (``N×h×w float16`` in [0, 1]) of ``N×h×w×3 uint8`` frames at the network's size:
    the mean of the network's on the frame and (mirrored back) on its mirror image; with ``normalise``, on
    the frames as :func:`normalise_light` makes them (the teacher's view)."""
    out = np.empty(images.shape[:3], np.float16)
    for i in range(0, len(images), batch):
        chunk = images[i:i + batch]
        if normalise:
            chunk = np.stack([normalise_light(image) for image in chunk])
        x = chunk.transpose(0, 3, 1, 2).astype(np.float32) / 255.0
        n = len(x)
        logits = session.run(None, {"image": np.ascontiguousarray(np.concatenate([x, x[..., ::-1]]))})[0]
        prob = 1.0 / (1.0 + np.exp(np.clip(logits[:, 0] - logits[:, 1], -60, 60)))  # softmax of two classes
        out[i:i + n] = (prob[:n] + prob[n:, :, ::-1]) / 2
    return out


def pseudo_labels(probs: np.ndarray, threshold: float) -> np.ndarray:
    """Labels (``uint8``, same shape) from road probabilities: 1 where ``p > threshold``, 0 where
    ``p < 1 − threshold``, :data:`IGNORE` between."""
    labels = np.full(probs.shape, IGNORE, np.uint8)
    labels[probs > threshold] = 1
    labels[probs < 1 - threshold] = 0
    return labels


def strong_views(images: np.ndarray, labels: np.ndarray, rng: np.random.Generator,
                 width_share: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Strongly augmented copies of ``N×h×w×3 uint8`` frames and their ``N×h×w uint8`` labels.

    Geometry (the labels follow, nearest neighbour): a random crop of 1/1.6…1 of the height and of
    ``width_share``·w scaled to h × ``width_share``·w (at ``width_share`` 1: the whole frame's size), a mirror
    image half of the time. Photometry (frames only): :func:`freespace.data.photometry.strong_photometry`
    (saturation, contrast, brightness, gamma, blur, noise).

    Returns:
        ``N×3×h×w'`` float32 frames in [0, 1] and ``N×h×w'`` int64 labels (w' = round(``width_share``·w)).
    """
    n, h, w = labels.shape
    ow = int(round(w * width_share))
    xs = np.empty((n, 3, h, ow), np.float32)
    ys = np.empty((n, h, ow), np.int64)
    for i in range(n):
        s = rng.uniform(1.0, 1.6)
        ch, cw = int(round(h / s)), int(round(ow / s))
        y0, x0 = rng.integers(0, h - ch + 1), rng.integers(0, w - cw + 1)
        img = cv2.resize(images[i, y0:y0 + ch, x0:x0 + cw], (ow, h), interpolation=cv2.INTER_LINEAR)
        lab = cv2.resize(labels[i, y0:y0 + ch, x0:x0 + cw], (ow, h), interpolation=cv2.INTER_NEAREST)
        if rng.random() < 0.5:
            img, lab = img[:, ::-1], lab[:, ::-1]
        xs[i] = strong_photometry(img.astype(np.float32) / 255.0, rng).transpose(2, 0, 1)
        ys[i] = lab
    return xs, ys


def _ema(teacher: Any, student: Any, decay: float) -> None:
    """teacher ← decay·teacher + (1 − decay)·student, weight by weight (buffers: copied)."""
    import torch

    with torch.no_grad():
        for t, s in zip(teacher.parameters(), student.parameters()):
            t.mul_(decay).add_(s.detach(), alpha=1 - decay)
        for t, s in zip(teacher.buffers(), student.buffers()):
            t.copy_(s)


def _student(net: Any) -> Any:
    """A copy of ``net`` in training mode with its batch norms frozen (eval: the published statistics)."""
    import torch

    student = copy.deepcopy(net).train()
    for m in student.modules():
        if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
            m.eval()
    return student.to(memory_format=torch.channels_last)


@dataclass
class _Data:
    """What one adapt run trains on: the target frames with their current road probabilities, the indices
    of the training and held-out frames, and the source frames with the published model's labels."""

    images: np.ndarray
    probs: np.ndarray
    train: np.ndarray
    held: np.ndarray
    source: np.ndarray | None = None
    source_labels: np.ndarray | None = None


def _train_round(student: Any, teacher: Any, opt: Any, data: _Data, settings: AdaptSettings,
                 rng: np.random.Generator, deadline: float, bar: Any) -> dict[str, float]:
    """One pass of the student over the training frames (the teacher following it); stops early at
    ``deadline`` (``time.monotonic()``). Returns the mean loss, the share of confident pixels, the steps
    and whether the deadline stopped it (1.0) or not (0.0).

    Raises:
        TrainingError: the loss became NaN or infinite.
    """
    import torch
    import torch.nn.functional as F

    from freespace.errors import TrainingError
    from freespace.models import main_logits

    per_step, n_src = _batch_split(settings.batch_size, data.source is not None)
    order = rng.permutation(data.train)
    losses, confident, stopped = [], [], 0.0
    for start in range(0, len(order), per_step):
        idx = np.sort(order[start:start + per_step])
        images, labels = data.images[idx], pseudo_labels(data.probs[idx].astype(np.float32), settings.threshold)
        if n_src:
            pick = rng.integers(len(data.source), size=n_src)
            images = np.concatenate([images, data.source[pick]])
            labels = np.concatenate([labels, data.source_labels[pick]])
        x, y = strong_views(images, labels, rng, CROP_WIDTH)
        confident.append(float((y != IGNORE).mean()))
        if confident[-1] > 0:
            loss = F.cross_entropy(main_logits(student(torch.from_numpy(x).contiguous(
                memory_format=torch.channels_last))), torch.from_numpy(y), ignore_index=IGNORE)
            if not torch.isfinite(loss):
                raise TrainingError(f"the loss became {loss.item()}; lower {param('lr')}")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            _ema(teacher, student, settings.ema)
            losses.append(float(loss.detach()))
        bar.update(1)
        if time.monotonic() > deadline:
            stopped = 1.0
            break
    return {"loss": float(np.mean(losses)) if losses else float("nan"), "confident": float(np.mean(confident)),
            "steps": float(len(confident)), "stopped": stopped}


def _batch_split(batch_size: int, source: bool) -> tuple[int, int]:
    """Frames per step from the user's frames and from the source frames: a quarter (at least one) from the
    source when there is one."""
    n_src = max(1, batch_size // 4) if source else 0
    return batch_size - n_src, n_src


def _guard(before: dict[str, float], now: dict[str, float], settings: AdaptSettings, when: str) -> None:
    """Refuse a model that drifted to all road, no road or far from the published one (see the module).

    Raises:
        CollapseError: one line that says what drifted, by how much, and what to change.
    """
    share, start = now["road_share"], before["road_share"]
    fix = f"nothing was written; lower {param('lr')} or {param('epochs')}, or raise {param('threshold')}"
    if share < MIN_ROAD_SHARE or share > MAX_ROAD_SHARE:
        raise CollapseError(f"adapt collapsed {when}: the model marks {share:.1%} of the held-out frames as road "
                            f"({'no road' if share < MIN_ROAD_SHARE else 'all road'}; {start:.1%} before); {fix}")
    if abs(share - start) > settings.max_drift:
        raise CollapseError(f"adapt drifted {when}: the road share of the held-out frames went from {start:.1%} to "
                            f"{share:.1%}, more than {param('max_drift')} {settings.max_drift:g}; {fix}")
    agree = now.get("source_agreement")
    if agree is not None and agree < MIN_SOURCE_AGREEMENT:
        raise CollapseError(f"adapt drifted {when}: on the source frames its masks agree with the published model's "
                            f"on {agree:.1%} of the pixels (at least {MIN_SOURCE_AGREEMENT:.0%} needed); {fix}")


def _measure(session: Any, data: _Data, source_masks: np.ndarray | None) -> tuple[dict[str, float], np.ndarray]:
    """Relabel the frames with ``session`` (``data.probs`` replaced: the teacher's view) and measure the
    model as it runs, on the frames as they are: the road share (p ≥ 0.5) and mean confidence (max(p, 1 − p))
    of the held-out frames, and with source frames the share of their pixels whose mask agrees with
    ``source_masks`` (the published model's). Returns the measures and the held-out probabilities."""
    data.probs = road_probabilities(session, data.images, normalise=True)
    held = road_probabilities(session, data.images[data.held]).astype(np.float32)
    out = {"road_share": float((held >= 0.5).mean()), "confidence": float(np.maximum(held, 1 - held).mean())}
    if source_masks is not None:
        out["source_agreement"] = float(((road_probabilities(session, data.source) >= 0.5) == source_masks).mean())
    return out, held


def _held_out(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the training and held-out frames: 1 in 20 held out (4 to 16), spread over the sequence."""
    k = int(np.clip(n // 20, 4, 16))
    offset = int(rng.integers(0, max(1, n // k)))
    held = np.unique(np.minimum(np.linspace(0, n - 1, k).round().astype(int) + offset, n - 1))
    return np.setdiff1d(np.arange(n), held), held


def adapt(model: PathLike, inputs: PathLike, out: PathLike, *, source: PathLike | None = None,
          epochs: int = AdaptSettings.epochs, minutes: float | None = None,
          threshold: float = AdaptSettings.threshold, lr: float = AdaptSettings.lr,
          batch_size: int = AdaptSettings.batch_size, ema: float = AdaptSettings.ema,
          max_drift: float = AdaptSettings.max_drift, seed: int = AdaptSettings.seed, progress: bool = True,
          threads: int | None = None) -> dict[str, Any]:
    """Adapt the published model in the folder ``model`` to the unlabelled frames ``inputs``; write the
    adapted model folder ``out`` (see the module's docstring for the method and what is written).

    Args:
        model: a model folder holding :data:`CHECKPOINT` (``models/real-road-fast``).
        inputs: the user's frames: a folder, a glob or a video (any size: each is resized to the network's,
            as ``predict`` does). At least :data:`MIN_FRAMES` readable ones; unreadable ones are skipped
            and counted; more than :data:`~freespace.engine.adapt_io.MAX_FRAMES` are thinned evenly.
        out: the new model folder (not inside ``model`` nor equal to it), written all or nothing.
        source: frames of the model's own training data to rehearse (its card names them), or None.
        epochs: rounds (passes over the frames; the teacher relabels them after each).
        minutes: a time limit for the training (None: none); the round it ends in is the last.
        threshold: a pixel is a label where the teacher's road probability is above it (road) or below
            1 − it (not road); in [0.5, 0.999].
        lr: the student's AdamW learning rate. batch_size: frames per step (≥ 2).
        ema: the teacher's decay per step (0: the teacher is the student). max_drift: the most the held-out
            frames' road share (a fraction) may move before the collapse guard stops the run.
        seed: the frame order, hold-out and augmentation draws. threads: CPU threads (None: the cores this
            process may use). progress: a progress bar on a terminal (one line per round otherwise).

    Returns:
        The summary written to ``out/summary.json``: frames, settings, seconds, the road share and mean
        confidence before and after on the held-out frames, the float16 export's check.

    Raises:
        InputFileError: no model folder or checkpoint; no frames or none readable. InvalidOptionError: an
        option out of bounds, too few frames, ``out`` inside or equal to ``model`` or among the inputs.
        CorruptFileError: a damaged checkpoint or video. CollapseError: the collapse guard stopped the run.
    """
    from freespace.inference.predictor import load_checkpoint
    from freespace.io.outdir import claim_folder

    settings = AdaptSettings(epochs, minutes, threshold, lr, batch_size, ema, max_drift, seed).check()
    folder, ckpt = _model_folder(model)
    check_writable(out, folder=True)
    inputs_of: dict[str, PathLike | None] = {"model": folder}
    for name, spec in (("input", inputs), ("source", source)):
        if spec is not None:
            kind, paths = frame_paths(spec)
            for i, p in enumerate(sorted({p.parent for p in paths}) if kind == "images" else paths):
                inputs_of[f"{name}[{i}]" if i else name] = p
    check_outputs({"out": out}, inputs_of)
    net, hp = load_checkpoint(ckpt)
    size = tuple(hp.get("image_size") or ())
    if len(size) != 2:
        raise InvalidOptionError(f"{ckpt} states no training image size; adapt needs the size the model runs at")
    frames = read_frames(inputs, size)
    if len(frames.names) < MIN_FRAMES:
        raise InvalidOptionError(f"{param('input')} {inputs}: {len(frames.names)} readable frames ({frames.skipped} "
                                 f"unreadable); adapt needs at least {MIN_FRAMES}: give more frames of the camera")
    src = read_frames(source, size, "source") if source is not None else None
    t0 = time.monotonic()
    with claim_folder(out, "adapt") as owned, owned.staged() as stage:
        run = _self_train(net, frames, src, settings, progress, threads)
        return write_model_folder(stage, run, hp, folder, frames, src, asdict(settings), time.monotonic() - t0,
                                  Path(out))


def _self_train(net: Any, frames: Frames, src: Frames | None, settings: AdaptSettings, progress: bool,
                threads: int | None) -> dict[str, Any]:
    """The self-training loop (module docstring). Returns the adapted network (the teacher), one row per
    round, the held-out measures before and after, the held-out indices and their road probabilities before
    and after (``N×h×w float32``, the frames as they are).

    Raises:
        CollapseError: the guard stopped it. TrainingError: the loss became NaN.
    """
    import torch

    from freespace.inference.predictor import machine_threads

    threads = threads or machine_threads()
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return {**_rounds(net, frames, src, settings, progress, threads), "threads": threads}
    finally:  # the caller's own setting back
        torch.set_num_threads(previous)


def _rounds(net: Any, frames: Frames, src: Frames | None, settings: AdaptSettings, progress: bool,
            threads: int) -> dict[str, Any]:
    """:func:`_self_train`'s loop, on ``threads`` torch and ONNX Runtime threads."""
    import torch

    from freespace.runtime.log import progress_bar

    torch.manual_seed(settings.seed)
    rng = np.random.default_rng(settings.seed)
    size = frames.images.shape[1:3]
    train, held = _held_out(len(frames.names), rng)
    data = _Data(frames.images, np.empty(0, np.float16), train, held, src.images if src is not None else None)
    teacher = net.eval()
    session = _teacher_session(teacher, size, threads)
    source_masks = None
    if data.source is not None:
        p = road_probabilities(session, data.source).astype(np.float32)
        data.source_labels, source_masks = pseudo_labels(p, settings.threshold), p >= 0.5
    before, held_before = _measure(session, data, source_masks)
    student = _student(teacher)
    opt = torch.optim.AdamW(student.parameters(), lr=settings.lr, weight_decay=0.0)
    per_step = _batch_split(settings.batch_size, src is not None)[0]
    bar = progress_bar(total=settings.epochs * math.ceil(len(train) / per_step), desc="adapt", unit="step",
                       enabled=progress)
    start = time.monotonic()
    deadline = start + settings.minutes * 60 if settings.minutes else math.inf
    rows, now, held_now = [], before, held_before
    for r in range(1, settings.epochs + 1):
        stats = _train_round(student, teacher, opt, data, settings, rng, deadline, bar)
        now, held_now = _measure(_teacher_session(teacher, size, threads), data, source_masks)
        rows.append({"round": r, **stats, **now, "seconds": round(time.monotonic() - start, 1)})
        log.info("adapt round %d/%d: loss %.4f, confident pixels %.1f%%, held-out road share %.1f%% (%.1f%% before)%s",
                 r, settings.epochs, stats["loss"], 100 * stats["confident"], 100 * now["road_share"],
                 100 * before["road_share"], ", time limit reached" if stats["stopped"] else "")
        _guard(before, now, settings, f"in round {r}")
        if stats["stopped"]:
            break
    bar.close()
    return {"net": teacher, "rounds": rows, "before": before, "after": now, "held": held,
            "held_probs": (held_before, held_now), "train_frames": len(train)}
