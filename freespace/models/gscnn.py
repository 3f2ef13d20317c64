"""GSCNN (Takikawa et al., "Gated-SCNN: Gated Shape CNNs for Semantic Segmentation", ICCV 2019).

Two streams, as in the official network (NVIDIA's gated-scnn). The regular stream is an smp ResNet
encoder at output stride 8. The shape stream starts from the regular stream's first feature (ResNet's
64-channel conv1, upsampled to the shape stream's resolution) and alternates residual blocks, 1×1
convolutions that narrow it (64 → 32 → 16 → 8 channels) and *gated convolutional layers*, each driven by
a regular-stream feature projected to one channel and upsampled to the shape stream's resolution
(layer1 at stride 4, layer2 at stride 8, layer4 at stride 8 — the strides of the official mod3, mod4 and
mod7): ``α = σ(BN(conv(ReLU(conv(BN([s, r]))))))``, ``s ← conv₁ₓ₁(s ⊙ (1 + α))``. A 1×1 convolution gives
the edge logits, at the image size. In the ``paper`` preset the shape stream runs at full resolution
(``shape_stride=1``); the ``light`` preset runs it at stride 2 (``shape_stride=2``, a quarter of the
cost; the edge logits are still upsampled to the image size). The image gradient (Sobel magnitude of the
grey image, computed in the network — the official code runs OpenCV's Canny on the CPU) is fused with
the edge probability and fed to the ASPP (rates 12, 24, 36 at stride 8) as an extra branch; a
DeepLabv3+-style decoder with the stride-4 feature gives the segmentation.

Train-mode output: ``{"logits": N×C×H×W, "edges": N×1×H×W}``. The loss (:meth:`GSCNN.loss`) is the
official joint loss: the segmentation cross-entropy with per-image class weights
(:func:`image_weighted_cross_entropy`) + ``edge_weight`` × class-balanced BCE of the edges against the
label boundaries + ``attention_weight`` × the same weighted cross-entropy on pixels whose edge
probability exceeds 0.8 + ``dual_weight`` × the dual-task loss (:func:`dual_task_loss`: L1 between
the boundary magnitudes of a Gumbel-softmax sample of the prediction and of the label, half averaged
over the predicted boundary pixels and half over the label's).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import IGNORE_INDEX, Outputs, SegmentationModel, load_smp_encoder
from freespace.models.blocks import ASPP, ConvBNReLU, upsample_to
from freespace.models.registry import register_model

__all__ = ["GSCNN", "GatedConv", "Sobel", "label_boundaries", "image_weighted_cross_entropy", "dual_task_loss",
           "boundary_magnitude"]

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


def image_weighted_cross_entropy(logits: torch.Tensor, target: torch.Tensor,
                                 ignore_index: int = IGNORE_INDEX) -> torch.Tensor:
    """Cross-entropy with per-image class weights (the official ``ImageBasedCrossEntropyLoss2d``): in each
    image, class c present with frequency h_c (of its valid pixels) weighs ``1 + (1 − h_c)``, an absent one
    1; each image's weighted mean, averaged over the batch (the official sums over the batch). Images
    without a valid pixel add 0. ``logits``: ``N×C×H×W``; ``target``: ``N×H×W`` int64."""
    num_classes = logits.shape[1]
    total = logits.new_zeros(())
    for lg, t in zip(logits, target):
        valid = t != ignore_index
        if not valid.any():
            total = total + lg.sum() * 0
            continue
        hist = torch.bincount(t[valid], minlength=num_classes)[:num_classes].to(logits.dtype)
        hist = hist / hist.sum()
        weight = 1 + (hist > 0).to(logits.dtype) * (1 - hist)
        total = total + F.cross_entropy(lg[None], t[None], weight=weight, ignore_index=ignore_index)
    return total / logits.shape[0]


def _triangle_blur(x: torch.Tensor, radius: int = 4) -> torch.Tensor:
    """Separable triangle filter of ``radius`` (weights 1, 2, …, r+1, …, 1 over (r+1)²), replicate padding."""
    f = torch.cat([torch.arange(1, radius + 2), torch.arange(radius, 0, -1)]).to(x) / (radius + 1) ** 2
    c = x.shape[1]
    x = F.conv2d(F.pad(x, (radius, radius, 0, 0), mode="replicate"), f.view(1, 1, 1, -1).repeat(c, 1, 1, 1), groups=c)
    return F.conv2d(F.pad(x, (0, 0, radius, radius), mode="replicate"), f.view(1, 1, -1, 1).repeat(c, 1, 1, 1),
                    groups=c)


def boundary_magnitude(maps: torch.Tensor) -> torch.Tensor:
    """Boundary magnitude of ``N×C×H×W`` class maps (probabilities or one-hot), as in the official dual-task
    loss: triangle blur (radius 4), central-difference gradient magnitude per channel, divided by the
    largest value of the batch (so it lies in [0, 1]; 0 where the map is flat)."""
    e = F.pad(_triangle_blur(maps), (1, 1, 1, 1), mode="replicate")
    gx = (e[:, :, 1:-1, 2:] - e[:, :, 1:-1, :-2]) / 2
    gy = (e[:, :, 2:, 1:-1] - e[:, :, :-2, 1:-1]) / 2
    mag = torch.sqrt(gx * gx + gy * gy + 1e-12) - 1e-6  # ≈ 0 (not 1e-6 as with sqrt(· + 1e-6)) where flat
    mag = mag.clamp_min(0)
    return mag / mag.amax().clamp_min(1e-12)


def dual_task_loss(logits: torch.Tensor, target: torch.Tensor, ignore_index: int = IGNORE_INDEX,
                   tau: float = 0.5, threshold: float = 1e-3) -> torch.Tensor:
    """The dual-task loss (paper eq. 5, official ``DualTaskLoss``): boundaries ζ of a Gumbel-softmax sample
    (temperature ``tau``) of the predicted classes against the boundaries ζ̂ of the one-hot label, both by
    :func:`boundary_magnitude`; the L1 difference is averaged half over the pixels where ζ > ``threshold``
    and half over those where ζ̂ > ``threshold`` (every class channel). Don't-care pixels count as class 0
    with zero logits, as in the official code. ``logits``: ``N×C×H×W``; ``target``: ``N×H×W`` int64.

    The official code takes ``sqrt(g² + 1e-6)``, which puts every pixel above its 1e-8 threshold, so both
    halves average over the whole image; here the masks hold the boundary pixels the paper means.
    """
    ignore = (target == ignore_index).unsqueeze(1)
    logits = logits.masked_fill(ignore, 0.0)
    onehot = F.one_hot(target.masked_fill(ignore[:, 0], 0), logits.shape[1]).permute(0, 3, 1, 2).float()
    u = torch.rand_like(logits)
    gumbel = -torch.log(-torch.log(u + 1e-10) + 1e-10)
    g = boundary_magnitude(torch.softmax((logits + gumbel) / tau, 1))
    g_hat = boundary_magnitude(onehot)
    err = (g - g_hat).abs()
    on_pred = (g > threshold).detach().float()
    on_label = (g_hat > threshold).float()
    return (0.5 * (err * on_pred).sum() / on_pred.sum().clamp_min(1)
            + 0.5 * (err * on_label).sum() / on_label.sum().clamp_min(1))


class GatedConv(nn.Module):
    """Gated convolutional layer (official ``GatedSpatialConv2d``): the shape stream ``s`` gated by the
    one-channel regular-stream map ``r``, then a 1×1 convolution."""

    def __init__(self, channels: int, out_channels: int | None = None) -> None:
        super().__init__()
        self.gate = nn.Sequential(nn.BatchNorm2d(channels + 1), nn.Conv2d(channels + 1, channels + 1, 1),
                                  nn.ReLU(inplace=True), nn.Conv2d(channels + 1, 1, 1), nn.BatchNorm2d(1), nn.Sigmoid())
        self.conv = nn.Conv2d(channels, out_channels or channels, 1, bias=False)

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


#: the ASPP rates at output stride 8 (the official code's 12, 24, 36)
ASPP_RATES = (12, 24, 36)
SHAPE_STRIDES = (1, 2, 4)
CLASS_WEIGHTING = ("image", "none")


class GSCNN(SegmentationModel):
    """Gated-SCNN on an smp ResNet (see the module docstring).

    Args:
        shape_stride: resolution of the shape stream (1 = the image's, as in the paper; 2 or 4).
        shape_channels: the shape stream's widths ``(c1, c2, c3, c4)`` (paper: 64, 32, 16, 8).
        class_weighting: ``"image"`` (official per-image class weights) or ``"none"`` (plain cross-entropy).
    """

    def __init__(self, num_classes: int = 2, encoder_name: str = "resnet18", aspp_channels: int = 128,
                 shape_stride: int = 1, shape_channels: tuple[int, int, int, int] = (64, 32, 16, 8),
                 edge_weight: float = 20.0, attention_weight: float = 1.0, dual_weight: float = 1.0,
                 class_weighting: str = "image", encoder_weights: str | None = None) -> None:
        super().__init__(num_classes)
        if shape_stride not in SHAPE_STRIDES:
            raise InvalidOptionError(f"shape_stride must be one of {SHAPE_STRIDES}, got {shape_stride}")
        if len(shape_channels) != 4 or min(shape_channels) < 1:
            raise InvalidOptionError(f"shape_channels must be 4 positive widths, got {shape_channels}")
        if class_weighting not in CLASS_WEIGHTING:
            raise InvalidOptionError(f"class_weighting must be one of {', '.join(CLASS_WEIGHTING)}, "
                                     f"got {class_weighting!r}")
        self.edge_weight, self.attention_weight, self.dual_weight = edge_weight, attention_weight, dual_weight
        self.shape_stride, self.class_weighting = shape_stride, class_weighting
        self.encoder = load_smp_encoder(encoder_name, encoder_weights, depth=5, output_stride=8)
        self.normalise_for(self.encoder)
        ch = self.encoder.out_channels  # [3, s/2, s/4, s/8, s/8, s/8]
        c1, c2, c3, c4 = shape_channels
        self.s1 = nn.Identity() if ch[1] == c1 else nn.Conv2d(ch[1], c1, 1)
        self.r1, self.r2, self.r3 = (nn.Conv2d(ch[i], 1, 1) for i in (2, 3, 5))  # official dsn3, dsn4, dsn7
        self.res1, self.d1, self.gate1 = _ResBlock(c1), nn.Conv2d(c1, c2, 1), GatedConv(c2)
        self.res2, self.d2, self.gate2 = _ResBlock(c2), nn.Conv2d(c2, c3, 1), GatedConv(c3)
        self.res3, self.d3, self.gate3 = _ResBlock(c3), nn.Conv2d(c3, c4, 1), GatedConv(c4)
        self.edge_out = nn.Conv2d(c4, 1, 1, bias=False)
        self.fuse = nn.Conv2d(2, 1, 1, bias=False)
        self.image_gradient = Sobel(1)
        self.aspp = ASPP(ch[5], aspp_channels, rates=ASPP_RATES, extra=True)
        self.low = ConvBNReLU(ch[2], 48, 1)
        self.decoder = nn.Sequential(ConvBNReLU(aspp_channels + 48, aspp_channels),
                                     ConvBNReLU(aspp_channels, aspp_channels), nn.Conv2d(aspp_channels, num_classes, 1))

    def shape_stream(self, feats: list[torch.Tensor], size: tuple[int, int]) -> torch.Tensor:
        """Edge logits ``N×1×h×w`` at the shape stream's resolution ``size`` (the image's / shape_stride)."""
        def up(t: torch.Tensor) -> torch.Tensor:
            return F.interpolate(t, size=size, mode="bilinear", align_corners=False)

        s = self.res1(up(self.s1(feats[1])))
        s = self.gate1(self.d1(s), up(self.r1(feats[2])))
        s = self.gate2(self.d2(self.res2(s)), up(self.r2(feats[3])))
        s = self.gate3(self.d3(self.res3(s)), up(self.r3(feats[5])))
        return self.edge_out(s)

    def forward_features(self, x: torch.Tensor) -> Outputs:
        feats = self.encoder(x)
        h, w = x.shape[-2:]
        edges = upsample_to(self.shape_stream(feats, (h // self.shape_stride, w // self.shape_stride)), x)
        grey = (x * self.std + self.mean).mean(1, keepdim=True)  # undo the normalisation for the gradient
        gradient = self.image_gradient(grey)
        attention = torch.sigmoid(self.fuse(torch.cat([torch.sigmoid(edges), gradient], 1)))
        f2, f5 = feats[2], feats[5]
        a = self.aspp(f5, attention)
        y = self.decoder(torch.cat([upsample_to(a, f2), self.low(f2)], 1))
        logits = upsample_to(y, x)
        return {"logits": logits, "edges": edges} if self.training else logits

    full_size_outputs = ("logits", "edges")

    def _seg_loss(self, logits: torch.Tensor, target: torch.Tensor, ignore_index: int) -> torch.Tensor:
        if self.class_weighting == "image":
            return image_weighted_cross_entropy(logits, target, ignore_index)
        return F.cross_entropy(logits, target, ignore_index=ignore_index)

    def loss(self, outputs: Outputs, target: torch.Tensor, ignore_index: int = IGNORE_INDEX) -> dict[str, torch.Tensor]:
        if not isinstance(outputs, dict):
            seg = self._seg_loss(outputs, target, ignore_index)
            return {"total": seg, "seg": seg}
        logits, edge_logits = outputs["logits"], outputs["edges"][:, 0]
        seg = self._seg_loss(logits, target, ignore_index)
        gt_edges, valid = label_boundaries(target, ignore_index)
        # class-balanced BCE (positives are rare)
        pos = (gt_edges & valid).float()
        neg = (~gt_edges & valid).float()
        n_pos, n_neg = pos.sum(), neg.sum()
        total = (n_pos + n_neg).clamp_min(1)
        weight = pos * (n_neg / total) + neg * (n_pos / total)
        edge = F.binary_cross_entropy_with_logits(edge_logits, pos, weight=weight, reduction="sum") / total
        # attention: the segmentation loss where the shape stream is confident about an edge
        confident = torch.sigmoid(edge_logits.detach()) > 0.8
        attention = self._seg_loss(logits, torch.where(confident, target, ignore_index), ignore_index)
        dual = dual_task_loss(logits, target, ignore_index)
        return {"total": seg + self.edge_weight * edge + self.attention_weight * attention + self.dual_weight * dual,
                "seg": seg, "edge": edge, "attention": attention, "dual": dual}


@register_model("gscnn",
                {"light": {"encoder_name": "resnet18", "aspp_channels": 128, "shape_stride": 2},
                 "paper": {"encoder_name": "resnet50", "aspp_channels": 256, "shape_stride": 1}},
                geometry=lambda o: (8, max(ASPP_RATES)))
def gscnn(num_classes: int = 2, encoder_name: str = "resnet18", aspp_channels: int = 128, shape_stride: int = 1,
          shape_channels: tuple[int, int, int, int] = (64, 32, 16, 8), edge_weight: float = 20.0,
          attention_weight: float = 1.0, dual_weight: float = 1.0, class_weighting: str = "image",
          encoder_weights: str | None = None) -> GSCNN:
    """GSCNN. ``paper``: ResNet-50 (the paper's WideResNet-38 is not in smp), ASPP 256, shape stream at full
    resolution, 64-32-16-8; ``light``: ResNet-18, ASPP 128, shape stream at stride 2 (same widths)."""
    return GSCNN(num_classes, encoder_name=encoder_name, aspp_channels=aspp_channels, shape_stride=shape_stride,
                 shape_channels=shape_channels, edge_weight=edge_weight, attention_weight=attention_weight,
                 dual_weight=dual_weight, class_weighting=class_weighting, encoder_weights=encoder_weights)
