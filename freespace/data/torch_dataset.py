"""The torch ``Dataset`` of training and evaluation: labelled frames of any
:class:`~freespace.data.base.StereoRoadDataset` as segmentation samples.

Samples are dicts: ``image`` float32 ``3×H×W`` in [0, 1] (normalisation belongs to the model),
``label`` int64 ``H×W`` (0 = non-road, 1 = road, :data:`~freespace.labels.IGNORE_INDEX` 255 = don't care),
``name`` str and ``index`` (the sample's position in this dataset). Options, all off by default:

* ``size=(H, W)``: images are resized with area interpolation, labels with nearest (never bilinear);
* ``cache=True``: decoded (and resized) frames are kept in memory, decoded once;
* ``affine=True``: the paper's conventional augmentation (random translation ±10 % and rotation ±10° of
  image and label together; label borders become don't care). Keys may be ``(epoch, i)`` pairs (see
  :class:`freespace.engine.data.EpochSampler`): the augmentation of sample i in an epoch depends only on
  (``seed``, epoch, i), so a resumed run sees exactly the same data;
* ``flip=True``, ``photometric=True`` (or ``"mild"``, ``"strong"``): a left-right mirror of image and label
  (probability ½) and a colour augmentation of the image (mild: brightness, contrast and saturation ×0.75–1.25,
  hue ±0.04 turn; strong: :func:`freespace.data.photometry.strong_photometry`, wider ranges, a dusk-like gamma,
  blur and noise), drawn with the conventional augmentation (before it, in this order); not in the paper, for
  training on few real drives;
* ``zoom=z`` (> 0, with ``affine``): the conventional augmentation also scales image and label by a factor drawn
  in 1 ± z (zoomed out, the new borders are don't care): the road at other distances than the drives show it;
  not in the paper;
* ``crop_top=c`` (> 0): each sample's top ``t × H`` rows are cut and the rest stretched back to ``H`` (image bilinear,
  label nearest), ``t`` drawn uniformly in [0, c] from (``seed``, epoch, i), before the colour and the
  conventional augmentation: the road ends at other rows than the training frames show it (a network otherwise
  learns where road usually stops); not in the paper;
* ``virtual=VirtualAugment(...)``: road-plane virtual views (a training run's ``augment="virtual"``),
  drawn from (``seed``, epoch, i) like the conventional augmentation and applied before it (when both are
  on), with the torch-free :func:`freespace.geometry.virtual_view`;
* ``transform(image, label) -> (image, label)``: a user function on the NumPy arrays (``H×W×3 uint8``,
  ``H×W uint8``), applied last, before the conversion to tensors.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from freespace.data.base import StereoRoadDataset
from freespace.data.photometry import strong_photometry
from freespace.errors import DatasetError
from freespace.io.codecs import read_image
from freespace.io.frame_fit import check_resize, fit
from freespace.labels import IGNORE_INDEX
from freespace.limits import MAX_CROP_TOP

__all__ = ["RoadSegmentationDataset", "Item", "VirtualAugment", "IGNORE_INDEX", "label_to_index", "resized_intrinsics",
           "PHOTOMETRIC", "photometric_strength"]


def label_to_index(road: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``uint8 H×W`` class map: 1 road, 0 non-road, :data:`IGNORE_INDEX` don't care."""
    out = road.astype(np.uint8)
    out[~valid] = IGNORE_INDEX
    return out


@dataclass(frozen=True)
class Item:
    """One sample: frame ``index`` of the dataset (named ``name``), and the image file to use instead of
    its left image (e.g. a DS-Generator view, which takes the left image's label) or None."""

    index: int
    name: str
    image: str | None = None


