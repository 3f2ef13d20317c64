"""How the fields of a configuration dataclass (:class:`~freespace.engine.config.TrainConfig`) are declared and typed:
what an interface shows of each (:func:`option`), each value typed by pydantic in strict mode and refused in one line
(:func:`typed_value`), and a YAML file of fields read as typed values (:func:`read_fields_yaml`).

Strict: a YAML ``true`` is no integer, ``"3"`` no number, NaN and infinities no float; the bounds (``ge``, ``gt``,
``le``, ``lt``) are declared with each field's type, the choices in its metadata. The functions take the dataclass
(``cls``), so that this module needs no configuration of its own.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import MISSING, field, fields
from pathlib import Path
from typing import Any, get_args, get_type_hints

from pydantic import ConfigDict, TypeAdapter, ValidationError
from pydantic.fields import FieldInfo

from freespace.engine.option_values import number
from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError
from freespace.io.codecs import load_yaml
from freespace.io.files import PathLike, missing_input

__all__ = ["option", "field_type", "bounds", "choices", "typed_value", "plain_value", "read_fields_yaml"]


def option(help: str, default: Any = MISSING, *,
           choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None, metavar: str | None = None) -> Any:
    """A dataclass field with what an interface shows of it (:func:`freespace.engine.options.options`): ``help``
    (parameters in it written with :func:`~freespace.errors.param`), ``choices`` (a tuple, or a function giving
    it, called when needed: e.g. the networks, whose registry imports torch) and ``metavar``."""
    meta = {"help": help, "choices": choices, "metavar": metavar}
    return field(metadata=meta) if default is MISSING else field(default=default, metadata=meta)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    hints = get_type_hints(cls, include_extras=True)
    return {f.name: hints[f.name] for f in fields(cls)}


def field_type(cls: type, name: str) -> Any:
    """The type of the field ``name`` of the dataclass ``cls``, with its annotations (bounds, validators)."""
    return _hints(cls)[name]


@functools.cache
def _adapters(cls: type) -> dict[str, TypeAdapter]:
    """A pydantic validator of each field of ``cls`` (strict: no conversion between types; no NaN or infinity)."""
    config = ConfigDict(strict=True, allow_inf_nan=False)
    return {name: TypeAdapter(hint, config=config) for name, hint in _hints(cls).items()}


def bounds(hint: Any) -> dict[str, float]:
    """The bounds (``ge``, ``gt``, ``le``, ``lt``) declared in a field's type ``hint``."""
    found: dict[str, float] = {}
    for arg in get_args(hint):
        if isinstance(arg, FieldInfo):
            for m in arg.metadata:
                found.update({k: getattr(m, k) for k in ("ge", "gt", "le", "lt") if hasattr(m, k)})
        else:
            found.update(bounds(arg))
    return found


def _interval(found: dict[str, float]) -> str:
    """``{"ge": 0, "lt": 1}`` → ``"in [0, 1)"``; ``{"ge": 1}`` → ``"≥ 1"``."""
    low = ("[", found["ge"]) if "ge" in found else ("(", found["gt"]) if "gt" in found else None
    high = ("]", found["le"]) if "le" in found else (")", found["lt"]) if "lt" in found else None
    if low and high:
        return f"in {low[0]}{number(low[1])}, {number(high[1])}{high[0]}"
    if low:
        return f"{'≥' if low[0] == '[' else '>'} {number(low[1])}"
    return f"{'≤' if high[0] == ']' else '<'} {number(high[1])}"  # type: ignore[index]


def choices(cls: type, name: str) -> tuple[str, ...] | None:
    """The values the field ``name`` of ``cls`` takes (its :func:`option` ``choices``), or None: any of its type."""
    found = cls.__dataclass_fields__[name].metadata.get("choices")  # type: ignore[attr-defined]
    return tuple(found()) if callable(found) else found


#: pydantic's error types of a value of the wrong type, and what the value must be instead
_EXPECTED = {"int_type": "an integer", "float_type": "a number", "bool_type": "true or false",
             "string_type": "a string"}


def typed_value(cls: type, name: str, value: Any) -> Any:
    """``value`` of the field ``name`` of ``cls`` as its type (parsed, checked against its bounds and choices).

    Raises:
        ValueError: what the value must be, and the value (``"must be ≥ 1, got 0"``).
    """
    hint = field_type(cls, name)
    try:
        typed = _adapters(cls)[name].validate_python(value)
    except ValidationError as exc:
        error = exc.errors()[0]
        if error["type"] == "value_error":
            problem = str(error["ctx"]["error"])
        elif error["type"] == "finite_number":
            problem = "must be a finite number"
        elif error["type"] in _EXPECTED:
            problem = f"must be {_EXPECTED[error['type']]}" + (" or null" if type(None) in get_args(hint) else "")
        elif error["type"] in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
            problem = f"must be {_interval(bounds(hint))}"
        else:
            problem = error["msg"][0].lower() + error["msg"][1:]
        raise ValueError(f"{problem}, got {value!r}") from None
    allowed = choices(cls, name)
    if allowed is not None and typed is not None and plain_value(cls, name, typed) not in allowed:
        raise ValueError(f"must be one of {', '.join(allowed)}, got {value!r}")
    return typed


def plain_value(cls: type, name: str, value: Any) -> Any:
    """The typed ``value`` of the field ``name`` of ``cls`` as a YAML file spells it (``augment``
    ``"homography,virtual"``, ``image_size`` ``[H, W]``, ...)."""
    return _adapters(cls)[name].dump_python(value)


def read_fields_yaml(cls: type, path: PathLike, renamed: Mapping[str, str] | None = None,
                     what: str = "configuration") -> dict[str, Any]:
    """The fields of ``cls`` in the YAML file ``path`` as typed values (:func:`typed_value`; the file is read with
    :func:`~freespace.io.codecs.load_yaml`, a ``yaml.SafeLoader``: runs no code). Fields may be missing; a key of
    ``renamed`` (an older name) is read as the field it names. ``what`` names such a file in messages.

    Raises:
        InputFileError: no file. CorruptFileError: not YAML, not a mapping, or a key given twice.
        InvalidOptionError: an unknown key, a bad value, or a field given in two spellings (its older name and
            its current one; the message names the file and the keys).
    """
    renamed = renamed or {}
    if Path(path).is_dir():
        raise InputFileError(f"{path} is a folder; name a YAML file, e.g. {Path(path) / 'config.yaml'}")
    if not Path(path).is_file():
        raise missing_input(path, "config file")
    data = load_yaml(path)
    if not isinstance(data, dict):
        raise CorruptFileError(f"{path} is not a freespace {what} (a mapping of options)")
    spelled: dict[str, str] = {}
    for key in data:
        name = renamed.get(key, key)
        if name in spelled:
            raise InvalidOptionError(f"{path}: {spelled[name]} and {key} both give {name} (an older name and the "
                                     f"current one); keep one of them")
        spelled[name] = str(key)
    data = {renamed.get(k, k): v for k, v in data.items()}
    names = [f.name for f in fields(cls)]
    unknown = sorted(str(k) for k in data if k not in names)
    if unknown:
        raise InvalidOptionError(f"{path}: unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                                 f"a {what} has {', '.join(names)}")
    values = {}
    for key, value in data.items():
        try:
            values[key] = typed_value(cls, key, value)
        except ValueError as exc:
            raise InvalidOptionError(f"{path}: {key} {exc}") from None
    return values
