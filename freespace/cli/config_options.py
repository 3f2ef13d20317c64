"""The options of train and reproduce, made from TrainConfig's fields, and train's --config file (read first)."""

from __future__ import annotations

import argparse
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

from freespace.errors import FreespaceError, InvalidOptionError

#: the flags of the :class:`~freespace.engine.config.TrainConfig` fields that are not ``--name-with-dashes``
CONFIG_FLAGS = {"splits_dir": "--splits"}


def config_flag(name: str) -> str:
    """The flag of the :class:`~freespace.engine.config.TrainConfig` field ``name``."""
    return CONFIG_FLAGS.get(name, "--" + name.replace("_", "-"))


class FromFile:
    """The default of an option that ``--config`` gave: its typed ``value``, checked when the file was read
    (and not again: :meth:`~freespace.engine.config.TrainConfig.from_checked`), and its ``text`` for the help."""

    def __init__(self, value: Any, text: Any) -> None:
        self.value, self.text = value, text

    def __str__(self) -> str:
        return str(self.text)


def add_config_options(p: argparse.ArgumentParser, names: Collection[str] | None = None,
                       values: Mapping[str, Any] | None = None, *, checked: bool = False) -> None:
    """An option for each :class:`~freespace.engine.config.TrainConfig` field in ``names`` (default: all), its
    ``dest`` the field's name (so that an error naming the parameter names this flag), with the field's help,
    choices and default; ``values`` (typed) replace the defaults, and a field given there is no longer required
    (``checked``: they are ``--config``'s, whose file checked them: :class:`FromFile`). Flags are passed on as
    given (numbers converted); TrainConfig parses and checks them, as the file's values were."""
    from freespace.engine.options import options

    for o in options(names, values):
        text = FreespaceError(o.help).render(config_flag).replace("%", "%%")  # its parameters as flags
        if o.choices is not None:
            text += f"; one of {', '.join(o.choices)}"
        if o.default is not None and o.default is not False:
            text += "; default %(default)s"
        default = FromFile(values[o.name], o.default) if checked and values and o.name in values else o.default
        kwargs: dict[str, Any] = {"dest": o.name, "default": default, "help": text}
        if o.kind is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs.update(type=o.kind, metavar=o.metavar or ("NAME" if o.choices is not None else None),
                          required=o.required)
        p.add_argument(config_flag(o.name), **kwargs)


def config_values(args: argparse.Namespace, names: Collection[str] | None = None) -> dict[str, Any]:
    """The values of the options :func:`add_config_options` added, by field name."""
    from freespace.engine.options import options

    return {o.name: getattr(args, o.name) for o in options(names)}


def config_file_options(argv: Sequence[str]) -> dict[str, Any] | None:
    """The options in ``--config YAML`` when ``argv`` has one (read before the real parse, as timm does), as
    typed values (:func:`~freespace.engine.config.read_config_yaml`); without one, ``--resume --out RUN`` reads
    the run's own ``RUN/config.yaml``, so that a run resumes from its folder alone."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config", action="append")
    pre.add_argument("--out")
    pre.add_argument("--resume", action="store_true")
    known, _ = pre.parse_known_args(argv)
    if known.config is None:
        if not (known.resume and known.out):
            return None
        saved = Path(known.out) / "config.yaml"
        if not saved.is_file():
            raise InvalidOptionError(f"--resume needs a run folder with config.yaml and checkpoints/last.ckpt; "
                                     f"{known.out} has no config.yaml: give the --out of a run that freespace train "
                                     f"started, or leave out --resume to train anew")
        known.config = [str(saved)]
    if len(known.config) > 1:  # the last would win without a word, as a key given twice in one file would
        raise InvalidOptionError(f"--config is given {len(known.config)} times ({', '.join(known.config)}); give one "
                                 f"file (flags given as well override it)")
    if not known.config[0].strip():
        raise InvalidOptionError("--config is empty; give it a YAML file, or leave it out")
    from freespace.engine.config import read_config_yaml

    return read_config_yaml(known.config[0])
