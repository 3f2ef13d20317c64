"""What the commands' parsers share: the parser class, the dataset and worker options, modes, flag names."""

from __future__ import annotations

import argparse
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from freespace.errors import MAX_SEED, InvalidOptionError, param
from freespace.limits import MAX_CROP_TOP, WORKERS_PER_CORE, bounded_float, bounded_int, max_workers

#: worker processes (generate, autolabel, synth): at most a few per CPU core of this machine
WORKERS = bounded_int(1, max_workers, why=f"{WORKERS_PER_CORE} per CPU core")
SEED = bounded_int(0, MAX_SEED)
#: ``--crop-top``: a share of the frame's height in [0, MAX_CROP_TOP)
CROP_TOP = bounded_float(0, MAX_CROP_TOP, high_open=True)


def number_pair(form: str, what: str) -> Callable[[str], tuple[float, float]]:
    """An argparse type for ``"A,B"`` → ``(A, B)``, two floats; ``form`` (``"MIN,MAX"``) and ``what`` (``"two
    numbers"``) word the one-line usage error. Their bounds are the caller's to check."""

    def pair(text: str) -> tuple[float, float]:
        try:
            a, b = (float(x) for x in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {form} ({what}), got {text!r}") from None
        return a, b

    return pair


class Parser(argparse.ArgumentParser):
    """argparse, except that an argument starting with a minus and a digit, ``inf`` or ``nan`` is a value,
    never an option: ``--shift -1,0,0``, ``--rotate -2,0,0`` and ``--pitches -5,5`` need no ``=`` form (no
    option of this command starts that way). Sub-command parsers are of this class too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\.?\d|inf|nan)", re.IGNORECASE)

    def error(self, message: str) -> Any:  # argparse: NoReturn
        """argparse's own mistakes (a missing required option, an unknown choice or command) end in one line
        like every other user mistake, pointing to the command's help instead of printing the usage."""
        raise InvalidOptionError(f"{message}; see `{self.prog} --help`")

    def _get_value(self, action: argparse.Action, arg_string: str) -> Any:
        """An empty value ('' or blanks: a path that would be the current folder) and a value of an option of this
        package's types (:class:`~freespace.limits.Bounded`: out of its bounds, or no number) are refused in one
        line naming the option (argparse's own message comes with the usage)."""
        if action.option_strings and isinstance(arg_string, str) and not arg_string.strip():  # '' = the current folder
            raise InvalidOptionError(f"{param(action.dest)} is empty; give it a value"
                                     + ("" if action.required else ", or leave it out"))
        if action.type is not None and not isinstance(action.type, type):  # Bounded, a MIN,MAX range: one line
            try:
                return action.type(arg_string)
            except (InvalidOptionError, argparse.ArgumentTypeError) as exc:
                raise InvalidOptionError(f"{param(action.dest)} {exc}") from None
        return super()._get_value(action, arg_string)


def flags_of(parser: argparse.ArgumentParser, argv: Sequence[str]) -> dict[str, str]:
    """``{dest: flag}`` of every option of the (sub-)command ``argv`` runs (``{"image_size": "--image-size"}``):
    how an error's parameters are written on the command line (:meth:`FreespaceError.render`)."""
    flags: dict[str, str] = {}
    words = [a for a in argv if not a.startswith("-")]
    while parser is not None:
        sub = None
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                sub = next((action.choices[w] for w in words if w in action.choices), None)
            longs = [o for o in action.option_strings if o.startswith("--")]
            if longs:
                flags.setdefault(action.dest, longs[0])
        parser = sub
    return flags


def add_dataset_root(p: argparse.ArgumentParser | argparse._ArgumentGroup, required: bool = True,
                     split: bool = True) -> None:
    """``--dataset``, ``--root`` and (optionally) ``--split``, shared by every command that reads a dataset. A
    layout's earlier name (``synth``, ``kitti_road``, ``kitti_raw``, ``syn-stereo``) is read as its name."""
    from freespace.data.registry import layout_name, list_datasets

    p.add_argument("--dataset", choices=list_datasets(aliases=False), required=required, type=layout_name,
                   help="layout: kitti (KITTI road, and the renderer's output: `freespace synth` writes a KITTI road "
                        "tree), kitti-raw (KITTI raw drives), synthia, carla (CARLA exports, e.g. SYN-Stereo), generic")
    p.add_argument("--root", metavar="DIR", required=required, help="dataset folder")
    if split:
        p.add_argument("--split", help="the dataset's on-disk split, a folder it ships (KITTI road: training or "
                                       "testing; default: the first); not train/val/test, which are subsets")


def dataset_of(args: argparse.Namespace, needs_right: str | None = None):  # -> StereoRoadDataset (lazy import)
    """The dataset the options name (:func:`~freespace.data.options.open_dataset`)."""
    from freespace.data.options import open_dataset

    return open_dataset(args.dataset, args.root, args.split, disparity_source=args.disparity_source,
                        cache_dir=args.cache_dir, max_disparity=args.max_disparity, disparity_dir=args.disparity_dir,
                        lidar_densify=args.lidar_densify, needs_right=needs_right)


@dataclass(frozen=True)
class Mode:
    """One of the ways a command runs that share its parser (``generate``: one pair, a dataset or a virtual
    view): the options (argparse ``dest``) that belong to it, those it needs, and how messages call it."""

    what: str
    options: frozenset[str]
    required: tuple[str, ...] = ()
    hint: str = ""


def check_mode(parser: argparse.ArgumentParser, args: argparse.Namespace, modes: Mapping[str, Mode],
               chosen: str) -> None:
    """Refuse, in one line, the options of the other ``modes`` given (not at their default) to the
    ``chosen`` one, then the options ``chosen`` needs and lacks. An option of no mode belongs to all."""
    mode = modes[chosen]
    others = set().union(*(m.options for m in modes.values())) - mode.options
    flags = flags_of(parser, [])
    given = [a.dest for a in parser._actions if a.dest in others and a.option_strings
             and getattr(args, a.dest) != a.default]
    if given:
        owners = " or ".join(m.what for m in modes.values() if m.options & set(given))
        raise InvalidOptionError(f"{', '.join(flags[d] for d in given)} {'is' if len(given) == 1 else 'are'} for "
                                 f"{owners}, not for {mode.what}; leave {'it' if len(given) == 1 else 'them'} out")
    missing = [flags[d] for d in mode.required if getattr(args, d) in (None, False)]
    if missing:
        raise InvalidOptionError(f"{mode.what} needs {', '.join(missing)}{mode.hint} (see --help)")


def refuse_folders(args: argparse.Namespace, names: Sequence[str]) -> None:
    """Refuse a folder given to an option that reads one file (``names``: argparse ``dest``), first: later checks
    would blame something else (an output inside that "input folder")."""
    from freespace.errors import InputFileError

    for name in names:
        value = getattr(args, name, None)
        if value is not None and os.path.isdir(value):
            raise InputFileError(f"{param(name)} {value} is a folder; give a file")


def run_dataset(args: argparse.Namespace, run: Callable[..., dict[str, Any]], options: Any, done: str,
                needs_right: str | None = None) -> int:
    """The dataset mode of ``generate`` and ``autolabel``: ``run`` (``generate_with_labels``, ``autolabel_dataset``)
    over the dataset the options name, then one line of counts (``summary[done]`` frames made) and one per
    failed frame; exit code 1 when a frame failed."""
    from freespace.datagen.runner import run_report
    from freespace.runtime.shard import parse_shard

    shard = parse_shard(args.shard) if args.shard is not None else None
    summary = run(dataset_of(args, needs_right), args.out, workers=args.workers, options=options,
                  overwrite=args.overwrite, shard=shard)
    flags = flags_of(args.parser, [])  # this run's failures name flags, not parameters
    print(run_report(summary, done, args.out, args.shard if shard else None, lambda n: flags.get(n, n)))
    return 1 if summary["failed"] else 0
