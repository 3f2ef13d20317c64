"""A study's own training data (a protocol file's ``data`` and ``variants`` mappings; the file:
:mod:`freespace.experiments.protocol`): named training sources (:class:`DataSource`: a dataset layout and root, and
optionally a label tree, splits and an SGBM cache; paths with ``${NAME}`` from the environment) and the variants
that train on them (:func:`declared_variants`).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from freespace.errors import InvalidOptionError, param
from freespace.experiments.variants import VARIANTS, Variant, variant_tag

__all__ = ["DataSource", "DATA_KEYS", "data_sources", "declared_variants"]

#: a declared variant's name (a protocol file's ``variants`` mapping), and a training source's (``data``)
_VARIANT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9+_-]{0,39}")
_DATA_NAME = re.compile(r"[a-z][a-z0-9_-]{0,39}")
#: the per-sample augmentations a declared variant may switch on (TrainConfig's switches)
_SAMPLES = ("flip", "photometric")
#: ``${NAME}`` in a training source's paths: the environment variable's value
_ENV = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")

#: a training source's keys (``data``), and the :class:`~freespace.engine.config.TrainConfig` field each sets
DATA_KEYS = {"dataset": "dataset", "root": "root", "labels": "labels", "splits": "splits_dir", "cache_dir": "cache_dir"}


@dataclass(frozen=True)
class DataSource:
    """A named training source of a protocol file (its ``data`` mapping): the dataset layout ``dataset`` at
    ``root``; optionally ``labels``, a label tree that replaces the dataset's labels (``freespace autolabel``'s:
    :attr:`~freespace.engine.config.TrainConfig.labels`), ``splits``, a folder of ``train.txt``/``val.txt``/
    ``test.txt`` (:attr:`~freespace.engine.config.TrainConfig.splits_dir`), and ``cache_dir``, an SGBM cache,
    which only the variants with an ``augment`` get (they read disparities; the others keep the default, so that
    their settings do not depend on it).

    Paths are kept as the file spells them and resolved when cells are made (:meth:`training`; rebuilding the tables
    needs none of them): ``${NAME}`` is the environment variable's value, ``~`` the home folder, and a
    relative path is taken from ``base``, the protocol file's folder. ``file``: the protocol file, for the
    messages."""

    name: str
    dataset: str
    root: str
    base: Path = Path(".")
    file: str = ""
    labels: str | None = None
    splits: str | None = None
    cache_dir: str | None = None

    def _where(self, key: str) -> str:
        return f"{param('protocol')} {self.file}: data {self.name}: {key} {getattr(self, key)}"

    def path(self, key: str) -> Path | None:
        """The path of ``key`` (``root``, ``labels``, ``splits`` or ``cache_dir``) on this machine: ``${NAME}``
        expanded, absolute (None when the source gives none).

        Raises:
            InvalidOptionError: an environment variable it names is not set (or empty).
        """
        text = getattr(self, key)
        if text is None:
            return None
        unset = [m[1] for m in _ENV.finditer(text) if not os.environ.get(m[1])]
        if unset:
            raise InvalidOptionError(f"{self._where(key)}: the environment variable {unset[0]} is not set; "
                                     f"export {unset[0]}=DIR before the command")
        path = Path(os.path.expanduser(_ENV.sub(lambda m: os.environ[m[1]], text)))
        return path if path.is_absolute() else self.base / path

    def training(self, augment: tuple[str, ...] = ()) -> dict[str, str | None]:
        """The :class:`~freespace.engine.config.TrainConfig` values of a variant with ``augment`` that trains
        on this source: ``dataset``, ``root``, ``labels``, ``splits_dir`` and ``cache_dir`` (None: not given,
        or no ``augment``), paths resolved (:meth:`path`) and checked before any work.

        Raises:
            InvalidOptionError: an unset environment variable. InputFileError: ``root``, ``labels`` or
            ``splits`` is no folder (or ``splits`` lacks a list); ``cache_dir`` is a file. DatasetError:
            ``splits`` lists a frame twice.
        """
        from freespace.data.splits import read_splits
        from freespace.errors import FreespaceError, InputFileError

        values: dict[str, str | None] = {"dataset": self.dataset}
        for key, field_name in DATA_KEYS.items():
            if key == "dataset":
                continue
            path = self.path(key) if key != "cache_dir" or augment else None
            if path is not None and key != "cache_dir" and not path.is_dir():
                raise InputFileError(f"{self._where(key)}: no folder {path}; give the "
                                     + {"root": f"{self.dataset} dataset's folder",
                                        "labels": "label tree that `freespace autolabel` wrote",
                                        "splits": "folder of train.txt, val.txt and test.txt"}[key])
            if path is not None and key == "cache_dir" and path.is_file():
                raise InputFileError(f"{self._where(key)}: {path} is a file; give a folder for the SGBM cache")
            if path is not None and key == "splits":
                try:
                    read_splits(path)
                except FreespaceError as exc:
                    raise type(exc)(f"{self._where(key)}: {exc}") from None
            values[field_name] = None if path is None else str(path)
        return values



def data_sources(data: Any, base: Path, file: str) -> dict[str, DataSource]:
    """The ``data`` mapping → its :class:`DataSource` s by name (paths kept as written)."""
    from freespace.data.registry import list_datasets

    if not isinstance(data, dict) or not data:
        raise InvalidOptionError("data must map names to training sources (e.g. {rendered: {dataset: kitti, root: "
                                 "syn}})")
    sources = {}
    for name, spec in data.items():
        if not isinstance(name, str) or not _DATA_NAME.fullmatch(name):
            raise InvalidOptionError(f"data name {name!r}: lower-case letters, digits, - and _ (at most 40)")
        if not isinstance(spec, dict) or not {"dataset", "root"} <= set(spec) or set(spec) - set(DATA_KEYS):
            raise InvalidOptionError(f"data {name} must give dataset and root, and optionally labels, splits and "
                                     f"cache_dir (nothing else)")
        for key, value in spec.items():
            if not isinstance(value, str) or not value.strip():
                raise InvalidOptionError(f"data {name}: {key} must be text (a name or a path), got {value!r}")
            if "$" in _ENV.sub("", value):
                raise InvalidOptionError(f"data {name}: {key} {value}: write an environment variable as ${{NAME}}, "
                                         f"and no other $")
        if spec["dataset"] not in list_datasets(aliases=True):  # an earlier name too (studies' files keep theirs)
            raise InvalidOptionError(f"data {name}: unknown dataset {spec['dataset']!r}; choose one of "
                                     f"{', '.join(list_datasets(aliases=False))}")
        sources[name] = DataSource(name=name, base=base, file=file, **spec)
    return sources


def declared_variants(data: Any, sources: dict[str, DataSource]) -> dict[str, Variant]:
    """A protocol's ``variants`` mapping (``NAME: {data, augment, flip, photometric}``) → its :class:`Variant` s,
    in the file's order, each training on one of ``sources``."""
    from freespace.engine.option_values import AUGMENTS, parse_augment

    if not data:
        raise InvalidOptionError("variants must declare at least one variant")
    builtin = {v.upper(): v for v in VARIANTS}
    tags = {v.tag: v.name for v in VARIANTS.values()}
    declared: dict[str, Variant] = {}
    for name, spec in data.items():
        if not isinstance(name, str) or not _VARIANT_NAME.fullmatch(name):
            raise InvalidOptionError(f"variant name {name!r}: letters, digits, +, - and _ (at most 40, not "
                                     f"starting with +, - or _)")
        if name.upper() in builtin:
            raise InvalidOptionError(f"variant {name} is (or spells) the built-in variant {builtin[name.upper()]}, "
                                     f"which trains on reproduce's own dataset; give the declared one another name")
        if not isinstance(spec, dict) or set(spec) - {"data", "augment", *_SAMPLES}:
            raise InvalidOptionError(f"variant {name} must be a mapping of data, augment, flip and photometric (e.g. "
                                     f"{{data: {next(iter(sources))}}})")
        wrong = next((k for k in _SAMPLES if not isinstance(spec.get(k, False), bool)), None)
        if wrong:
            raise InvalidOptionError(f"variant {name}: {wrong} must be true or false, got {spec[wrong]!r}")
        if spec.get("data") not in sources:
            what = f"unknown data {spec['data']!r}" if "data" in spec else "names no data"
            raise InvalidOptionError(f"variant {name}: {what}; give data: one of {', '.join(sources)}")
        try:
            augment = parse_augment(spec.get("augment", "none")) if isinstance(spec.get("augment", "none"), str) \
                else None
        except InvalidOptionError:
            augment = None
        if augment is None:
            raise InvalidOptionError(f"variant {name}: augment must be one of {', '.join(AUGMENTS)}, got "
                                     f"{spec.get('augment')!r}")
        tag = variant_tag(name)
        if tag in tags:
            raise InvalidOptionError(f"variants {tags[tag]} and {name} would share the run folders' tag {tag!r} "
                                     f"(the name in lower case, + as _); rename one")
        tags[tag] = name
        declared[name] = Variant(name, augment, tag, data=spec["data"],
                                 samples=tuple(k for k in _SAMPLES if spec.get(k)))
    unused = [s for s in sources if all(v.data != s for v in declared.values())]
    if unused:
        raise InvalidOptionError(f"data {unused[0]} is the data of no variant; name it in one, or remove it")
    return declared
