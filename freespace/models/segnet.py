"""SegNet (Badrinarayanan et al., TPAMI 2017).

The encoder is VGG16-BN's 13 convolutions in five blocks; each block ends in a 2×2 max pooling whose
indices are kept, and the mirrored decoder upsamples with those indices (max unpooling) before its
convolutions, so boundaries come back where the encoder found them. ``width`` scales the channel counts
(1.0 = the paper's 64–512; the light default 0.25 trains on a CPU).

``class_balance="median_freq"`` weights the cross-entropy as the paper does (median frequency
balancing, Eigen & Fergus): class c gets ``median(f) / f_c``, where ``f_c`` is the number of pixels
of class c divided by the number of pixels of the training images that contain c. The weights are
computed from the training labels by :meth:`SegNet.prepare` and kept in the ``class_weights`` buffer
(so they come back with a checkpoint).
"""

from __future__ import annotations

from collections.abc import Iterable

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import IGNORE_INDEX, Outputs, SegmentationModel, load_smp_encoder, main_logits
from freespace.models.blocks import ConvBNReLU
from freespace.models.registry import register_model

__all__ = ["SegNet", "median_frequency_weights", "CLASS_BALANCE"]

CLASS_BALANCE = (None, "median_freq")

VGG16_BLOCKS = ((64, 2), (128, 2), (256, 3), (512, 3), (512, 3))  # (channels, convolutions)


def median_frequency_weights(labels: Iterable[torch.Tensor], num_classes: int,
                             ignore_index: int = IGNORE_INDEX) -> torch.Tensor:
    """Median frequency balancing: ``C`` float32 weights ``median(f) / f_c`` with ``f_c`` = pixels of class
    c / pixels of the images (don't-care excluded) in which c appears. ``labels``: ``H×W`` or ``N×H×W``
    int64 class maps. A class that never appears gets weight 1."""
    pixels = torch.zeros(num_classes, dtype=torch.float64)
    present = torch.zeros(num_classes, dtype=torch.float64)
    for t in labels:
        for image in (t.unsqueeze(0) if t.dim() == 2 else t):
            valid = image[image != ignore_index].long()
            counts = torch.bincount(valid, minlength=num_classes)[:num_classes].double()
            pixels += counts
            present += (counts > 0).double() * valid.numel()
    seen = present > 0
    if not seen.any():
        raise InvalidOptionError("median frequency balancing needs labels with at least one valid pixel")
    freq = pixels[seen] / present[seen]
    weights = torch.ones(num_classes, dtype=torch.float64)
    weights[seen] = torch.quantile(freq, 0.5) / freq  # the middle value; the mean of the two middle ones
    return weights.float()


def _unpool(x: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """2×2 max unpooling: each value goes back to where its pooling window's maximum was (the same as
    ``F.max_unpool2d``, written as a scatter so that it traces and exports with dynamic sizes)."""
    out = torch.zeros_like(x).repeat(1, 1, 2, 2)
    return out.flatten(2).scatter(2, indices.flatten(2), x.flatten(2)).view_as(out)


class SegNet(SegmentationModel):
    """SegNet with a VGG16-BN encoder and a mirrored decoder that unpools with the pooling indices."""

    def __init__(self, num_classes: int = 2, width: float = 0.25, encoder_weights: str | None = None,
                 class_balance: str | None = None) -> None:
        super().__init__(num_classes)
        if not 0 < width <= 2:
            raise InvalidOptionError(f"width must be in (0, 2], got {width}")
        if class_balance not in CLASS_BALANCE:
            raise InvalidOptionError(f"class_balance must be one of {', '.join(map(str, CLASS_BALANCE))}, "
                                     f"got {class_balance!r}")
        self.class_balance = class_balance
        # saved only when used: checkpoints of unbalanced SegNets keep their keys
        self.register_buffer("class_weights", torch.ones(num_classes), persistent=class_balance is not None)
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

    @torch.no_grad()
    def prepare(self, train_labels: Iterable[torch.Tensor]) -> None:
        """With ``class_balance="median_freq"``, set ``class_weights`` from the training labels."""
        if self.class_balance == "median_freq":
            self.class_weights.copy_(median_frequency_weights(train_labels, self.num_classes))

    def loss(self, outputs: Outputs, target: torch.Tensor, ignore_index: int = IGNORE_INDEX) -> dict[str, torch.Tensor]:
        """Cross-entropy, weighted by ``class_weights`` (all 1 unless median frequency balancing is on)."""
        if self.class_balance is None:
            return super().loss(outputs, target, ignore_index)
        seg = F.cross_entropy(main_logits(outputs), target, weight=self.class_weights, ignore_index=ignore_index)
        return {"total": seg, "seg": seg}

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        indices = []  # the input is padded to a multiple of 32: every pooling halves exactly
        for block in self.encoder:
            x, idx = F.max_pool2d(block(x), 2, 2, return_indices=True)
            indices.append(idx)
        for block in self.decoder:
            x = block(_unpool(x, indices.pop()))
        return self.classifier(x)


@register_model("segnet", {"light": {"width": 0.25}, "paper": {"width": 1.0}}, geometry=lambda o: (16, 1))
def segnet(num_classes: int = 2, width: float = 0.25, encoder_weights: str | None = None,
           class_balance: str | None = None) -> SegNet:
    """SegNet; ``preset="paper"`` is full-width VGG16-BN (29.5 M parameters; ``encoder_weights="imagenet"``
    loads smp's VGG16-BN), ``light`` a quarter width. ``class_balance="median_freq"``: the paper's loss.
    (Geometry: the deepest 3×3 convolutions, block 5, run at output stride 16.)"""
    return SegNet(num_classes, width=width, encoder_weights=encoder_weights, class_balance=class_balance)
