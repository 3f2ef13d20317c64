"""DUpsampling (Tian et al., "Decoders Matter for Semantic Segmentation: Data-Dependent Decoding
Enables Flexible Feature Aggregation", CVPR 2019).

The network predicts, at output stride ``ratio``, a ``compressed_dim``-vector per cell; a linear
reconstruction ``W`` (plus the mean patch) maps it to the ``ratio × ratio × C`` one-hot label patch of
that cell, and a pixel shuffle lays the patches out at full resolution. ``W`` is learned from the label
space — the principal components of the training labels' patches — with :meth:`DUpsampling.fit_reconstruction`
(:meth:`DUpsampling.prepare`, which the trainer calls before training); the logits are the
reconstruction divided by a learned temperature (softmax with adaptive temperature). Low-level encoder
features are downsampled and fused with the last ones, as in the paper.

Three choices make the head trainable on the paper's budget (without them it predicts the majority
class: F 38 % where the other networks reach 80–90 %):

- **whitened coefficients**: the head predicts each principal coefficient divided by its standard
  deviation over the training patches (``coef_std``), so every output has unit scale (the raw ones
  span two orders of magnitude, 9.6 down to 0.1 for road labels at ratio 16);
- **temperature**: initialised to ``1 / ln(99 (C − 1))``, so that a perfect reconstruction (1 on the
  true class, 0 elsewhere) gives p = 0.99 — with T = 1 it gives only 0.73, and at lr 0.001 T barely moves;
- **class bias**: a learned per-class logit bias, initialised to ``−mean_patch / T`` averaged over the
  patch, so that the mean patch (what an untrained head outputs) sits at p = 1/C instead of favouring
  the majority class (p(road) ≈ 0.4 < 0.5 on road scenes).

Train-mode output: ``{"logits": N×C×H×W, "compressed": N×compressed_dim×H/ratio×W/ratio}`` (whitened);
the loss adds ``aux_weight`` × the mean squared error between the compressed prediction and the
label's whitened projection.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import InvalidOptionError
from freespace.models.base import IGNORE_INDEX, Outputs, SegmentationModel, load_smp_encoder
from freespace.models.blocks import ConvBNReLU
from freespace.models.registry import register_model

__all__ = ["DUpsampling", "label_patches"]

log = logging.getLogger(__name__)


def label_patches(target: torch.Tensor, num_classes: int, ratio: int,
                  ignore_index: int = IGNORE_INDEX) -> tuple[torch.Tensor, torch.Tensor]:
    """One-hot label patches: ``(N×(C·r²)×h×w float, N×h×w bool)`` — the second marks the cells with
    no don't-care pixel. ``target``: ``N×H×W`` class map, H and W multiples of ``ratio``. Channel order
    matches :func:`torch.nn.functional.pixel_shuffle` (class-major, then the r×r offsets)."""
    valid = target != ignore_index
    onehot = F.one_hot(torch.where(valid, target, 0), num_classes).permute(0, 3, 1, 2).float()
    patches = F.pixel_unshuffle(onehot, ratio)
    ok = F.max_pool2d((~valid).float().unsqueeze(1), ratio)[:, 0] == 0
    return patches, ok


class DUpsampling(SegmentationModel):
    """DUpsampling on an smp encoder (see the module docstring)."""

    full_size_outputs = ("logits",)

    def __init__(self, num_classes: int = 2, encoder_name: str = "resnet18", ratio: int = 16,
                 compressed_dim: int = 64, head_channels: int = 128, aux_weight: float = 0.1,
                 encoder_weights: str | None = None) -> None:
        super().__init__(num_classes)
        if ratio not in (8, 16, 32):
            raise InvalidOptionError(f"ratio must be 8, 16 or 32 (the encoder's output stride), got {ratio}")
        patch = num_classes * ratio * ratio
        if not 1 <= compressed_dim <= patch:
            raise InvalidOptionError(f"compressed_dim must be 1..{patch}, got {compressed_dim}")
        self.ratio, self.aux_weight = ratio, aux_weight
        self.encoder = load_smp_encoder(encoder_name, encoder_weights, depth=5,
                                        output_stride=ratio if ratio < 32 else 32)
        self.normalise_for(self.encoder)
        chans = self.encoder.out_channels
        self.low = ConvBNReLU(chans[2], 48, 1)
        self.head = nn.Sequential(ConvBNReLU(chans[-1] + 48, head_channels), ConvBNReLU(head_channels, head_channels),
                                  nn.Conv2d(head_channels, compressed_dim, 1))
        # reconstruction: patch = W z + mean; orthonormal until fitted from labels
        basis = torch.linalg.qr(torch.randn(patch, compressed_dim, generator=torch.Generator().manual_seed(0)))[0]
        self.register_buffer("reconstruction", basis)
        self.register_buffer("patch_mean", torch.full((patch,), 1.0 / num_classes))
        self.register_buffer("coef_std", torch.ones(compressed_dim))
        # a perfect reconstruction (margin 1 between the true class and the others) gives p = 0.99
        self.log_temperature = nn.Parameter(torch.tensor(-math.log(math.log(99.0 * (num_classes - 1)))))
        self.class_bias = nn.Parameter(torch.zeros(num_classes))

    def prepare(self, train_labels: Iterable[torch.Tensor]) -> None:
        """Fit the reconstruction from the training labels (:meth:`fit_reconstruction`)."""
        kept = self.fit_reconstruction(train_labels)
        log.info("DUpsampling reconstruction fitted (%.1f%% of the label patches' variance kept by %d components)",
                 100 * kept, self.reconstruction.shape[1])

    @torch.no_grad()
    def fit_reconstruction(self, targets: Iterable[torch.Tensor], max_patches: int = 200_000) -> float:
        """Set ``W``, the mean patch, the coefficients' scales and the class bias from training labels
        (PCA of their one-hot patches; see the module docstring).

        Args:
            targets: ``N×H×W`` (or ``H×W``) int64 class maps, H and W multiples of ``ratio``
                (don't-care cells are skipped).
        Returns:
            The fraction of the patches' variance that ``compressed_dim`` components keep.
        """
        rows = []
        for t in targets:
            t = t.unsqueeze(0) if t.dim() == 2 else t
            h, w = t.shape[-2:]
            t = t[..., : h - h % self.ratio, : w - w % self.ratio].long()
            p, ok = label_patches(t, self.num_classes, self.ratio)
            rows.append(p.permute(0, 2, 3, 1)[ok])
        data = torch.cat(rows)[:max_patches].double()
        if data.shape[0] < 2:
            raise InvalidOptionError("fit_reconstruction needs labels with at least two full patches")
        mean = data.mean(0)
        _, s, vh = torch.linalg.svd(data - mean, full_matrices=False)
        k = self.reconstruction.shape[1]
        basis = vh[:k].T
        if basis.shape[1] < k:  # fewer patches than components: pad with orthonormal directions
            extra = torch.linalg.qr(torch.randn(basis.shape[0], k, dtype=torch.float64))[0]
            basis = torch.linalg.qr(torch.cat([basis, extra], 1))[0][:, :k]
        self.reconstruction.copy_(basis.float())
        self.patch_mean.copy_(mean.float())
        std = ((data - mean) @ basis).std(0)
        self.coef_std.copy_(std.clamp_min(1e-2 * float(std.max())).float())
        prior = mean.view(self.num_classes, -1).mean(1).float()  # mean patch, per class, averaged over the patch
        self.class_bias.copy_(-prior / self.log_temperature.exp())
        energy = (s ** 2)
        return float(energy[:k].sum() / energy.sum().clamp_min(1e-12))

    def forward_features(self, x: torch.Tensor) -> Outputs:
        feats = self.encoder(x)
        last = feats[-1]
        low = F.interpolate(self.low(feats[2]), size=last.shape[-2:], mode="bilinear", align_corners=False)
        z = self.head(torch.cat([last, low], 1))  # whitened coefficients
        basis = self.reconstruction * self.coef_std[None, :]
        patches = F.conv2d(z, basis[:, :, None, None]) + self.patch_mean[None, :, None, None]
        logits = F.pixel_shuffle(patches, self.ratio) / self.log_temperature.exp()
        logits = logits + self.class_bias[None, :, None, None]
        return {"logits": logits, "compressed": z} if self.training else logits

    def loss(self, outputs: Outputs, target: torch.Tensor, ignore_index: int = IGNORE_INDEX) -> dict[str, torch.Tensor]:
        losses = super().loss(outputs, target, ignore_index)
        if isinstance(outputs, dict) and self.aux_weight > 0:
            z = outputs["compressed"]
            h, w = (s * self.ratio for s in z.shape[-2:])
            padded = F.pad(target, (0, w - target.shape[-1], 0, h - target.shape[-2]), value=ignore_index)
            patches, ok = label_patches(padded, self.num_classes, self.ratio, ignore_index)
            proj = torch.einsum("nphw,pk->nkhw", patches - self.patch_mean[None, :, None, None], self.reconstruction)
            proj = proj / self.coef_std[None, :, None, None]
            err = ((z - proj) ** 2).mean(1)
            aux = err[ok].mean() if ok.any() else z.sum() * 0
            losses["compressed"] = aux
            losses["total"] = losses["total"] + self.aux_weight * aux
        return losses


@register_model("dupsampling",
                {"light": {"encoder_name": "resnet18", "head_channels": 128},
                 "paper": {"encoder_name": "resnet50", "head_channels": 256}},
                geometry=lambda o: (o["ratio"], 1 if o["ratio"] == 32 else 32 // o["ratio"]))
def dupsampling(num_classes: int = 2, encoder_name: str = "resnet18", ratio: int = 16, compressed_dim: int = 64,
                head_channels: int = 128, aux_weight: float = 0.1, encoder_weights: str | None = None) -> DUpsampling:
    """DUpsampling. ``light``: ResNet-18, ratio 16, 128-channel head; ``paper``: ResNet-50, ratio 16, 256.
    (Geometry for :func:`~freespace.models.min_input_size`: at ratio 16 the encoder's last stage is
    dilated by 2, at 8 by 4.)"""
    return DUpsampling(num_classes, encoder_name=encoder_name, ratio=ratio, compressed_dim=compressed_dim,
                       head_channels=head_channels, aux_weight=aux_weight, encoder_weights=encoder_weights)
