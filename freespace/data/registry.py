"""The dataset registry: layouts by name (torch-free).

Each layout registers itself with :func:`register_dataset`; ``freespace/data/__init__.py`` imports every
layout, so importing this module (which imports the package first) makes all of them available.

One name per layout: ``kitti`` (KITTI road, and the renderer's output, which ``freespace synth`` writes as a KITTI
road tree), ``kitti-raw``, ``synthia``, ``carla`` (CARLA exports such as the paper's SYN-Stereo) and ``generic``.
The names of earlier versions (``kitti_road``, ``synth``, ``kitti_raw``, ``syn-stereo``) stay accepted as aliases,
so that configurations and run folders written with them still load; they are shown nowhere
(``list_datasets(aliases=False)`` leaves them out) and :func:`canonical_dataset` turns them into the layout's
name.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from freespace.data.base import StereoRoadDataset
from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike

__all__ = ["register_dataset", "list_datasets", "canonical_dataset", "layout_name", "get_dataset_class",
           "get_dataset"]

#: every name a layout answers to (its own and its aliases) → the layout
_REGISTRY: dict[str, type[StereoRoadDataset]] = {}


def register_dataset(name: str, *aliases: str) -> Callable[[type[StereoRoadDataset]], type[StereoRoadDataset]]:
    """Class decorator: make a layout available as ``name`` (its one name, shown in help and messages: the class's
    ``name``) and as ``aliases`` (earlier names, still accepted, shown nowhere)."""
    def wrap(cls: type[StereoRoadDataset]) -> type[StereoRoadDataset]:
        cls.name = name
        for n in (name, *aliases):
            if n in _REGISTRY and _REGISTRY[n] is not cls:
                raise ValueError(f"dataset name {n!r} is taken by {_REGISTRY[n].__name__}")
            _REGISTRY[n] = cls
        return cls
    return wrap


def list_datasets(aliases: bool = True) -> list[str]:
    """Every name a layout answers to, sorted; ``aliases=False``: one per layout, its name (what help and messages
    show)."""
    return sorted(_REGISTRY if aliases else {cls.name for cls in _REGISTRY.values()})


def canonical_dataset(name: str) -> str:
    """The layout's name of ``name``, which may be an alias: ``canonical_dataset("synth") == "kitti"``.

    Raises:
        InvalidOptionError: no layout answers to ``name`` (the message lists the layouts' names).
    """
    return get_dataset_class(name).name


def layout_name(name: Any) -> Any:
    """:func:`canonical_dataset` of a name some layout answers to; any other value as it is, for a caller's own
    choices to refuse (argparse, TrainConfig)."""
    return _REGISTRY[name].name if isinstance(name, str) and name in _REGISTRY else name


def get_dataset_class(name: str) -> type[StereoRoadDataset]:
    """The layout registered as ``name`` (its name or an alias).

    Raises:
        InvalidOptionError: no layout answers to ``name`` (the message lists the layouts' names).
    """
    if not isinstance(name, str) or name not in _REGISTRY:
        raise InvalidOptionError(f"unknown dataset {name!r}; choose one of {', '.join(list_datasets(aliases=False))}")
    return _REGISTRY[name]


def get_dataset(name: str, root: PathLike, split: str | None = None, **options: Any) -> StereoRoadDataset:
    """Open the dataset layout called ``name`` at ``root``, on-disk ``split`` (default: the layout's first).

    Options: ``disparity_source``, ``cache_dir``, ``max_disparity`` (:class:`~freespace.data.base.StereoRoadDataset`)
    and the layout's own (e.g. KITTI's ``disparity_dir``).

    Raises:
        InvalidOptionError: an unknown layout, or an option the layout does not take (named).
    """
    layout = get_dataset_class(name)
    unknown = sorted(set(options) - _options_of(layout))
    if unknown:
        raise InvalidOptionError(f"{param(unknown[0])} is not an option of the {layout.name} layout (it takes "
                                 f"{', '.join(sorted(_options_of(layout)))}); leave it out")
    return layout(root, split, **options)


def _options_of(layout: type[StereoRoadDataset]) -> set[str]:
    """The keyword options the constructors of ``layout`` take, down its classes as far as each passes
    ``**options`` on (so that an option no layout reads is refused, not a TypeError)."""
    names: set[str] = set()
    for klass in layout.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        params = inspect.signature(init).parameters.values()
        names |= {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
        if not any(p.kind == p.VAR_KEYWORD for p in params):
            break
    return names - {"self", "root", "split"}
