"""U-Net (Ronneberger et al.) and DeepLabv3+ (Chen et al.) from segmentation-models-pytorch.

Thin wrappers: the smp model does the work; ours adds the input normalisation and padding of
:class:`~freespace.models.base.SegmentationModel` (the benchmark checks there is no other overhead).
DeepLabv3+'s ASPP rates follow its output stride as in the paper: 6, 12, 18 at output stride 16 and
twice that, 12, 24, 36, at output stride 8 (smp's default keeps 12, 24, 36 at stride 16).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from freespace.errors import FreespaceError, InvalidOptionError
from freespace.models.base import SegmentationModel, network_error
from freespace.models.registry import register_model

__all__ = ["SmpModel", "PRESETS", "aspp_rates"]

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "unet": {"light": {"encoder_name": "resnet18", "decoder_channels": (128, 64, 32, 16, 16)},
             "paper": {"encoder_name": "resnet34", "decoder_channels": (256, 128, 64, 32, 16)}},
    "deeplabv3plus": {"light": {"encoder_name": "resnet18", "decoder_channels": 128, "encoder_output_stride": 16},
                      "paper": {"encoder_name": "resnet101", "decoder_channels": 256, "encoder_output_stride": 16}},
}


def aspp_rates(output_stride: int) -> tuple[int, int, int]:
    """DeepLab's ASPP rates for an encoder output stride: ``(6, 12, 18)`` at 16, ``(12, 24, 36)`` at 8
    (the rates scale with the feature map, so each branch sees the same image context)."""
    if output_stride not in (8, 16):
        raise InvalidOptionError(f"DeepLabv3+ output stride must be 8 or 16, got {output_stride}")
    return (6, 12, 18) if output_stride == 16 else (12, 24, 36)


class SmpModel(SegmentationModel):
    """A segmentation-models-pytorch network behind the common interface (``self.net``)."""

    def __init__(self, net: nn.Module, num_classes: int) -> None:
        super().__init__(num_classes)
        self.net = net

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def smp_kwargs(arch: str, options: dict[str, Any]) -> dict[str, Any]:
    """The keyword arguments of the smp constructor for our options (DeepLabv3+: rates from the stride)."""
    kwargs = dict(options)
    if arch == "deeplabv3plus" and kwargs.get("decoder_atrous_rates") is None:
        kwargs["decoder_atrous_rates"] = aspp_rates(kwargs.get("encoder_output_stride", 16))
    return kwargs


def _build(arch: str, num_classes: int, encoder_weights: str | None, **options: Any) -> SmpModel:
    import segmentation_models_pytorch as smp

    from freespace.models.weights import hub_offline, load_encoder_weights, smp_weights

    cls = {"unet": smp.Unet, "deeplabv3plus": smp.DeepLabV3Plus}[arch]
    downloaded = smp_weights(options["encoder_name"], encoder_weights)
    try:
        with hub_offline():  # no network at run time: the hub's cache, else a one-line error at once
            net = cls(encoder_weights=downloaded, classes=num_classes, **smp_kwargs(arch, options))
    except FreespaceError:
        raise
    except (KeyError, ValueError, TypeError) as exc:
        raise InvalidOptionError(f"bad {arch} option: {exc}") from None
    except Exception as exc:  # weight download without a network
        if encoder_weights is None:
            raise
        raise network_error(options["encoder_name"], encoder_weights, exc) from None
    if encoder_weights is not None and downloaded is None:
        load_encoder_weights(net.encoder, options["encoder_name"], encoder_weights)
    model = SmpModel(net, num_classes)
    model.normalise_for(net.encoder)
    return model


@register_model("unet", PRESETS["unet"], geometry=lambda o: (32, 1))
def unet(num_classes: int = 2, encoder_name: str = "resnet18",
         decoder_channels: tuple[int, ...] = (128, 64, 32, 16, 16), encoder_weights: str | None = None) -> SmpModel:
    """U-Net (smp). ``light``: ResNet-18 encoder, narrow decoder; ``paper``: ResNet-34, 256–16 decoder."""
    return _build("unet", num_classes, encoder_weights, encoder_name=encoder_name, decoder_channels=decoder_channels)


@register_model("deeplabv3plus", PRESETS["deeplabv3plus"],
                geometry=lambda o: (o["encoder_output_stride"],
                                    max(o.get("decoder_atrous_rates") or aspp_rates(o["encoder_output_stride"]))))
def deeplabv3plus(num_classes: int = 2, encoder_name: str = "resnet18", decoder_channels: int = 128,
                  encoder_output_stride: int = 16, decoder_atrous_rates: tuple[int, int, int] | None = None,
                  encoder_weights: str | None = None) -> SmpModel:
    """DeepLabv3+ (smp). ``light``: ResNet-18, 128 channels; ``paper``: ResNet-101, 256; both at output
    stride 16, ASPP rates from the stride (:func:`aspp_rates`) unless ``decoder_atrous_rates`` is given."""
    return _build("deeplabv3plus", num_classes, encoder_weights, encoder_name=encoder_name,
                  decoder_channels=decoder_channels, encoder_output_stride=encoder_output_stride,
                  decoder_atrous_rates=decoder_atrous_rates)
