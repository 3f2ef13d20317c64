"""GSCNN (Takikawa et al., "Gated-SCNN: Gated Shape CNNs for Semantic Segmentation", ICCV 2019).

Two streams. The regular stream is an smp ResNet encoder at output stride 8. The shape stream starts
from the first encoder stage and refines it with residual blocks and *gated convolutional layers*, each
driven by a deeper regular-stream feature (projected to one channel): ``α = σ(conv(ReLU(conv([s, r]))))``,
``s ← conv(s ⊙ (1 + α))``. It ends in edge logits at full resolution. The image gradient (Sobel
magnitude of the grey image, computed in the network — no OpenCV or device special cases) is fused with
the edge probability and fed to the ASPP as an extra branch; a DeepLabv3+-style decoder with the
stride-4 feature gives the segmentation.

Train-mode output: ``{"logits": N×C×H×W, "edges": N×1×H×W}``. The loss (:meth:`GSCNN.loss`) is the
paper's: cross-entropy + ``edge_weight`` × class-balanced BCE of the edges against the label boundaries
+ ``attention_weight`` × cross-entropy on pixels whose edge probability exceeds 0.8 + ``dual_weight`` ×
the dual-task term (L1 between the boundaries of the predicted class probabilities and the label's).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import IGNORE_INDEX, Outputs, SegmentationModel, load_smp_encoder, register_model
from freespace.models.blocks import ASPP, ConvBNReLU, upsample_to

__all__ = ["GSCNN", "GatedConv", "Sobel", "label_boundaries"]


class Sobel(nn.Module):
    """Per-channel Sobel gradient magnitude of a ``channels``-channel map, same size (replicate padding).
    The kernels are fixed buffers (exported as plain convolutions)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        k = torch.tensor([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]]) / 8
        self.channels = channels
        self.register_buffer("kernel", torch.stack([k, k.t()]).repeat(channels, 1, 1).unsqueeze(1), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        g = F.conv2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), self.kernel, groups=self.channels)
        g = g * g
        return torch.sqrt(g[:, 0::2] + g[:, 1::2] + 1e-12)


def label_boundaries(target: torch.Tensor, ignore_index: int = IGNORE_INDEX) -> tuple[torch.Tensor, torch.Tensor]:
    """``(edges, valid)``, both ``N×H×W`` bool: pixels whose 3×3 neighbourhood holds another (valid) class,
    and pixels away from don't-care regions."""
    valid = target != ignore_index
    t = torch.where(valid, target, -1).float().unsqueeze(1)
    big = torch.where(valid.unsqueeze(1), t, torch.full_like(t, -1e4))
    small = torch.where(valid.unsqueeze(1), t, torch.full_like(t, 1e4))
    hi = F.max_pool2d(big, 3, 1, 1)
    lo = -F.max_pool2d(-small, 3, 1, 1)
    edges = ((hi != t) | (lo != t)) & valid.unsqueeze(1)
    near_ignore = F.max_pool2d((~valid).float().unsqueeze(1), 3, 1, 1) > 0
    return edges[:, 0], (~near_ignore)[:, 0]


