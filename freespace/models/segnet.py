"""SegNet (Badrinarayanan et al., TPAMI 2017).

The encoder is VGG16-BN's 13 convolutions in five blocks; each block ends in a 2×2 max pooling whose
indices are kept, and the mirrored decoder upsamples with those indices (max unpooling) before its
convolutions, so boundaries come back where the encoder found them. ``width`` scales the channel counts
(1.0 = the paper's 64–512; the light default 0.25 trains on a CPU).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import SegmentationModel, load_smp_encoder, register_model
from freespace.models.blocks import ConvBNReLU

__all__ = ["SegNet"]

VGG16_BLOCKS = ((64, 2), (128, 2), (256, 3), (512, 3), (512, 3))  # (channels, convolutions)


def _unpool(x: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """2×2 max unpooling: each value goes back to where its pooling window's maximum was (the same as
    ``F.max_unpool2d``, written as a scatter so that it traces and exports with dynamic sizes)."""
    out = torch.zeros_like(x).repeat(1, 1, 2, 2)
    return out.flatten(2).scatter(2, indices.flatten(2), x.flatten(2)).view_as(out)


class SegNet(SegmentationModel):
    """SegNet with a VGG16-BN encoder and a mirrored decoder that unpools with the pooling indices."""

    def __init__(self, num_classes: int = 2, width: float = 0.25, encoder_weights: str | None = None) -> None:
        super().__init__(num_classes)
        if not 0 < width <= 2:
            raise InvalidOptionError(f"width must be in (0, 2], got {width}")
        if encoder_weights is not None and width != 1.0:
            raise InvalidOptionError("pretrained VGG16-BN weights need the full-width encoder (preset='paper')")
        chans = [max(8, int(round(c * width))) for c, _ in VGG16_BLOCKS]
        self.encoder = nn.ModuleList()
        cin = 3
        for (_, n), c in zip(VGG16_BLOCKS, chans):
            self.encoder.append(nn.Sequential(*[ConvBNReLU(cin if i == 0 else c, c) for i in range(n)]))
            cin = c
        # decoder block k mirrors encoder block 4 − k: n convolutions, the last one to the previous width
        self.decoder = nn.ModuleList()
        outs = chans[::-1][1:] + [chans[0]]
        for (_, n), c, cout in zip(VGG16_BLOCKS[::-1], chans[::-1], outs):
            self.decoder.append(nn.Sequential(*[ConvBNReLU(c, c if i < n - 1 else cout) for i in range(n)]))
        self.classifier = nn.Conv2d(chans[0], num_classes, 3, padding=1)
        if encoder_weights is not None:
            self._load_vgg(load_smp_encoder("vgg16_bn", encoder_weights))

    def _load_vgg(self, vgg: nn.Module) -> None:
        """Copy a VGG16-BN's 13 convolution + batch-norm pairs, in order, into the encoder."""
        convs = [m for m in vgg.modules() if isinstance(m, (nn.Conv2d, nn.BatchNorm2d))]
        ours = [m for block in self.encoder for m in block.modules() if isinstance(m, (nn.Conv2d, nn.BatchNorm2d))]
        if len(convs) != len(ours):
            raise InvalidOptionError(f"expected a VGG16-BN encoder with {len(ours)} conv/bn layers, got {len(convs)}")
        bias = None
        for src, dst in zip(convs, ours):
            state = {k: v.clone() for k, v in src.state_dict().items() if k in dst.state_dict()}
            if isinstance(src, nn.Conv2d):
                bias = src.bias  # ours have none: batch norm follows, so the bias moves into its running mean
            elif bias is not None:
                state["running_mean"] = state["running_mean"] - bias.detach()
            dst.load_state_dict(state)

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        indices = []  # the input is padded to a multiple of 32: every pooling halves exactly
        for block in self.encoder:
            x, idx = F.max_pool2d(block(x), 2, 2, return_indices=True)
            indices.append(idx)
        for block in self.decoder:
            x = block(_unpool(x, indices.pop()))
        return self.classifier(x)


@register_model("segnet")
def segnet(num_classes: int = 2, preset: str = "light", width: float | None = None,
           encoder_weights: str | None = None) -> SegNet:
    """SegNet; ``preset="paper"`` is full-width VGG16-BN (29.5 M parameters; ``encoder_weights="imagenet"``
    loads smp's VGG16-BN), ``light`` a quarter width."""
    presets = {"light": 0.25, "paper": 1.0}
    if preset not in presets:
        raise InvalidOptionError(f"unknown preset {preset!r}; choose one of {', '.join(presets)}")
    return SegNet(num_classes, width=width if width is not None else presets[preset], encoder_weights=encoder_weights)