def _centre_and_half(ranges: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """The centres and half-widths of three pose ranges (:func:`freespace.geometry.pose_ranges`); a symmetric
    range ±h has centre 0 and half-width h exactly, so its draws are those of ``uniform(-1, 1) · h``."""
    from freespace.geometry import pose_ranges

    lo, hi = np.array(pose_ranges(ranges)).T
    return (lo + hi) / 2, (hi - lo) / 2


@dataclass(frozen=True)
class VirtualAugment:
    """The road-plane virtual views (``augment="virtual"``): each sample, each epoch, with probability
    ``prob``, becomes its road-plane virtual view (:func:`freespace.geometry.virtual_view`) from a pose drawn
    uniformly in the ranges ``shift`` (dx, dy, dz metres) and ``rotate`` (roll, pitch, yaw degrees), from
    (seed, epoch, i) only. A range is ``h`` for ±h or ``(low, high)`` (:func:`freespace.geometry.pose_ranges`).

    ``planes`` maps a dataset frame index to its intrinsics (3×3, pixels of the frame's own size) and
    road plane (:class:`freespace.geometry.RoadPlane`); frames without one are never warped.
    """

    planes: dict[int, tuple[np.ndarray, Any]]
    shift: Sequence[Any] = (0.5, 0.2, 0.0)
    rotate: Sequence[Any] = (3.0, 3.0, 3.0)
    prob: float = 0.5

    def pose(self, seed: int, epoch: int, i: int):  # -> VirtualPose | None
        """The pose of sample ``i`` in ``epoch`` (None: keep the sample as it is)."""
        from freespace.geometry import VirtualPose

        rng = np.random.default_rng([seed, epoch, i, 29])
        if rng.random() >= self.prob:
            return None
        (cs, hs), (cr, hr) = _centre_and_half(self.shift), _centre_and_half(self.rotate)
        s = cs + rng.uniform(-1, 1, 3) * hs
        r = cr + rng.uniform(-1, 1, 3) * hr
        return VirtualPose(shift=(float(s[0]), float(s[1]), float(s[2])), roll=float(r[0]), pitch=float(r[1]),
                           yaw=float(r[2]))


def resized_intrinsics(K: np.ndarray, src: tuple[int, int], dst: tuple[int, int]) -> np.ndarray:
    """Intrinsics (3×3, pixels) after resizing an image from ``src`` to ``dst`` (H, W), pixel centres kept
    (as cv2.resize: source pixel centre ``u`` lands on ``(u + 0.5)·sx − 0.5``)."""
    sx, sy = dst[1] / src[1], dst[0] / src[0]
    S = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
    return S @ K


#: the strengths of the colour augmentation (``photometric``): none, the mild jitter, or the strong one
PHOTOMETRIC = ("off", "mild", "strong")


def photometric_strength(value: bool | str) -> str:
    """``photometric`` as one of :data:`PHOTOMETRIC` (``False`` = off, ``True`` = mild)."""
    strength = ("mild" if value else "off") if isinstance(value, bool) else value
    if strength not in PHOTOMETRIC:
        raise ValueError(f"photometric must be one of {PHOTOMETRIC} or a bool, got {value!r}")
    return strength


def _augmenter(affine: bool, flip: bool, photometric: bool | str, zoom: float = 0.0) -> Any:
    """The per-sample augmentations that are on, as one albumentations pipeline (None when none is): the mild
    colour jitter (``photometric`` mild; the strong one is drawn apart, :func:`strong_photometry`), the mirror,
    then the paper's conventional augmentation (random translation and rotation of image and label together,
    and a scale in 1 ± ``zoom`` when ``zoom`` > 0). With ``affine`` alone it is the paper's pipeline as it always
    was (the same draws)."""
    import albumentations as A

    steps = [A.ColorJitter(brightness=(0.75, 1.25), contrast=(0.75, 1.25), saturation=(0.75, 1.25),
                           hue=(-0.04, 0.04), p=0.8)] if photometric_strength(photometric) == "mild" else []
    steps += [A.HorizontalFlip(p=0.5)] if flip else []
    scale = {"scale": (1 - zoom, 1 + zoom)} if zoom > 0 else {}
    steps += [A.Affine(translate_percent=(-0.1, 0.1), rotate=(-10, 10), p=0.8, border_mode=cv2.BORDER_CONSTANT,
                       fill=0, fill_mask=IGNORE_INDEX, **scale)] if affine else []
    return A.Compose(steps, seed=0) if steps else None


def cut_top(image: np.ndarray, label: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    """``image`` (``H×W×3 uint8``) and ``label`` (``H×W uint8`` class map) without their top ``round(share × H)`` rows,
    stretched back to ``H×W`` (image: bilinear, label: nearest, never mixing classes)."""
    h, w = label.shape
    top = int(round(share * h))
    if top == 0:
        return image, label
    return (cv2.resize(image[top:], (w, h), interpolation=cv2.INTER_LINEAR),
            cv2.resize(label[top:], (w, h), interpolation=cv2.INTER_NEAREST))


class RoadSegmentationDataset(torch.utils.data.Dataset):
    """Labelled frames of ``dataset`` as segmentation samples (see the module docstring for the options).

    Args:
        dataset: any dataset layout.
        names: the frames, by name or as :class:`Item` (default: every labelled frame).
        transform: ``(image, label) -> (image, label)`` on NumPy arrays, applied last.
        size: ``(H, W)`` to resize to, or None (each frame's own size).
        affine: the conventional augmentation (random translation and rotation), drawn from (``seed``,
            epoch, i).
        flip: mirror image and label left-right with probability ½, drawn like ``affine``.
        photometric: the colour augmentation's strength (:data:`PHOTOMETRIC`; ``True`` = mild), drawn like
            ``affine``.
        seed: the seed of the augmentations.
        cache: keep decoded frames in memory.
        virtual: road-plane virtual views, drawn from (``seed``, epoch, i); before the conventional
            augmentation when both are on.
        zoom: with ``affine``, also scale by a factor in 1 ± ``zoom`` (0: off; at most 0.5).
        crop_top: cut the top ``t`` (a fraction of the height, drawn in [0, ``crop_top``]) and stretch the rest
            back (0: off; below :data:`~freespace.limits.MAX_CROP_TOP`).
        resize: how a frame is fitted to ``size``: ``stretch`` or ``letterbox`` (aspect kept, the border don't
            care; :mod:`freespace.io.frame_fit`).

    Raises:
        DatasetError: a requested frame is unknown or has no label.
    """

    def __init__(self, dataset: StereoRoadDataset, names: Sequence[str | Item] | None = None,
                 transform: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None, *,
                 size: tuple[int, int] | None = None, affine: bool = False, seed: int = 0,
                 cache: bool = False, virtual: VirtualAugment | None = None, flip: bool = False,
                 photometric: bool | str = False, zoom: float = 0.0, resize: str = "stretch",
                 crop_top: float = 0.0) -> None:
        self.dataset = dataset
        wanted = list(names) if names is not None else [f.name for f in dataset.labelled()]
        self.items = [n if isinstance(n, Item) else Item(dataset.index(n), n) for n in wanted]
        unlabelled = [it.name for it in self.items if not dataset.has_label(dataset.frames[it.index])]
        if unlabelled:
            raise DatasetError(f"{len(unlabelled)} frames have no road label (first: {unlabelled[0]}); "
                               f"train on a labelled split")
        self.transform, self.size, self.affine, self.seed, self.cache = transform, size, affine, seed, cache
        self.resize = check_resize(resize)
        if virtual is not None and self.resize != "stretch":
            raise ValueError("virtual views take stretched frames (their intrinsics are scaled, not letterboxed)")
        self._cache: dict[tuple[int, str | None], tuple[np.ndarray, np.ndarray]] = {}
        if not 0 <= zoom <= 0.5:
            raise ValueError(f"zoom must be in [0, 0.5], got {zoom}")
        if not 0 <= crop_top < MAX_CROP_TOP:
            raise ValueError(f"crop_top must be in [0, {MAX_CROP_TOP}), got {crop_top}")
        self._aug = _augmenter(affine, flip, photometric, zoom)
        self.crop_top = crop_top
        self._strong = photometric_strength(photometric) == "strong"
        self.virtual = virtual
        self._K: dict[tuple[int, str | None], np.ndarray] = {}  # intrinsics at the decoded size, by frame and image

    def __len__(self) -> int:
        return len(self.items)

    def decoded(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Image (``uint8 H×W×3``) and class map (``uint8 H×W``) of sample i, resized to ``size`` if set
        (before augmentation and ``transform``)."""
        item = self.items[i]
        key = (item.index, item.image)  # a frame listed twice (``augment="duplicate"``) is decoded once
        if key in self._cache:
            return self._cache[key]
        sample = self.dataset.load(item.index, right=False, disparity=False)
        image = read_image(item.image) if item.image else sample.left
        label = label_to_index(sample.label.road, sample.label.valid)  # type: ignore[union-attr]
        if self.virtual is not None and item.index in self.virtual.planes:
            self._K[key] = resized_intrinsics(self.virtual.planes[item.index][0], image.shape[:2],
                                            tuple(self.size) if self.size is not None else image.shape[:2])
        if self.size is not None and image.shape[:2] != tuple(self.size):
            image = fit(image, tuple(self.size), self.resize)
            label = fit(label, tuple(self.size), self.resize, label=True, fill=IGNORE_INDEX)  # labels: never bilinear
        if self.cache:
            self._cache[key] = (image, label)
        return image, label

    def __getitem__(self, key: int | tuple[int, int]) -> dict[str, Any]:
        epoch, i = key if isinstance(key, tuple) else (0, key)
        image, label = self.decoded(i)
        k = (self.items[i].index, self.items[i].image)
        if self.virtual is not None and k in self._K:
            pose = self.virtual.pose(self.seed, epoch, i)
            if pose is not None:
                from freespace.geometry import virtual_view

                plane = self.virtual.planes[self.items[i].index][1]
                image, label, _ = virtual_view(image, label, self._K[k], plane, pose, ignore=IGNORE_INDEX)
        if self.crop_top > 0:  # its own generator, like the strong colours below
            image, label = cut_top(image, label, np.random.default_rng([self.seed, epoch, i, 2]).uniform(
                0, self.crop_top))
        if self._strong:  # its own generator: independent of the pipeline's draws, which it leaves as they were
            rng = np.random.default_rng([self.seed, epoch, i, 1])
            image = (strong_photometry(image.astype(np.float32) / 255.0, rng) * 255.0 + 0.5).astype(np.uint8)
        if self._aug is not None:
            self._aug.set_random_seed(int(np.random.default_rng([self.seed, epoch, i]).integers(2**31)))
            out = self._aug(image=image, mask=label)
            image, label = out["image"], out["mask"]
        if self.transform is not None:
            image, label = self.transform(image, label)
        return {"image": torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).float().div_(255.0),
                "label": torch.from_numpy(np.ascontiguousarray(label)).long(), "name": self.items[i].name,
                "index": i}
