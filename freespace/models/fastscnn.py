"""Fast-SCNN (Poudel, Liwicki and Cipolla, "Fast-SCNN: Fast Semantic Segmentation Network", BMVC 2019): a
two-branch network built for speed, the fast model of real-time prediction on a CPU.

Design, as in the paper:

- **Learning to downsample** (stride 8): a 3×3 stride-2 convolution, then two depthwise-separable stride-2
  convolutions (32, 48, 64 channels at ``width`` 1). Its output is both the high-resolution branch and
  the input of the global branch, so the two branches share their first layers.
- **Global feature extractor** (stride 32): MobileNetV2 inverted-residual bottlenecks (expansion 6), three
  at 64 channels (stride 2 first), three at 96 (stride 2 first) and three at 128, then a context module.
- **Feature fusion**: the global features, upsampled ×4 bilinearly, a depthwise 3×3 and a 1×1 convolution,
  added to a 1×1 convolution of the high-resolution branch, ReLU.
- **Classifier**: two depthwise-separable convolutions, dropout, a 1×1 convolution to the classes,
  upsampled ×8 bilinearly to the input.

One departure: the paper's context module is PSPNet's pyramid pooling (bins 1, 2, 3, 6). Bins other than
1 need adaptive pooling of a fixed output size from a variable input, which ONNX cannot express for an input
of dynamic size; it is replaced here by the global-context gating of LR-ASPP (Howard et al., "Searching for
MobileNetV3", ICCV 2019): a 1×1 convolution of the features, multiplied by a sigmoid of a 1×1 convolution
of their global average. Both are a few thousand operations against the network's ~10⁸.

``width`` scales every channel count (1.0 = the paper's, 1.1 M parameters; the ``light`` preset's 0.5 has
0.3 M, the size of TwinLiteNet's 0.4 M). The input is padded to a multiple of 32 inside the model
(:class:`~freespace.models.base.SegmentationModel`); at KITTI's 375×1242 the network runs at 384×1248, or at
a reduced internal size when trained at one (the predictor resizes to the training size and upsamples the
probabilities: :class:`freespace.inference.predictor.Predictor`).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import SegmentationModel
from freespace.models.blocks import upsample_to
from freespace.models.registry import register_model

__all__ = ["FastSCNN"]


def _bn_relu(cout: int) -> list[nn.Module]:
    return [nn.BatchNorm2d(cout), nn.ReLU(inplace=True)]


class _DSConv(nn.Sequential):
    """Depthwise-separable convolution: depthwise 3×3 (stride ``stride``), BN, ReLU, pointwise 1×1, BN, ReLU."""

    def __init__(self, cin: int, cout: int, stride: int = 1) -> None:
        super().__init__(nn.Conv2d(cin, cin, 3, stride, 1, groups=cin, bias=False), *_bn_relu(cin),
                         nn.Conv2d(cin, cout, 1, bias=False), *_bn_relu(cout))


class _Bottleneck(nn.Module):
    """MobileNetV2's inverted residual: 1×1 expansion (×``t``), depthwise 3×3 (stride ``stride``), linear 1×1
    projection; the input is added back when the stride is 1 and the channels match."""

    def __init__(self, cin: int, cout: int, stride: int, t: int) -> None:
        super().__init__()
        mid = cin * t
        self.block = nn.Sequential(nn.Conv2d(cin, mid, 1, bias=False), *_bn_relu(mid),
                                   nn.Conv2d(mid, mid, 3, stride, 1, groups=mid, bias=False), *_bn_relu(mid),
                                   nn.Conv2d(mid, cout, 1, bias=False), nn.BatchNorm2d(cout))
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.block(x)
        return x + y if self.residual else y


class _GlobalContext(nn.Module):
    """LR-ASPP's context: ``relu(bn(conv1×1(x))) · sigmoid(conv1×1(mean over H, W of x))``."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.local = nn.Sequential(nn.Conv2d(cin, cout, 1, bias=False), *_bn_relu(cout))
        self.gate = nn.Conv2d(cin, cout, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.local(x) * torch.sigmoid(self.gate(x.mean((2, 3), keepdim=True)))


def _fusion(c_high: int, c: int, num_classes: int) -> tuple[nn.Module, nn.Module, nn.Module]:
    """Feature fusion and classifier: ``fuse_low`` (depthwise 3×3 and 1×1 of the upsampled ``c``-channel context
    features), ``fuse_high`` (1×1 of the ``c_high``-channel high-resolution features to ``c``), whose sum goes
    through a ReLU into ``classifier`` (two depthwise-separable convolutions, dropout, 1×1 to the classes)."""
    fuse_low = nn.Sequential(nn.Conv2d(c, c, 3, 1, 1, groups=c, bias=False), *_bn_relu(c),
                             nn.Conv2d(c, c, 1, bias=False), nn.BatchNorm2d(c))
    fuse_high = nn.Sequential(nn.Conv2d(c_high, c, 1, bias=False), nn.BatchNorm2d(c))
    classifier = nn.Sequential(_DSConv(c, c), _DSConv(c, c), nn.Dropout2d(0.1), nn.Conv2d(c, num_classes, 1))
    return fuse_low, fuse_high, classifier


class FastSCNN(SegmentationModel):
    """Fast-SCNN: learning to downsample (stride 8), a global feature extractor (stride 32), feature fusion
    and a light classifier (see the module's docstring for the design and its one departure)."""

    def __init__(self, num_classes: int = 2, width: float = 1.0, expansion: int = 6) -> None:
        super().__init__(num_classes)
        if not 0.125 <= width <= 2:
            raise InvalidOptionError(f"width must be in [0.125, 2], got {width}")
        if not 1 <= expansion <= 8:
            raise InvalidOptionError(f"expansion must be in 1…8, got {expansion}")

        def ch(c: int) -> int:
            return max(8, int(round(c * width / 8)) * 8)  # multiples of 8: vector-friendly on a CPU

        c32, c48, c64, c96, c128 = ch(32), ch(48), ch(64), ch(96), ch(128)
        self.downsample = nn.Sequential(nn.Conv2d(3, c32, 3, 2, 1, bias=False), *_bn_relu(c32),
                                        _DSConv(c32, c48, 2), _DSConv(c48, c64, 2))
        stages: list[nn.Module] = []
        cin = c64
        for cout, stride in ((c64, 2), (c96, 2), (c128, 1)):
            for i in range(3):
                stages.append(_Bottleneck(cin, cout, stride if i == 0 else 1, expansion))
                cin = cout
        self.features = nn.Sequential(*stages, _GlobalContext(c128, c128))
        self.fuse_low, self.fuse_high, self.classifier = _fusion(c64, c128, num_classes)

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        high = self.downsample(x)
        low = upsample_to(self.features(high), high)
        fused = F.relu(self.fuse_low(low) + self.fuse_high(high))
        return upsample_to(self.classifier(fused), x)


@register_model("fastscnn", {"light": {"width": 0.5}, "paper": {"width": 1.0}}, geometry=lambda o: (32, 1))
def fastscnn(num_classes: int = 2, width: float = 0.5, expansion: int = 6) -> FastSCNN:
    """Fast-SCNN (Poudel et al., BMVC 2019), built for speed. ``light``: half width (0.3 M parameters);
    ``paper``: the paper's channels (1.1 M)."""
    return FastSCNN(num_classes, width=width, expansion=expansion)
