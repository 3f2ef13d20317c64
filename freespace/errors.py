"""Typed errors.

Every error raised for a user mistake derives from :class:`FreespaceError`. Its message is one line
that says what was wrong and how to fix it; the command-line interface prints it and exits with
``exit_code`` (2) instead of showing a traceback.

The library speaks in parameters, the command line in flags. A message names a parameter with
:func:`param` (``f"{param('image_size')} must be HxW"``): ``str(error)`` writes its Python name
(``image_size must be HxW``), and the command line, the one place that knows the flags, writes the option
that set it (``freespace train --image-size`` for ``image_size``, :meth:`FreespaceError.render`).
"""

from __future__ import annotations

import re
import reprlib
from typing import Callable

#: a parameter's name inside a message: NUL-delimited, as no path, argument or option value can hold a NUL
_PARAM = re.compile("\x00([A-Za-z_][A-Za-z0-9_]*)\x00")


def param(name: str) -> str:
    """The parameter ``name`` (a Python identifier, e.g. ``"image_size"``) as it goes into an error message;
    shown as ``name`` by ``str(error)`` and as its flag by the command line (``freespace train --image-size``)."""
    if not name.isidentifier():
        raise ValueError(f"a parameter is named by its Python identifier, got {name!r}")
    return f"\x00{name}\x00"


def render(text: str, spell: Callable[[str], str] = str) -> str:
    """``text`` with every :func:`param` written as ``spell(name)`` (default: the name itself): how a message
    that is no error (a problem :func:`freespace.data.info.dataset_info` lists) names its parameters."""
    return _PARAM.sub(lambda m: spell(m.group(1)), text)


class FreespaceError(Exception):
    """Base class of every error ``freespace`` raises for bad input or bad options."""

    exit_code: int = 2

    def render(self, spell: Callable[[str], str] = str) -> str:
        """The message with every :func:`param` written as ``spell(name)`` (default: the name itself)."""
        return render(super().__str__(), spell)

    def __str__(self) -> str:
        return self.render()


class InputFileError(FreespaceError, FileNotFoundError):
    """A file or folder the user named is missing or cannot be read."""


class CorruptFileError(FreespaceError, ValueError):
    """A file exists but its content cannot be decoded (truncated image, bad PFM header, ...)."""


class ShapeMismatchError(FreespaceError, ValueError):
    """Arrays that must share a size do not (reference vs target, image vs disparity, ...)."""


class InvalidOptionError(FreespaceError, ValueError):
    """An option or argument has a value outside what the function accepts."""


class RoadFitError(FreespaceError, ValueError):
    """The road disparity model cannot be fitted (too few valid road pixels, degenerate geometry)."""


class DatasetError(FreespaceError, ValueError):
    """A dataset tree does not have the expected layout."""


class OutputError(FreespaceError, OSError):
    """An output file or folder cannot be written (permissions, a file where a folder should be, ...)."""


class TrainingError(FreespaceError):
    """Training cannot go on (e.g. the loss became NaN); exit code 1, as for a run that failed."""

    exit_code = 1


#: seeds are 32-bit: NumPy's legacy seeding and Lightning's ``seed_everything`` take no more
MAX_SEED = 2**32 - 1


def check_seed(seed: int, name: str = "seed") -> int:
    """``seed`` if it is an integer in 0…2³²−1, else an :class:`InvalidOptionError` naming the parameter
    ``name``."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise InvalidOptionError(f"{param(name)} must be an integer in 0…{MAX_SEED}, got {seed!r}")
    return seed


def check_choice(value: object, choices: tuple[str, ...], name: str) -> str:
    """``value`` if it is one of the strings ``choices``, else an :class:`InvalidOptionError` naming the parameter
    ``name`` and listing them."""
    if not (isinstance(value, str) and value in choices):
        raise InvalidOptionError(f"{param(name)} must be one of {', '.join(choices)}, got {reprlib.repr(value)}")
    return value


class PretrainedWeightsError(FreespaceError, RuntimeError):
    """Pretrained weights cannot be loaded (no network to download them, or none exist for that configuration)."""


class Terminated(BaseException):
    """The command received ``SIGTERM`` (what SLURM and ``kill`` send; :func:`freespace.cli.main` raises it
    from its handler). Like :class:`KeyboardInterrupt` it is no :class:`Exception`: ``except Exception``
    does not swallow it, while ``finally`` blocks and ``except BaseException`` clean-ups run; the command
    line ends with "terminated" and exit code 143 (128 + 15)."""

    exit_code = 128 + 15
