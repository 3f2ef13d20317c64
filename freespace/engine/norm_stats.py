"""Adapt's first step: a network's batch-norm statistics re-estimated on the user's frames (AdaBN).

A batch norm normalises each channel with the running mean and variance it saw in training; on another camera the
activations have other statistics. AdaBN (Li et al. 2016, *Revisiting Batch Normalization For Practical Domain
Adaptation*) replaces them with the target frames' own: every batch norm's running statistics are reset and
estimated again as a cumulative average (``momentum=None``) over forward passes on the frames, the batch norms in
training mode and everything else as it runs (eval: no dropout, no auxiliary head), without a gradient; nothing else
of the network changes. It needs no label and takes seconds.

It only makes sense where the batch norms hold the statistics the network was trained with. A checkpoint rebuilt
from an ONNX file (:func:`freespace.engine.adapt_io.checkpoint_from_onnx`; ``models/real-road-unet``'s, and
``models/real-road-fast``'s before its rebuild) has each batch norm folded into the convolution before it by the
export: the batch norms are the identity (running mean 0, running variance 1) and the statistics live inside the
convolutions' weights. Statistics estimated there would
normalise activations a second time: such a checkpoint is detected (:func:`folded_norms`) and kept
(:func:`norm_stats_plan`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from freespace.errors import InvalidOptionError, check_choice, param

__all__ = ["NORM_STATS", "MAX_NORM_FRAMES", "NORM_BATCH", "NORM_BATCH_PIXELS", "batch_norms", "folded_norms",
           "check_norm_stats", "norm_stats_plan", "reestimate_norm_stats"]

#: the values of adapt's ``norm_stats``: ``auto`` re-estimates when the checkpoint holds real statistics and keeps
#: folded ones, ``frames`` re-estimates (a checkpoint with folded statistics is refused), ``keep`` keeps them
NORM_STATS = ("auto", "frames", "keep")
#: frames the statistics are estimated on at most (evenly spread among more): 200 frames give each channel's mean
#: over tens of millions of pixels
MAX_NORM_FRAMES = 200
#: frames a forward pass at most, and pixels (frames × the model's height × width) a pass at most: 8 frames of a
#: 192×640 model, 2 of a 384×1248 one (never fewer than 2: a batch norm after a global pooling needs two values)
NORM_BATCH, NORM_BATCH_PIXELS = 8, 2**20


def batch_norms(net: Any) -> list[tuple[str, Any]]:
    """``(name, module)`` of every batch norm of ``net`` (a ``torch.nn.Module``) that keeps running statistics, in
    the network's order."""
    import torch

    return [(name, m) for name, m in net.named_modules()
            if isinstance(m, torch.nn.modules.batchnorm._BatchNorm) and m.track_running_stats
            and m.running_mean is not None and m.running_var is not None]


def folded_norms(net: Any) -> list[str]:
    """The names of ``net``'s batch norms whose running statistics are the identity — every channel's running mean
    exactly 0 and running variance exactly 1 —: folded into the convolution before them by an export (what
    :func:`~freespace.engine.adapt_io.checkpoint_from_onnx` rebuilds), or never trained. A trained batch norm's
    statistics are never exactly these."""
    import torch

    return [name for name, m in batch_norms(net)
            if bool(torch.all(m.running_mean == 0)) and bool(torch.all(m.running_var == 1))]


def check_norm_stats(value: Any) -> str:
    """``value`` if it is one of :data:`NORM_STATS`, else :class:`~freespace.errors.InvalidOptionError` naming
    ``norm_stats``."""
    return check_choice(value, NORM_STATS, "norm_stats")


