"""The training options as an interface offers them: each :class:`~freespace.engine.config.TrainConfig` field as an
:class:`Option` (help, default as config.yaml spells it, choices, metavar, and the type with its bounds), from which
the command line builds the options of ``train`` and ``reproduce``."""

from __future__ import annotations

import functools
import types
from collections.abc import Iterable, Mapping
from dataclasses import MISSING, dataclass, fields
from typing import Annotated, Any, Union, get_args, get_origin

from freespace.engine import config_yaml
from freespace.engine.config import TrainConfig
from freespace.limits import Bounded

__all__ = ["Option", "options"]


@dataclass(frozen=True)
class Option:
    """A :class:`~freespace.engine.config.TrainConfig` field as an interface offers it.

    ``name``: the field's. ``help``: its text (parameters in it written with :func:`~freespace.errors.param`).
    ``default``: as config.yaml spells it (None: none; TrainConfig parses the spelling). ``required``: no
    default. ``choices``: the values, for the help (TrainConfig checks them). ``kind``: the type an interface
    converts its text to — ``bool`` (a switch), a :class:`~freespace.limits.Bounded` int or float (the bounds
    declared in the field's type: text out of them is refused as TrainConfig refuses the value) or ``str``
    (passed on as text, which TrainConfig parses).
    """

    name: str
    help: str
    default: Any
    required: bool
    choices: tuple[str, ...] | None
    metavar: str | None
    kind: type | Bounded


def _kind(hint: Any) -> type:
    """``int`` of ``Annotated[int, ...] | None``; ``str`` for the types whose text TrainConfig parses."""
    if get_origin(hint) is Annotated:
        return _kind(get_args(hint)[0])
    if get_origin(hint) in (Union, types.UnionType):
        args = [a for a in get_args(hint) if a is not type(None)]
        return _kind(args[0]) if len(args) == 1 else str
    return hint if hint in (bool, int, float) else str


def _bounded(hint: Any) -> type | Bounded:
    """:func:`_kind`, a number's as a :class:`~freespace.limits.Bounded` of the bounds its type declares."""
    kind, b = _kind(hint), config_yaml.bounds(hint)
    if kind is int:
        return Bounded(int, b["ge"] if "ge" in b else b["gt"] + 1 if "gt" in b else None,
                       b["le"] if "le" in b else b["lt"] - 1 if "lt" in b else None)
    if kind is float:
        return Bounded(float, b.get("ge", b.get("gt")), b.get("le", b.get("lt")), "gt" in b, "lt" in b)
    return kind


@functools.lru_cache(maxsize=None)
def _default_text(name: str) -> Any:
    """The default of the field ``name`` as config.yaml spells it (None: none), typed once per process."""
    default = TrainConfig.__dataclass_fields__[name].default
    if default is MISSING or default is None:
        return None
    return config_yaml.plain_value(TrainConfig, name, config_yaml.typed_value(TrainConfig, name, default))


def options(names: Iterable[str] | None = None, values: Mapping[str, Any] | None = None) -> list[Option]:
    """The :class:`~freespace.engine.config.TrainConfig` fields ``names`` (default: all), in their order, as
    :class:`Option` objects; ``values``, typed (e.g. from :func:`~freespace.engine.config.read_config_yaml`),
    replace the fields' defaults, and a field given there is no longer required."""
    wanted = set(names) if names is not None else None
    values = values or {}
    found = []
    for f in fields(TrainConfig):
        if wanted is not None and f.name not in wanted:
            continue
        given = f.name in values
        if given:  # typed already: spelled, not checked again
            plain = config_yaml.plain_value(TrainConfig, f.name, values[f.name]) if values[f.name] is not None \
                else None
        else:
            plain = _default_text(f.name)
        found.append(Option(f.name, f.metadata["help"], plain, f.default is MISSING and not given,
                            config_yaml.choices(TrainConfig, f.name), f.metadata.get("metavar"),
                            _bounded(config_yaml.field_type(TrainConfig, f.name))))
    return found
