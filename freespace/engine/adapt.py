"""``freespace adapt``: self-training of a published road model on a user's unlabelled frames.

A model trained on one city and camera loses road on another. Adapt fits it to the user's frames without a
label, by **mean-teacher self-training in rounds**:

- the *teacher* starts as the published model (its ``model.ckpt``, a weights-only checkpoint) and follows the
  student as an exponential moving average of its weights (``ema``), so it moves slowly;
- at the start of each round (one pass over the frames) the teacher labels every frame (ONNX Runtime on a
  float32 export of the teacher, ~10× a PyTorch forward on a CPU): its road probability on the frame and on its
  mirror image, averaged, both seen with their light normalised (a gamma to a mean brightness of
  :data:`~freespace.data.photometry.LABEL_BRIGHTNESS` and a local contrast equalisation,
  :func:`~freespace.data.photometry.normalise_light`, which finds most of the road that the published model misses
  at dusk); pixels with ``p > threshold`` are road, ``p < 1 − threshold``
  not road, the rest ignored;
- the *student* learns those labels on strongly augmented views (random scale and crop of half the frame's
  width, :data:`CROP_WIDTH`; mirror, brightness, contrast, saturation, gamma, blur, noise:
  :func:`strong_views`), with cross entropy on the confident pixels;
  its batch norms keep the statistics the run starts with (frozen: batches of a few strongly augmented views would
  give noisy ones);
- with ``source`` (frames of the model's own training drives, which its card names) a quarter of each batch
  comes from those frames, labelled once by the published model: what the model knew is rehearsed, not
  forgotten.

**Batch-norm statistics first** (``norm_stats``; AdaBN, :mod:`freespace.engine.norm_stats`): before the first
round every batch norm's running mean and variance are estimated again on up to
:data:`~freespace.engine.norm_stats.MAX_NORM_FRAMES` of the training frames (as they are, at the model's size: what
the adapted model runs on), so that teacher and student start from the statistics of the user's camera. ``auto``
(the default) does so when the checkpoint holds the statistics of a training run and keeps them when they are
folded into the convolutions (a checkpoint rebuilt from an ONNX file, as ``models/real-road-unet``'s: every batch norm
the identity, where new statistics would normalise twice); ``frames`` insists (and refuses such a checkpoint);
``keep`` keeps them. The held-out measures right after it are recorded beside those before and after, and the
collapse guard checks it as it checks a round.

**Labels carried along time** (``across_time``; :mod:`freespace.engine.adapt_time`): when the frames are a sequence
(a video, or consecutive frames: ``auto`` checks that at least half of the consecutive pairs share a road
homography), each round's labels are carried from the next frames along the road plane's homographies
(:mod:`freespace.datagen.temporal`): the far road and the road beside the cars, which the teacher is sure of only
once the car is nearer, join the labels. With ``complete`` (the default), each training frame's label then has its
don't care decided by a graph cut on the frame's colours (:func:`freespace.datagen.completion.complete_by_appearance`).

**Before training** the published model labels the frames: outputs that are not finite (a damaged checkpoint),
a confident pixel on less than :data:`MIN_CONFIDENT_SHARE` of them (nothing to learn from), no road or nothing
but road (a road share of the held-out frames outside :data:`MIN_ROAD_SHARE`…:data:`MAX_ROAD_SHARE`, or no
confident road or non-road pixel) are refused in one line, naming what is wrong with the frames or the checkpoint.

**Collapse guard.** Without a label a self-trained model can drift to all road or no road, or diverge. A few of
the user's frames are held out of training; after every round, and before anything is written, the teacher's
road share on them is compared with the published model's: below :data:`MIN_ROAD_SHARE`, above
:data:`MAX_ROAD_SHARE`, more than ``max_drift`` from the start, below :data:`MIN_ROAD_RATIO` (half) or above
:data:`MAX_ROAD_RATIO` (twice) the start (or the published model's share in the teacher's view, when larger)
— a relative bound, which acts on frames with little road, where an absolute drift cannot —, and (with
``source``) a mask agreement with the published model on the source frames below :data:`MIN_SOURCE_AGREEMENT`,
end the run; so do a loss that is not finite, a loss that diverges (the mean of
its last :data:`LOSS_WINDOW` steps above :data:`LOSS_GROWTH` times its first step's, and above
:data:`LOSS_FLOOR`), and a round in which the teacher is sure of no pixel. Each ends the run with one line
(:class:`CollapseError`, a :class:`~freespace.errors.TrainingError`: exit code 1) and nothing written.

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
import os
import reprlib
import time
import warnings
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.data.photometry import normalise_light, strong_photometry
from freespace.engine.adapt_io import (
    CHECKPOINT,
    MAX_FRAMES,
    MIN_FRAME_SIDE,
    Frames,
    frame_paths,
    read_frames,
    write_model_folder,
)
from freespace.engine.adapt_time import check_across_time, plan_sequence, round_labels
from freespace.engine.norm_stats import check_norm_stats, norm_stats_plan, reestimate_norm_stats
from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, TrainingError, check_seed, param
from freespace.io.codecs import MAX_IMAGE_SIDE
from freespace.io.files import PathLike, check_outputs, check_writable, missing_input
from freespace.limits import MAX_EPOCHS, bounded_float, bounded_int, check_threads

log = logging.getLogger(__name__)

__all__ = ["adapt", "AdaptSettings", "BOUNDS", "CollapseError", "strong_views", "road_probabilities", "pseudo_labels",
           "normalise_light", "MIN_FRAMES", "MIN_ROAD_SHARE", "MAX_ROAD_SHARE", "MIN_SOURCE_AGREEMENT",
           "MIN_ROAD_RATIO", "MAX_ROAD_RATIO", "LOSS_GROWTH", "LOSS_WINDOW", "LOSS_FLOOR", "MIN_CONFIDENT_SHARE",
           "MAX_ADAPT_BATCH", "MAX_STEP_PIXELS", "MAX_FRAME_BYTES"]

#: frames adapt needs at least (after unreadable ones are skipped): fewer teach a camera nothing
MIN_FRAMES = 20
#: the collapse guard's bounds on the road share of the held-out frames (fractions of their pixels)
MIN_ROAD_SHARE, MAX_ROAD_SHARE = 0.01, 0.95
#: the collapse guard's least share of source pixels whose mask still agrees with the published model's
MIN_SOURCE_AGREEMENT = 0.9
#: the collapse guard's bounds on the held-out road share relative to the published model's: below half or above
#: twice it ends the run whatever ``max_drift`` (an absolute drift of 0.3 never acts on frames with less road)
MIN_ROAD_RATIO, MAX_ROAD_RATIO = 0.5, 2.0
#: the loss diverged when the mean of its last LOSS_WINDOW steps is more than LOSS_GROWTH times its first step's
#: (an order of magnitude) and above LOSS_FLOOR (ln 2: the loss of a student that says 50 % everywhere)
LOSS_GROWTH, LOSS_WINDOW, LOSS_FLOOR = 10.0, 8, math.log(2)
#: the share of the frames' pixels the published model must be sure of at least (the labels): less leaves nothing
#: to learn from
MIN_CONFIDENT_SHARE = 0.001
#: frames per step at most (the user's and the source's together: a quarter of them source frames)
MAX_ADAPT_BATCH = 64
#: pixels of the student's views per step at most (the batch times the model's height times half its width): 2²²,
#: 64 views of a 192×640 model's (models/real-road-fast), 17 of a 384×1248 one's; a model of more pixels than
#: this is refused (two views of it would be more)
MAX_STEP_PIXELS = 2**22
#: the bytes the frames of one set (input, source) may hold at most, as adapt keeps them (RGB and a float16 road
#: probability, 5 bytes a pixel at the model's size): fewer than MAX_FRAMES are kept of a model of many pixels
MAX_FRAME_BYTES = 2 * 2**30
#: ignored pixels of a pseudo-label
IGNORE = 255
#: the student's views are crops of this share of the frame's width, at the frame's scale: half the cost of a
#: step (the network is fully convolutional; the published model sees whole frames as before)
CROP_WIDTH = 0.5


#: the bounds of adapt's numeric options (the command line's types too); of them only ``minutes`` may be None
BOUNDS = {"epochs": bounded_int(1, MAX_EPOCHS), "minutes": bounded_float(0, 10_000, low_open=True),
          "threshold": bounded_float(0.5, 0.999), "lr": bounded_float(0, 1, low_open=True),
          "batch_size": bounded_int(2, MAX_ADAPT_BATCH), "ema": bounded_float(0, 0.9999),
          "max_drift": bounded_float(0, 1, low_open=True), "release": bounded_float(0, 1),
          "release_far": bounded_float(0, 1, low_open=True)}


class CollapseError(TrainingError):
    """The student drifted to all road, no road, or far from the published model, or its loss diverged: nothing
    was written (exit code 1, a run that failed)."""


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
    norm_stats: str = "auto"
    across_time: str = "auto"
    complete: bool = True
    release: float = 0.0
    release_far: float = 1.0
    #: the lane ahead's columns (fractions of the width) whose road teaches the road's look, or None: no look check
    look: tuple[float, float] | None = None

    def check(self) -> AdaptSettings:
        """These settings, each option checked against :data:`BOUNDS` (whole numbers made ``int``), ``norm_stats``
        against :data:`~freespace.engine.norm_stats.NORM_STATS`, ``across_time`` against
        :data:`~freespace.engine.adapt_time.ACROSS_TIME`, ``complete`` a bool.

        Raises:
            InvalidOptionError: an option out of bounds, of another type, or None where a value is needed (named,
            with its bounds); a ``norm_stats`` or ``across_time`` that is none of its values, a ``complete`` that is
            no bool.
        """
        check_seed(self.seed)
        check_across_time(self.across_time)
        if not isinstance(self.complete, bool):
            raise InvalidOptionError(f"{param('complete')} must be True or False, got {reprlib.repr(self.complete)}")
        check_norm_stats(self.norm_stats)
        look = None if self.look is None else _check_look(self.look)
        if self.release and not self.complete:
            raise InvalidOptionError(f"{param('release')} acts in the completion by appearance; leave "
                                     f"{param('complete')} on or {param('release')} at 0")
        values = {}
        for name, bound in BOUNDS.items():
            value = getattr(self, name)
            if value is None and name == "minutes":  # no time limit
                continue
            try:
                values[name] = bound.kind(bound.check(value))
            except InvalidOptionError as exc:
                raise InvalidOptionError(f"{param(name)} {exc}") from None
        return replace(self, **values, look=look)


def _check_look(look: Any) -> tuple[float, float]:
    """``look`` as a ``(lo, hi)`` pair of floats, 0 ≤ lo < hi ≤ 1, or :class:`InvalidOptionError` naming it."""
    try:
        lo, hi = (float(x) for x in look)
    except (TypeError, ValueError):
        lo = hi = math.nan
    if not 0 <= lo < hi <= 1:
        raise InvalidOptionError(f"{param('look')} must be two fractions of the width, 0 ≤ lo < hi ≤ 1 (the lane "
                                 f"ahead, e.g. 0.30,0.55), got {reprlib.repr(look)}")
    return lo, hi


def _check_look_weights(settings: AdaptSettings) -> None:
    """With a look check, load its ImageNet encoder before any work: a missing one ends the run at once, in one line
    (:class:`~freespace.errors.PretrainedWeightsError` says what to install)."""
    if settings.look is not None:
        from freespace.datagen.options import LookOptions
        from freespace.datagen.road_look import look_encoder

        look_encoder(LookOptions().encoder)  # the encoder _look_check's looks_like_road loads


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


def road_probabilities(session: Any, images: np.ndarray, batch: int = 8, normalise: bool = False) -> np.ndarray:
    """The road probability (``N×h×w float16`` in [0, 1]) of ``N×h×w×3 uint8`` frames at the network's size:
    the mean of the network's on the frame and (mirrored back) on its mirror image; with ``normalise``, on
    the frames as :func:`~freespace.data.photometry.normalise_light` makes them (the teacher's view)."""
    out = np.empty(images.shape[:3], np.float16)
    for i in range(0, len(images), batch):
        chunk = images[i:i + batch]
        if normalise:
            chunk = np.stack([normalise_light(image) for image in chunk])
        x = chunk.transpose(0, 3, 1, 2).astype(np.float32) / 255.0
        n = len(x)
        logits = session.run(None, {"image": np.ascontiguousarray(np.concatenate([x, x[..., ::-1]]))})[0]
        with np.errstate(over="ignore", invalid="ignore"):  # a damaged model's inf/NaN: refused by the caller
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
    #: the loss of every step so far, over all rounds (the divergence check's record)
    losses: list[float] = field(default_factory=list)
    #: the round's labels carried along time and/or completed by appearance (``N×h×w uint8``), or None: the
    #: confident labels of ``probs``
    labels: np.ndarray | None = None


def _train_round(student: Any, teacher: Any, opt: Any, data: _Data, settings: AdaptSettings,
                 rng: np.random.Generator, deadline: float, bar: Any, when: str = "") -> dict[str, float]:
    """One pass of the student over the training frames (the teacher following it); stops early at
    ``deadline`` (``time.monotonic()``). Returns the mean loss, the share of confident pixels, the steps
    and whether the deadline stopped it (1.0) or not (0.0).

    Raises:
        TrainingError: the loss became NaN or infinite. CollapseError: the loss diverged (:func:`_check_loss`), or
        no view of the round held a confident pixel.
    """
    import torch
    import torch.nn.functional as F

    from freespace.models import main_logits

    per_step, n_src = _batch_split(settings.batch_size, data.source is not None)
    order = rng.permutation(data.train)
    losses, confident, stopped = [], [], 0.0
    for start in range(0, len(order), per_step):
        idx = np.sort(order[start:start + per_step])
        images = data.images[idx]
        labels = (data.labels[idx] if data.labels is not None
                  else pseudo_labels(data.probs[idx].astype(np.float32), settings.threshold))
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
                raise TrainingError(f"adapt diverged {when}: the loss became {loss.item()}; nothing was written; "
                                    f"lower {param('lr')}")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            _ema(teacher, student, settings.ema)
            losses.append(float(loss.detach()))
            data.losses.append(losses[-1])
            if len(data.losses) > LOSS_WINDOW:
                _check_loss(data.losses, when)
        bar.update(1)
        if time.monotonic() > deadline:
            stopped = 1.0
            break
    if not losses:
        raise CollapseError(f"adapt stopped {when}: the teacher was sure of no pixel of the round's views (its road "
                            f"probability never above {param('threshold')} {settings.threshold:g} nor below "
                            f"{1 - settings.threshold:g}): nothing to learn from; nothing was written; lower "
                            f"{param('threshold')} or give frames more like the model's own")
    _check_loss(data.losses, when)
    return {"loss": float(np.mean(losses)), "confident": float(np.mean(confident)),
            "steps": float(len(confident)), "stopped": stopped}


def _check_loss(losses: list[float], when: str) -> None:
    """Refuse a loss that diverged: the mean of its last :data:`LOSS_WINDOW` steps more than :data:`LOSS_GROWTH`
    times its first step's (``losses[0]``, before any update) and above :data:`LOSS_FLOOR`.

    Raises:
        CollapseError: one line with both losses.
    """
    recent = losses[-LOSS_WINDOW:]
    mean = float(np.mean(recent))
    if mean > max(LOSS_GROWTH * losses[0], LOSS_FLOOR):
        raise CollapseError(f"adapt diverged {when}: the loss rose from {losses[0]:.3g} (its first step) to "
                            f"{mean:.3g} (the mean of its last {len(recent)} steps), more than {LOSS_GROWTH:g} times "
                            f"its first value; nothing was written; lower {param('lr')}")


def _batch_split(batch_size: int, source: bool) -> tuple[int, int]:
    """Frames per step from the user's frames and from the source frames: a quarter (at least one) from the
    source when there is one."""
    n_src = max(1, batch_size // 4) if source else 0
    return batch_size - n_src, n_src


def _guard(before: dict[str, float], now: dict[str, float], settings: AdaptSettings, when: str,
           view_share: float | None = None, fix: str | None = None) -> None:
    """Refuse a model that drifted to all road, no road or far from the published one (see the module).

    ``view_share``: the published model's road share of the held-out frames in the teacher's view
    (:func:`~freespace.data.photometry.normalise_light`), which the student learns: the share may rise to twice the
    larger of it and the share before (dusk frames, where the light normalisation finds the road the published
    model misses). ``fix``: what the message tells the user to change (default: the training's settings).

    Raises:
        CollapseError: one line that says what drifted, by how much, and what to change.
    """
    share, start = now["road_share"], before["road_share"]
    top = max(start, view_share or 0.0)
    fix = fix or f"nothing was written; lower {param('lr')} or {param('epochs')}, or raise {param('threshold')}"
    if share < MIN_ROAD_SHARE or share > MAX_ROAD_SHARE:
        raise CollapseError(f"adapt collapsed {when}: the model marks {share:.1%} of the held-out frames as road "
                            f"({'no road' if share < MIN_ROAD_SHARE else 'all road'}; {start:.1%} before); {fix}")
    if abs(share - start) > settings.max_drift:
        raise CollapseError(f"adapt drifted {when}: the road share of the held-out frames went from {start:.1%} to "
                            f"{share:.1%}, more than {param('max_drift')} {settings.max_drift:g}; {fix}")
    if not MIN_ROAD_RATIO * start <= share <= MAX_ROAD_RATIO * top:
        raise CollapseError(f"adapt drifted {when}: the road share of the held-out frames went from {start:.1%} to "
                            f"{share:.1%}, {'less than half' if share < start else 'more than twice'} the published "
                            f"model's{'' if share < start or top == start else f' ({top:.1%} in the teacher view)'}; "
                            f"{fix}")
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


def _view_share(data: _Data) -> float:
    """The road share (p ≥ 0.5) of the held-out frames in the teacher's view (``data.probs``, the light
    normalised)."""
    return float((data.probs[data.held] >= 0.5).mean())


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
          max_drift: float = AdaptSettings.max_drift, seed: int = AdaptSettings.seed,
          norm_stats: str = AdaptSettings.norm_stats, across_time: str = AdaptSettings.across_time,
          complete: bool = AdaptSettings.complete, release: float = AdaptSettings.release,
          release_far: float = AdaptSettings.release_far, look: tuple[float, float] | None = None,
          progress: bool = True, threads: int | None = None) -> dict[str, Any]:
    """Adapt the published model in the folder ``model`` to the unlabelled frames ``inputs``; write the
    adapted model folder ``out`` (see the module's docstring for the method and what is written).

    Every argument is checked before any work (type and bounds, :data:`BOUNDS`; None only where it says so).

    Args:
        model: a model folder holding :data:`CHECKPOINT` (``models/real-road-fast``).
        inputs: the user's frames: a folder, a glob or a video (any size from :data:`MIN_FRAME_SIDE` pixels a side:
            each is resized to the network's, as ``predict`` does). At least :data:`MIN_FRAMES` readable ones;
            unreadable ones are skipped and counted; more than :data:`~freespace.engine.adapt_io.MAX_FRAMES` (fewer
            for a model of many pixels, :data:`MAX_FRAME_BYTES`) are thinned to that many, evenly spread.
        out: the new model folder (not inside ``model`` nor equal to it, holding no input), written all or nothing.
        source: frames of the model's own training data to rehearse (its card names them), or None.
        epochs: rounds (passes over the frames; the teacher relabels them after each).
        minutes: a time limit for the training (None: none); the round it ends in is the last.
        threshold: a pixel is a label where the teacher's road probability is above it (road) or below
            1 − it (not road); in [0.5, 0.999].
        lr: the student's AdamW learning rate. batch_size: frames per step, 2…:data:`MAX_ADAPT_BATCH` and at most
            :data:`MAX_STEP_PIXELS` pixels of views (a quarter of them source frames with ``source``).
        ema: the teacher's decay per step (0: the teacher is the student). max_drift: the most the held-out
            frames' road share (a fraction) may move before the collapse guard stops the run; whatever it is, a
            share below half or above twice the published model's stops it too.
        seed: the frame order, hold-out and augmentation draws. norm_stats: the batch-norm statistics before the
            first round (AdaBN, :mod:`freespace.engine.norm_stats`): ``"auto"`` re-estimates them on the frames when
            the checkpoint holds a training run's and keeps them when they are folded into the convolutions
            (``models/real-road-unet``'s); ``"frames"`` re-estimates them (folded ones refused); ``"keep"`` keeps them.
        across_time, complete, release, release_far: each round's labels carried from the next frames (``"auto"``
            when the frames are a sequence, ``"on"``, ``"off"``), completed by appearance, and with ``release`` in
            (0, 1] also the confident not road within that share of the frame's height of the road, in the top
            ``release_far`` share of its rows (:func:`freespace.datagen.completion.released_seeds`).
        look: the lane ahead's columns (fractions of the width: ``(0.30, 0.55)`` driving on the right), or None:
            each round's road that does not look like it is don't care (:func:`_look_check`).
        threads: CPU threads, 1…:func:`~freespace.limits.max_workers` (None: the cores this process may use);
            ``progress``: a progress bar on a terminal (one line per round otherwise).

    Returns:
        The summary written to ``out/summary.json``: frames, settings, seconds, the held-out frames' road share and
        mean confidence before and after (``after_norm_stats``: right after the batch-norm statistics were
        re-estimated), what was done with those statistics (``norm_stats``: ``"re-estimated on N frames (K batch
        norms)"`` or ``"kept: …"`` and why), whether labels were carried along time (``across_time``: the setting,
        consecutive pairs and those with a road homography), the float16 export's check.

    Raises:
        InputFileError: no model folder or checkpoint; no frames or none readable. InvalidOptionError: an
        argument of another type or out of bounds, too few frames, frames too small, frames on which the published
        model is sure of nothing or finds no road, ``out`` inside or equal to ``model`` or among the inputs,
        ``norm_stats`` ``"frames"`` for a checkpoint whose batch norms are folded or absent.
        CorruptFileError: a damaged checkpoint (a bad image size, non-finite outputs) or video. CollapseError (a
        TrainingError, exit code 1): the collapse guard stopped the run; TrainingError: the loss became NaN.
    """
    from freespace.inference.predictor import load_checkpoint
    from freespace.io.outdir import claim_folder

    _check_arguments(model=model, input=inputs, out=out, source=source, progress=progress)
    threads = check_threads(threads)
    settings = AdaptSettings(epochs, minutes, threshold, lr, batch_size, ema, max_drift, seed, norm_stats,
                             across_time, complete, release, release_far, look).check()
    folder, ckpt = _model_folder(model)
    check_writable(out, folder=True)
    _check_overlap(folder, inputs, source, out)
    net, hp = load_checkpoint(ckpt)
    size = _checkpoint_size(hp, ckpt)
    kept = norm_stats_plan(net, settings.norm_stats, ckpt)
    _check_look_weights(settings)
    most = _check_memory(size, settings, folder)
    frames, src = _read_inputs(inputs, source, size, most)
    t0 = time.monotonic()
    with claim_folder(out, "adapt") as owned, owned.staged() as stage:
        run = _self_train(net, frames, src, settings, progress, threads, ckpt, kept)
        return write_model_folder(stage, run, hp, folder, frames, src, asdict(settings), time.monotonic() - t0,
                                  Path(out))


def _read_inputs(inputs: PathLike, source: PathLike | None, size: tuple[int, int], most: int
                 ) -> tuple[Frames, Frames | None]:
    """The user's frames and the source frames (or None), read at the network's ``size`` (``h, w``), at most
    ``most`` each.

    Raises:
        InvalidOptionError: fewer than :data:`MIN_FRAMES` readable frames of the user's.
    """
    frames = read_frames(inputs, size, "input", most)
    if len(frames.names) < MIN_FRAMES:
        raise InvalidOptionError(f"{param('input')} {inputs}: {len(frames.names)} readable frames ({frames.skipped} "
                                 f"unreadable); adapt needs at least {MIN_FRAMES}: give more frames of the camera")
    return frames, read_frames(source, size, "source", most) if source is not None else None


def _check_arguments(**paths: Any) -> None:
    """Refuse, naming the parameter, a path argument that is no path (None where one is needed, a number, an empty
    string; ``source`` may be None) and a ``progress`` that is no bool. ``inputs`` is named ``input``, as adapt's
    other messages name it.

    Raises:
        InvalidOptionError: one line naming the parameter and what it got.
    """
    progress = paths.pop("progress")
    if not isinstance(progress, bool):
        raise InvalidOptionError(f"{param('progress')} must be True or False, got {reprlib.repr(progress)}")
    for name, value in paths.items():
        if value is None and name == "source":
            continue
        path = os.fspath(value) if isinstance(value, (str, os.PathLike)) else None
        if not isinstance(path, str) or not path:
            got = "an empty path" if path == "" else reprlib.repr(value)
            raise InvalidOptionError(f"{param(name)} must be a path (str or pathlib.Path), got {got}")


def _check_overlap(folder: Path, inputs: PathLike, source: PathLike | None, out: PathLike) -> None:
    """Refuse an ``out`` that is, holds or lies inside an input: the model folder, the folders of the frames and
    each frame file itself (resolved: a frame that is a link into ``out`` is an input inside it), the video.

    Raises:
        InputFileError: no frames there (named by its parameter). InvalidOptionError: an overlap.
    """
    inputs_of: dict[str, PathLike | None] = {"model": folder}
    for name, spec in (("input", inputs), ("source", source)):
        if spec is not None:
            kind, paths = frame_paths(spec, name)
            places = [*sorted({p.parent for p in paths}), *paths] if kind == "images" else paths
            for i, p in enumerate(places):
                inputs_of[f"{name}[{i}]" if i else name] = p
    check_outputs({"out": out}, inputs_of)


def _checkpoint_size(hp: dict[str, Any], ckpt: Path) -> tuple[int, int]:
    """The image size ``(h, w)`` the checkpoint ``ckpt`` states (its ``hyper_parameters``' ``image_size``),
    checked: two integers in :data:`~freespace.engine.adapt_io.MIN_FRAME_SIDE`…``MAX_IMAGE_SIDE``.

    Raises:
        CorruptFileError: none, or not such a pair (one line naming the file).
    """
    size = hp.get("image_size")
    if size is None:
        raise CorruptFileError(f"{ckpt} states no training image size; adapt needs the size the model runs at")
    if hp.get("resize", "stretch") != "stretch":
        raise InvalidOptionError(f"{ckpt} was trained on letterboxed frames ({hp.get('resize')!r}); adapt fits "
                                 f"frames by stretching them to the model's size: adapt a model trained so")
    if not (isinstance(size, (list, tuple)) and len(size) == 2
            and all(isinstance(x, int) and not isinstance(x, bool) and MIN_FRAME_SIDE <= x <= MAX_IMAGE_SIDE
                    for x in size)):
        raise CorruptFileError(f"{ckpt} states an image size of {reprlib.repr(size)}; a freespace model's is [H, W] "
                               f"with {MIN_FRAME_SIDE}…{MAX_IMAGE_SIDE} pixels a side")
    return int(size[0]), int(size[1])


def _check_memory(size: tuple[int, int], settings: AdaptSettings, folder: Path) -> int:
    """The frames adapt keeps at most of each set for a model of ``size`` (:data:`MAX_FRAMES`, fewer when they
    would hold more than :data:`MAX_FRAME_BYTES`), after refusing a model or a batch whose views are more than
    :data:`MAX_STEP_PIXELS` pixels a step.

    Raises:
        InvalidOptionError: the model's size (naming ``model``) or ``batch_size`` is too large.
    """
    h, w = size
    if h * w > MAX_STEP_PIXELS:
        raise InvalidOptionError(f"{param('model')} {folder} runs at {h}×{w} pixels, more than adapt trains on a CPU "
                                 f"(at most {MAX_STEP_PIXELS} pixels: two views of half its width a step)")
    view = h * int(round(w * CROP_WIDTH))
    if settings.batch_size * view > MAX_STEP_PIXELS:
        raise InvalidOptionError(f"{param('batch_size')} {settings.batch_size}: views of {h}×{view // h} pixels are "
                                 f"at most {MAX_STEP_PIXELS // view} a step for this model (at most {MAX_STEP_PIXELS} "
                                 f"pixels a step)")
    per_pixel = 5 + (settings.look is not None)  # RGB and a float16 probability; the look check's mask
    return int(min(MAX_FRAMES, MAX_FRAME_BYTES // (per_pixel * h * w)))


def _self_train(net: Any, frames: Frames, src: Frames | None, settings: AdaptSettings, progress: bool,
                threads: int | None, checkpoint: Path, kept: str | None = None) -> dict[str, Any]:
    """The self-training loop (module docstring). Returns the adapted network (the teacher), one row per
    round, the held-out measures before and after (and right after the batch-norm statistics were re-estimated),
    what was done with those statistics (``norm_stats``), the held-out indices and their road probabilities before
    and after (``N×h×w float32``, the frames as they are). ``checkpoint``: the file ``net`` came from (named when
    it gives non-finite outputs). ``kept``: why the batch-norm statistics are kept
    (:func:`~freespace.engine.norm_stats.norm_stats_plan`), or None to re-estimate them first.

    Raises:
        InvalidOptionError, CorruptFileError: the frames or the checkpoint are refused before training
        (:func:`_check_teacher`). CollapseError: the guard stopped it. TrainingError: the loss became NaN.
    """
    import torch

    from freespace.inference.predictor import machine_threads

    threads = threads or machine_threads()
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return {**_rounds(net, frames, src, settings, progress, threads, checkpoint, kept), "threads": threads}
    finally:  # the caller's own setting back
        torch.set_num_threads(previous)


def _check_teacher(data: _Data, before: dict[str, float], held: np.ndarray, source: np.ndarray | None,
                   settings: AdaptSettings, checkpoint: Path) -> None:
    """Refuse, before training, what the published model's first labels say cannot be learnt: outputs that are not
    finite (the checkpoint), confident pixels on less than :data:`MIN_CONFIDENT_SHARE` of the frames' pixels, no
    road or nothing but road (the held-out share outside :data:`MIN_ROAD_SHARE`…:data:`MAX_ROAD_SHARE`, or no
    confident pixel of either class; "no road" in the frames as they are and in the teacher's view). ``held``,
    ``source``: its probabilities on the held-out and source frames.

    Raises:
        CorruptFileError: non-finite outputs. InvalidOptionError: what is wrong with the frames (``input``).
    """
    probs = data.probs
    if not (np.isfinite(probs).all() and np.isfinite(held).all()
            and (source is None or np.isfinite(source).all())):
        raise CorruptFileError(f"{checkpoint} gives non-finite outputs (NaN or infinity) on the frames: its weights "
                               f"are damaged or overflow; adapt a model that predicts (check it with freespace "
                               f"predict)")
    t = settings.threshold
    road, other = float((probs > t).mean()), float((probs < 1 - t).mean())
    raw, view = before["road_share"], _view_share(data)
    frames = f"the frames of {param('input')}"
    if road + other < MIN_CONFIDENT_SHARE:
        raise InvalidOptionError(f"the model is sure of no pixel of {frames} ({road + other:.2%} of them have a road "
                                 f"probability above {param('threshold')} {t:g} or below {1 - t:g}): nothing to "
                                 f"learn from; give frames of a road seen from a vehicle, like the model's own, or "
                                 f"lower {param('threshold')}")
    if max(raw, view) < MIN_ROAD_SHARE or road == 0:
        raise InvalidOptionError(f"the model finds no road on {frames} (road share {max(raw, view):.1%} of the "
                                 f"held-out frames, a confident road label on {road:.2%} of the pixels): adapt needs "
                                 f"frames in which it finds some road; give frames of a road seen from a vehicle")
    if raw > MAX_ROAD_SHARE or other == 0:
        raise InvalidOptionError(f"the model finds road nearly everywhere on {frames} (road share {raw:.1%} of the "
                                 f"held-out frames, a confident non-road label on {other:.2%} of the pixels): adapt "
                                 f"needs frames with road and more; give frames of a road seen from a vehicle")


def _rounds(net: Any, frames: Frames, src: Frames | None, settings: AdaptSettings, progress: bool,
            threads: int, checkpoint: Path, kept: str | None = None) -> dict[str, Any]:
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
    source_masks, p = None, None
    if data.source is not None:
        p = road_probabilities(session, data.source).astype(np.float32)
        data.source_labels, source_masks = pseudo_labels(p, settings.threshold), p >= 0.5
    before, held_before = _measure(session, data, source_masks)
    _check_teacher(data, before, held_before, p, settings, checkpoint)
    view_share = _view_share(data)
    tta = data.probs[data.held].astype(np.float32)  # the published model as predict runs it with tta
    before_tta = {"road_share": view_share, "confidence": float(np.maximum(tta, 1 - tta).mean())}
    norms = _norm_step(teacher, data, settings, kept, threads, source_masks, before, view_share)
    steps, across = plan_sequence(data.images, data.probs, settings.across_time)
    student = _student(teacher)
    opt = torch.optim.AdamW(student.parameters(), lr=settings.lr, weight_decay=0.0)
    per_step = _batch_split(settings.batch_size, src is not None)[0]
    bar = progress_bar(total=settings.epochs * math.ceil(len(train) / per_step), desc="adapt", unit="step",
                       enabled=progress)
    start = time.monotonic()
    deadline = start + settings.minutes * 60 if settings.minutes else math.inf
    rows, now, held_now, looks = [], before, held_before, None
    for r in range(1, settings.epochs + 1):
        confident = pseudo_labels(data.probs.astype(np.float32), settings.threshold)
        data.labels, carried = round_labels(data.images, data.probs, confident, steps, data.held, settings.complete,
                                            (settings.release, settings.release_far))
        if settings.look is not None:
            looks = _look_check(data, confident, looks, settings.look, carried)
        stats = _train_round(student, teacher, opt, data, settings, rng, deadline, bar, f"in round {r}")
        now, held_now = _measure(_teacher_session(teacher, size, threads), data, source_masks)
        rows.append({"round": r, **stats, **now, **carried, "seconds": round(time.monotonic() - start, 1)})
        log.info("adapt round %d/%d: loss %.4f, confident pixels %.1f%%, held-out road share %.1f%% (%.1f%% before)%s",
                 r, settings.epochs, stats["loss"], 100 * stats["confident"], 100 * now["road_share"],
                 100 * before["road_share"], ", time limit reached" if stats["stopped"] else "")
        if not (np.isfinite(held_now).all() and np.isfinite(data.probs).all()):
            raise CollapseError(f"adapt diverged in round {r}: the adapted model gives non-finite outputs (NaN or "
                                f"infinity); nothing was written; lower {param('lr')}")
        _guard(before, now, settings, f"in round {r}", view_share)
        if stats["stopped"]:
            break
    bar.close()
    return {"net": teacher, "rounds": rows, "before": before, "before_tta": before_tta, "after": now, "held": held,
            "held_probs": (held_before, held_now), "train_frames": len(train), "across_time": across, **norms,
            **({"look": looks[1]} if looks is not None else {})}


def _look_check(data: _Data, confident: np.ndarray, looks: tuple[np.ndarray, dict[str, Any]] | None,
                band: tuple[float, float], record: dict[str, float]) -> tuple[np.ndarray, dict[str, Any]]:
    """The round's labels (``data.labels``, or the ``confident`` ones) with the road that does not look like the
    road made don't care, in place (``data.labels`` then holds them); returns the look (``bool N×h×w`` and the
    classifier's row), learnt on the first round (``looks`` None) from the training frames' labels and kept
    (:func:`freespace.datagen.road_look.looks_like_road`: ImageNet features, the lane ahead against the not road).
    ``record`` gets ``vetoed``: the share of the training frames' pixels so made don't care."""
    from freespace.datagen.options import LookOptions
    from freespace.datagen.road_look import looks_like_road

    labels = data.labels if data.labels is not None else confident
    if looks is None:
        looks = looks_like_road(data.images, labels, data.train, LookOptions(band=band))
        log.info("adapt: the road's look learnt from %d frames (road cells right %.1f%%, not road %.1f%%)",
                 len(data.train), 100 * looks[1]["road_recall"], 100 * looks[1]["not_road_recall"])
    vetoed = (labels == 1) & ~looks[0]
    vetoed[data.held] = False
    labels[vetoed] = IGNORE
    data.labels = labels
    record["vetoed"] = round(float(vetoed.sum()) / max(labels[data.train].size, 1), 4)
    return looks


def _norm_step(net: Any, data: _Data, settings: AdaptSettings, kept: str | None, threads: int,
               source_masks: np.ndarray | None, before: dict[str, float], view_share: float) -> dict[str, Any]:
    """AdaBN before the first round (the module's docstring): ``net``'s batch-norm statistics re-estimated in place
    on up to :data:`~freespace.engine.norm_stats.MAX_NORM_FRAMES` training frames, evenly spread, as they are; then
    the frames relabelled by it (``data.probs``) and the held-out frames measured (:func:`_measure`) and guarded
    against ``before`` as a round is (:func:`_guard`). With ``kept`` (why they are kept) nothing changes.

    Returns:
        ``{"norm_stats": what was done}`` (``"re-estimated on N frames (K batch norms)"`` or ``kept``), and when they
        were re-estimated ``"after_norm_stats"``: the held-out measures then (road share, confidence, source
        agreement), as :func:`_measure` gives them.

    Raises:
        CollapseError: the re-estimated network gives non-finite outputs, or the guard stops it (the message says to
        keep the statistics: ``norm_stats`` keep).
    """
    from freespace.engine.adapt_io import thin
    from freespace.engine.norm_stats import MAX_NORM_FRAMES, batch_norms

    if kept is not None:
        log.info("adapt: batch-norm statistics %s", kept)
        return {"norm_stats": kept}
    pick = data.train[thin(len(data.train), MAX_NORM_FRAMES)]
    n = reestimate_norm_stats(net, data.images[pick])
    note = f"re-estimated on {n} frames ({len(batch_norms(net))} batch norms)"
    now, held = _measure(_teacher_session(net, data.images.shape[1:3], threads), data, source_masks)
    fix = f"nothing was written; keep the checkpoint's statistics with {param('norm_stats')} keep"
    when = "after re-estimating the batch-norm statistics"
    if not (np.isfinite(held).all() and np.isfinite(data.probs).all()):
        raise CollapseError(f"adapt diverged {when}: the model gives non-finite outputs (NaN or infinity); {fix}")
    _guard(before, now, settings, when, view_share, fix)
    log.info("adapt: batch-norm statistics %s: held-out road share %.1f%% (%.1f%% before)", note,
             100 * now["road_share"], 100 * before["road_share"])
    return {"norm_stats": note, "after_norm_stats": now}