def norm_stats_plan(net: Any, setting: str, checkpoint: Any = None) -> str | None:
    """What adapt does with ``net``'s batch-norm statistics under ``setting`` (one of :data:`NORM_STATS`): None to
    re-estimate them on the frames, else why they are kept, as the run's record says it (``"kept: …"``).

    ``auto`` re-estimates unless a batch norm holds folded statistics (:func:`folded_norms`) or there is none;
    ``keep`` keeps them; ``frames`` re-estimates, and refuses a network where that would be wrong. ``checkpoint``:
    the file ``net`` came from, named in the message.

    Raises:
        InvalidOptionError: ``setting`` is none of :data:`NORM_STATS`; ``frames`` and the network has no batch norm
            or folded ones (one line naming ``norm_stats``).
    """
    if check_norm_stats(setting) == "keep":
        return "kept: as asked (norm_stats keep)"
    norms, folded = batch_norms(net), folded_norms(net)
    where = f"{checkpoint}" if checkpoint is not None else "the network"
    if not norms:
        reason = "kept: the network has no batch norm"
        if setting == "frames":
            raise InvalidOptionError(f"{param('norm_stats')} frames: {where} has no batch norm whose statistics could "
                                     f"be re-estimated; use auto or keep")
        return reason
    if folded:
        if setting == "frames":
            raise InvalidOptionError(
                f"{param('norm_stats')} frames: {where} has its batch norms folded into the convolutions "
                f"({len(folded)} of {len(norms)} hold running mean 0 and variance 1, as an ONNX export leaves them): "
                f"statistics estimated there would normalise twice; use auto or keep, or adapt a checkpoint of a "
                f"training run")
        return (f"kept: folded into the convolutions ({len(folded)} of {len(norms)} batch norms hold running mean 0 "
                f"and variance 1)")
    return None


def reestimate_norm_stats(net: Any, images: np.ndarray, most: int = MAX_NORM_FRAMES,
                          normalise: bool = False) -> int:
    """Re-estimate every batch norm's running mean and variance of ``net`` in place on ``images`` (AdaBN; see the
    module). Returns the number of frames used.

    Each batch norm's statistics are reset, then accumulated as a cumulative average (``momentum=None``: the mean of
    the batches' means and unbiased variances) over forward passes without a gradient, the batch norms in training
    mode and the rest of the network in eval mode; afterwards every module's mode and every batch norm's momentum are
    as they were. At most ``most`` frames, evenly spread (:func:`~freespace.engine.adapt_io.thin`), are used, in
    batches of nearly equal size (at most :data:`NORM_BATCH` frames and :data:`NORM_BATCH_PIXELS` pixels, at least 2:
    one frame more where an odd count of a large model's frames leaves no other split), so that every frame weighs
    about the same.

    Args:
        net: a freespace network (its input ``N×3×h×w`` float32 RGB in [0, 1]; it normalises inside).
        images: ``N×h×w×3 uint8`` RGB frames at the network's input size, as adapt keeps them (``N ≥ 2``).
        most: frames used at most (≥ 2). normalise: see each frame as adapt's teacher labels it
            (:func:`~freespace.data.photometry.normalise_light`) instead of as it is.

    Raises:
        InvalidOptionError: fewer than 2 frames, or not ``N×h×w×3 uint8``.
    """
    import torch

    from freespace.data.photometry import normalise_light
    from freespace.engine.adapt_io import thin

    if not (isinstance(images, np.ndarray) and images.ndim == 4 and images.shape[3] == 3
            and images.dtype == np.uint8 and len(images) >= 2 and most >= 2):
        raise InvalidOptionError(f"re-estimating batch-norm statistics needs at least 2 frames N×h×w×3 uint8 (and "
                                 f"most ≥ 2), got {getattr(images, 'shape', type(images).__name__)}")
    norms = [m for _, m in batch_norms(net)]
    pick = thin(len(images), most)
    per = max(2, min(NORM_BATCH, NORM_BATCH_PIXELS // (images.shape[1] * images.shape[2])))
    modes = {m: m.training for m in net.modules()}
    momenta = [m.momentum for m in norms]
    net.eval()
    try:
        for m in norms:
            m.reset_running_stats()
            m.momentum = None
            m.train()
        with torch.no_grad():
            for idx in np.array_split(pick, max(1, min(math.ceil(len(pick) / per), len(pick) // 2))):
                chunk = images[idx]
                if normalise:
                    chunk = np.stack([normalise_light(image) for image in chunk])
                net(torch.from_numpy(np.ascontiguousarray(chunk.transpose(0, 3, 1, 2))).float().div_(255.0))
    finally:
        for m, momentum in zip(norms, momenta):
            m.momentum = momentum
        for m, training in modes.items():
            m.training = training
    return len(pick)
