"""Small building blocks shared by the networks."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ConvBNReLU", "ASPP", "upsample_to"]


class ConvBNReLU(nn.Sequential):
    """``k×k`` convolution (optionally dilated), batch norm, ReLU; padding keeps the size."""

    def __init__(self, cin: int, cout: int, k: int = 3, dilation: int = 1) -> None:
        super().__init__(nn.Conv2d(cin, cout, k, padding=dilation * (k // 2), dilation=dilation, bias=False),
                         nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


def upsample_to(x: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """Bilinear resize of ``x`` to the spatial size of ``ref``."""
    return F.interpolate(x, size=ref.shape[-2:], mode="bilinear", align_corners=False)


class ASPP(nn.Module):
    """Atrous spatial pyramid pooling (DeepLab v3): 1×1, three dilated 3×3, image pooling; an optional
    extra single-channel map (GSCNN's edges) is projected and fused as one more branch."""

    def __init__(self, cin: int, cout: int, rates: tuple[int, int, int] = (6, 12, 18), extra: bool = False) -> None:
        super().__init__()
        self.branches = nn.ModuleList([ConvBNReLU(cin, cout, 1)] + [ConvBNReLU(cin, cout, 3, r) for r in rates])
        self.pool = nn.Sequential(nn.AdaptiveAvgPool2d(1), nn.Conv2d(cin, cout, 1, bias=False), nn.ReLU(inplace=True))
        self.extra = ConvBNReLU(1, cout, 1) if extra else None
        n = len(rates) + 2 + (1 if extra else 0)
        self.project = nn.Sequential(ConvBNReLU(n * cout, cout, 1), nn.Dropout2d(0.1))

    def forward(self, x: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        feats = [b(x) for b in self.branches]
        feats.append(self.pool(x).expand(-1, -1, x.shape[2], x.shape[3]))
        if self.extra is not None:
            feats.append(self.extra(upsample_to(extra, x)))  # type: ignore[arg-type]
        return self.project(torch.cat(feats, 1))
