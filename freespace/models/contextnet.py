"""ContextNet with an ImageNet encoder (Poudel, Bonde, Liwicki and Zach, "ContextNet: Exploring Context and
Detail for Semantic Segmentation in Real-time", BMVC 2018): a deep branch that sees the frame at a reduced
resolution for context, and a shallow branch that sees it at full resolution for detail, fused at stride 8.

Design:

- **Detail branch** (the full input, stride 8): a 3×3 stride-2 convolution, then two depthwise-separable
  stride-2 convolutions (16, 24, 32 channels at ``width`` 0.5; Fast-SCNN's *learning to downsample*, where the
  paper's shallow branch has one more depthwise-separable convolution).
- **Context branch** (the input resized by ``context_scale``): EfficientNet-Lite0 down to stride 32 of its own
  input (:class:`~freespace.models.lite.LiteEncoder`, ImageNet weights shipped by ``freespace[pretrained]``),
  LR-ASPP's global-context gating on its last map (:class:`~freespace.models.fastscnn._GlobalContext`), added,
  upsampled, to a 1×1 convolution of its stride-16 map.
- **Feature fusion and classifier**, as the paper's: the context features upsampled to the detail branch's
  grid, a depthwise 3×3 and a 1×1 convolution, added to a 1×1 convolution of the detail features, ReLU; two
  depthwise-separable convolutions, dropout, a 1×1 convolution to the classes, upsampled ×8 bilinearly.

Departures from the paper: its deep branch is MobileNetV2 bottlenecks trained from scratch on the deepest map
alone; here it is the ImageNet Lite0 encoder with its stride-16 map and a global context. The paper's
``context_scale`` is 1/4 (the ``paper`` preset); the default here is 1/2. An ImageNet start is what a
from-scratch fast network lacks on a few hundred training frames, and the shallow branch keeps the road's edges
at the full input's resolution, which a whole network at a reduced size loses. The input is padded to a
multiple of ``32 / context_scale`` (64 at 1/2), so the resized frame is a multiple of 32.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import SegmentationModel, load_smp_encoder
from freespace.models.blocks import upsample_to
from freespace.models.fastscnn import _bn_relu, _DSConv, _fusion, _GlobalContext
from freespace.models.registry import register_model

__all__ = ["ContextNet"]


class ContextNet(SegmentationModel):
    """ContextNet with a Lite0 context branch (see the module's docstring for the design and its departures).

    Args:
        num_classes: output classes.
        context_scale: the context branch's input size as a fraction of the input (1/2 or 1/4).
        width: scales the detail branch and the head (0.5: 16, 24, 32 channels in the detail branch, 64
            after the fusion).
        encoder_name: the context branch's encoder, an EfficientNet-Lite (``efficientnet-lite0`` … ``-lite4``).
        encoder_weights: None (random), ``"imagenet"`` or a state-dict file, as for the other networks.
    """

    def __init__(self, num_classes: int = 2, context_scale: float = 0.5, width: float = 0.5,
                 encoder_name: str = "efficientnet-lite0", encoder_weights: str | None = None) -> None:
        super().__init__(num_classes)
        if context_scale not in (0.5, 0.25):
            raise InvalidOptionError(f"context_scale must be 0.5 or 0.25, got {context_scale}")
        if not 0.25 <= width <= 2:
            raise InvalidOptionError(f"width must be in [0.25, 2], got {width}")
        if not encoder_name.startswith("efficientnet-lite"):
            raise InvalidOptionError(f"contextnet's context branch is an EfficientNet-Lite encoder "
                                     f"(efficientnet-lite0 … -lite4), got {encoder_name!r}")
        self.context_scale = context_scale
        self.divisor = int(32 / context_scale)

        def ch(c: int) -> int:
            return max(8, int(round(c * width / 8)) * 8)

        c32, c48, c64, c128 = ch(32), ch(48), ch(64), ch(128)
        self.detail = nn.Sequential(nn.Conv2d(3, c32, 3, 2, 1, bias=False), *_bn_relu(c32),
                                    _DSConv(c32, c48, 2), _DSConv(c48, c64, 2))
        self.encoder = load_smp_encoder(encoder_name, encoder_weights, depth=5)
        self.normalise_for(self.encoder)
        f16, f32 = self.encoder.out_channels[-2:]
        self.context = _GlobalContext(f32, c128)
        self.lateral = nn.Sequential(nn.Conv2d(f16, c128, 1, bias=False), nn.BatchNorm2d(c128))
        self.fuse_low, self.fuse_high, self.classifier = _fusion(c64, c128, num_classes)

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        high = self.detail(x)
        small = F.interpolate(x, scale_factor=self.context_scale, mode="bilinear", align_corners=False,
                              antialias=False)
        *_, f16, f32 = self.encoder(small)
        low = upsample_to(self.context(f32), f16) + self.lateral(f16)
        fused = F.relu(self.fuse_low(upsample_to(low, high)) + self.fuse_high(high))
        return upsample_to(self.classifier(fused), x)


@register_model("contextnet", {"light": {"context_scale": 0.5}, "paper": {"context_scale": 0.25}},
                geometry=lambda o: (int(32 / o["context_scale"]), 1))
def contextnet(num_classes: int = 2, context_scale: float = 0.5, width: float = 0.5,
               encoder_name: str = "efficientnet-lite0", encoder_weights: str | None = None) -> ContextNet:
    """ContextNet (Poudel et al., BMVC 2018) with an EfficientNet-Lite0 context branch, built for speed with an
    ImageNet start. ``light``: context at 1/2 of the input; ``paper``: at 1/4, as the paper."""
    return ContextNet(num_classes, context_scale=context_scale, width=width, encoder_name=encoder_name,
                      encoder_weights=encoder_weights)