class GatedConv(nn.Module):
    """Gated convolutional layer: the shape stream ``s`` gated by the regular-stream map ``r`` (1 channel)."""

    def __init__(self, channels: int, out_channels: int) -> None:
        super().__init__()
        self.gate = nn.Sequential(nn.BatchNorm2d(channels + 1), nn.Conv2d(channels + 1, channels + 1, 1),
                                  nn.ReLU(inplace=True), nn.Conv2d(channels + 1, 1, 1), nn.BatchNorm2d(1), nn.Sigmoid())
        self.conv = nn.Conv2d(channels, out_channels, 1, bias=False)

    def forward(self, s: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        alpha = self.gate(torch.cat([s, r], 1))
        return self.conv(s * (alpha + 1))


class _ResBlock(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.body = nn.Sequential(nn.Conv2d(c, c, 3, padding=1, bias=False), nn.BatchNorm2d(c), nn.ReLU(inplace=True),
                                  nn.Conv2d(c, c, 3, padding=1, bias=False), nn.BatchNorm2d(c))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.body(x))


class GSCNN(SegmentationModel):
    """Gated-SCNN on an smp ResNet (see the module docstring)."""

    def __init__(self, num_classes: int = 2, encoder_name: str = "resnet18", aspp_channels: int = 128,
                 shape_channels: tuple[int, int, int] = (64, 32, 16), edge_weight: float = 20.0,
                 attention_weight: float = 1.0, dual_weight: float = 1.0, encoder_weights: str | None = None) -> None:
        super().__init__(num_classes)
        self.edge_weight, self.attention_weight, self.dual_weight = edge_weight, attention_weight, dual_weight
        self.encoder = load_smp_encoder(encoder_name, encoder_weights, depth=5, output_stride=8)
        ch = self.encoder.out_channels  # [3, s/2, s/4, s/8, s/8, s/8]
        c1, c2, c3 = shape_channels
        self.s1 = nn.Conv2d(ch[2], c1, 1)
        self.r3, self.r4, self.r5 = (nn.Conv2d(ch[i], 1, 1) for i in (3, 4, 5))
        self.res1, self.gate1 = _ResBlock(c1), GatedConv(c1, c2)
        self.res2, self.gate2 = _ResBlock(c2), GatedConv(c2, c3)
        self.res3, self.gate3 = _ResBlock(c3), GatedConv(c3, c3)
        self.edge_out = nn.Conv2d(c3, 1, 1)
        self.fuse = nn.Conv2d(2, 1, 1)
        self.image_gradient, self.class_gradient = Sobel(1), Sobel(num_classes)
        self.aspp = ASPP(ch[5], aspp_channels, rates=(12, 24, 36), extra=True)
        self.low = ConvBNReLU(ch[2], 48, 1)
        self.decoder = nn.Sequential(ConvBNReLU(aspp_channels + 48, aspp_channels),
                                     ConvBNReLU(aspp_channels, aspp_channels), nn.Conv2d(aspp_channels, num_classes, 1))

    def forward_features(self, x: torch.Tensor) -> Outputs:
        feats = self.encoder(x)
        f2, f3, f4, f5 = feats[2], feats[3], feats[4], feats[5]
        s = self.s1(f2)
        s = self.gate1(self.res1(s), upsample_to(self.r3(f3), s))
        s = self.gate2(self.res2(s), upsample_to(self.r4(f4), s))
        s = self.gate3(self.res3(s), upsample_to(self.r5(f5), s))
        edges = upsample_to(self.edge_out(s), x)
        grey = (x * self.std + self.mean).mean(1, keepdim=True)  # undo the normalisation for the gradient
        gradient = self.image_gradient(grey)
        attention = torch.sigmoid(self.fuse(torch.cat([torch.sigmoid(edges), gradient], 1)))
        a = self.aspp(f5, attention)
        y = self.decoder(torch.cat([upsample_to(a, f2), self.low(f2)], 1))
        logits = upsample_to(y, x)
        return {"logits": logits, "edges": edges} if self.training else logits

    full_size_outputs = ("logits", "edges")

    def loss(self, outputs: Outputs, target: torch.Tensor, ignore_index: int = IGNORE_INDEX) -> dict[str, torch.Tensor]:
        losses = super().loss(outputs, target, ignore_index)
        if not isinstance(outputs, dict):
            return losses
        logits, edge_logits = outputs["logits"], outputs["edges"][:, 0]
        gt_edges, valid = label_boundaries(target, ignore_index)
        # class-balanced BCE (positives are rare)
        pos = (gt_edges & valid).float()
        neg = (~gt_edges & valid).float()
        n_pos, n_neg = pos.sum(), neg.sum()
        total = (n_pos + n_neg).clamp_min(1)
        weight = pos * (n_neg / total) + neg * (n_pos / total)
        edge = F.binary_cross_entropy_with_logits(edge_logits, pos, weight=weight, reduction="sum") / total
        # attention: cross-entropy where the shape stream is confident about an edge
        ce = F.cross_entropy(logits, target, ignore_index=ignore_index, reduction="none")
        att_mask = (torch.sigmoid(edge_logits) > 0.8) & (target != ignore_index)
        attention = (ce * att_mask).sum() / att_mask.sum().clamp_min(1)
        # dual task: boundaries of the predicted probabilities vs the label's boundaries
        prob_edges = self.class_gradient(torch.softmax(logits, 1)).amax(1)
        pred_b = torch.tanh(prob_edges * 4)
        dual = ((pred_b - gt_edges.float()).abs() * valid).sum() / valid.sum().clamp_min(1)
        losses.update(edge=edge, attention=attention, dual=dual)
        losses["total"] = (losses["total"] + self.edge_weight * edge + self.attention_weight * attention
                           + self.dual_weight * dual)
        return losses


@register_model("gscnn")
def gscnn(num_classes: int = 2, preset: str = "light", encoder_weights: str | None = None, **options) -> GSCNN:
    """GSCNN. ``light``: ResNet-18, ASPP 128; ``paper``: ResNet-50 (the paper's WideResNet-38 is not in
    smp), ASPP 256, shape stream 64-32-16."""
    presets = {"light": {"encoder_name": "resnet18", "aspp_channels": 128},
               "paper": {"encoder_name": "resnet50", "aspp_channels": 256}}
    if preset not in presets:
        raise InvalidOptionError(f"unknown preset {preset!r}; choose one of {', '.join(presets)}")
    return GSCNN(num_classes, encoder_weights=encoder_weights, **{**presets[preset], **options})
