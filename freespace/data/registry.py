"""The dataset registry: layouts by name (torch-free).

Each layout registers itself with :func:`register_dataset`; ``freespace/data/__init__.py`` imports every
layout, so importing this module (which imports the package first) makes all of them available.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from freespace.data.base import StereoRoadDataset
from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike

__all__ = ["register_dataset", "list_datasets", "get_dataset_class", "get_dataset"]

_REGISTRY: dict[str, type[StereoRoadDataset]] = {}


def register_dataset(*names: str) -> Callable[[type[StereoRoadDataset]], type[StereoRoadDataset]]:
    """Class decorator: make a layout available under ``names`` (first = canonical, its ``name``)."""
    def wrap(cls: type[StereoRoadDataset]) -> type[StereoRoadDataset]:
        cls.name = names[0]
        for n in names:
            _REGISTRY[n] = cls
        return cls
    return wrap


def list_datasets() -> list[str]:
    """Registered dataset names, aliases included, sorted."""
    return sorted(_REGISTRY)


def get_dataset_class(name: str) -> type[StereoRoadDataset]:
    """The layout registered as ``name``; InvalidOptionError listing the names if there is none."""
    if name not in _REGISTRY:
        raise InvalidOptionError(f"unknown dataset {name!r}; choose one of {', '.join(sorted(_REGISTRY))}")
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
        raise InvalidOptionError(f"{param(unknown[0])} is not an option of the {name} layout (it takes "
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
