"""U-Net (Ronneberger et al.) and DeepLabv3+ (Chen et al.) from segmentation-models-pytorch.

Thin wrappers: the smp model does the work; ours adds the input normalisation and padding of
:class:`~freespace.models.base.SegmentationModel` (the benchmark checks there is no other overhead).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from freespace.errors import FreespaceError, InvalidOptionError
from freespace.models.base import SegmentationModel, register_model

__all__ = ["SmpModel"]

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "unet": {"light": {"encoder_name": "resnet18", "decoder_channels": (128, 64, 32, 16, 16)},
             "paper": {"encoder_name": "resnet34", "decoder_channels": (256, 128, 64, 32, 16)}},
    "deeplabv3plus": {"light": {"encoder_name": "resnet18", "decoder_channels": 128, "encoder_output_stride": 16},
                      "paper": {"encoder_name": "resnet101", "decoder_channels": 256, "encoder_output_stride": 16}},
}


class SmpModel(SegmentationModel):
    """A segmentation-models-pytorch network behind the common interface (``self.net``)."""

    def __init__(self, net: nn.Module, num_classes: int) -> None:
        super().__init__(num_classes)
        self.net = net

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def _build(arch: str, num_classes: int, preset: str, encoder_weights: str | None, **options: Any) -> SmpModel:
    import segmentation_models_pytorch as smp

    if preset not in PRESETS[arch]:
        raise InvalidOptionError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS[arch])}")
    kwargs = {**PRESETS[arch][preset], **options}
    cls = {"unet": smp.Unet, "deeplabv3plus": smp.DeepLabV3Plus}[arch]
    try:
        net = cls(encoder_weights=encoder_weights, classes=num_classes, **kwargs)
    except (KeyError, ValueError) as exc:
        raise InvalidOptionError(f"bad {arch} option: {exc}") from None
    except Exception as exc:  # weight download without a network
        if encoder_weights is None:
            raise
        raise FreespaceError(f"cannot load {encoder_weights!r} encoder weights ({type(exc).__name__}); this needs "
                             f"the network — use encoder_weights=None") from None
    return SmpModel(net, num_classes)


@register_model("unet")
def unet(num_classes: int = 2, preset: str = "light", encoder_weights: str | None = None, **options: Any) -> SmpModel:
    """U-Net (smp). ``light``: ResNet-18 encoder, narrow decoder; ``paper``: ResNet-34, 256–16 decoder."""
    return _build("unet", num_classes, preset, encoder_weights, **options)


@register_model("deeplabv3plus")
def deeplabv3plus(num_classes: int = 2, preset: str = "light", encoder_weights: str | None = None,
                  **options: Any) -> SmpModel:
    """DeepLabv3+ (smp), output stride 16. ``light``: ResNet-18, 128 channels; ``paper``: ResNet-101, 256."""
    return _build("deeplabv3plus", num_classes, preset, encoder_weights, **options)
