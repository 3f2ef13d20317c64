"""The bounds of the numeric options: each declared once, with its type, and checked before any work.

A number the user gives (a flag, or a value of a training config file) is refused in one line, naming it, when it
is not of its type, not finite, or outside its bounds; a bound says what no real use needs and what would exhaust
the machine or end in a traceback deep inside a library (``islice`` refuses a stop beyond ``sys.maxsize``; a
Python int too large for C ends a process pool; 100 000 loader processes fork the machine to a halt).

* :class:`Bounded` is the type of such an option (``Bounded(int, 1, MAX_BATCH_SIZE)``), for argparse
  (``type=``) and for anything else that parses text; :func:`bounded_int` and :func:`bounded_float` make them.
* The training options' bounds are declared in their pydantic types (:class:`freespace.engine.config.TrainConfig`,
  ``Field(ge=..., le=...)``) from the constants here; the command line derives their types from those fields.
* Worker processes: at most :data:`WORKERS_PER_CORE` per CPU core this process may run on
  (:func:`max_workers`): the work is CPU-bound, so more processes only share the same cores (and memory).

Torch-free: the generate command imports this.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Callable

from freespace.errors import InvalidOptionError, param

__all__ = ["Bounded", "bounded_int", "bounded_float", "usable_cores", "max_workers", "check_workers",
           "WORKERS_PER_CORE", "MAX_WORKERS", "check_threads", "MAX_BATCH_SIZE", "MAX_EPOCHS", "MAX_WEIGHT_DECAY",
           "MAX_DEVICES", "MAX_NODES", "MAX_DISPARITY_PX", "MAX_CURB_HEIGHT_M", "MAX_BASELINE_M", "MAX_NOISE_PX",
           "MAX_LIDAR_FILL_PX", "MAX_INLIER_THRESHOLD_PX", "MAX_FRAME_COUNT", "MAX_POSE", "bounded_triple",
           "MAX_IMAGE_PIXELS",           "MAX_IMAGE_FILE_BYTES", "MAX_SCAN_POINTS", "MIN_BASELINE_M", "MAX_FOCAL_PX"]

#: worker processes per CPU core at most (frame processing and data loading are CPU-bound)
WORKERS_PER_CORE = 4
#: worker processes at most, whatever the machine (a ceiling for values read on another machine)
MAX_WORKERS = 1024
#: frames per network call or training step at most: 1024 frames of 384×1248 RGB are 5.9 GB as float32
MAX_BATCH_SIZE = 1024
#: epochs (and epoch counts: patience, the validation window) at most: the paper's runs take 50, converged ones a few
#: hundred
MAX_EPOCHS = 100_000
#: SGD weight decay at most: an L2 coefficient of 1 already pulls every weight to 0 at each step
MAX_WEIGHT_DECAY = 1.0
#: training devices (GPUs, or CPU processes) per machine, and machines, at most
MAX_DEVICES = 1024
MAX_NODES = 10_000
#: a frame count at most (``max_frames``): more than any road dataset holds
MAX_FRAME_COUNT = 100_000_000
#: the SGBM search range at most, pixels (what the road fits check too)
MAX_DISPARITY_PX = 1024
#: autolabel's smallest step off the road at most, metres (a 1 m step is a wall, not a curb)
MAX_CURB_HEIGHT_M = 1.0
#: a stereo baseline at most, metres (road rigs: 0.1–1.6 m)
MAX_BASELINE_M = 10.0
#: a stereo baseline at least, metres: a calibration that gives less is no stereo rig (or is in other units)
MIN_BASELINE_M = 0.01
#: a focal length at most, pixels (a 1242-pixel-wide image at this focal length sees 0.7 degrees)
MAX_FOCAL_PX = 100_000.0
#: the pixels (W·H) an image file may state in its header at most, checked before it is decoded: 2²⁵, so 8K video
#: (7680×4320) fits, while a 1 MB PNG whose header says 30000×30000 (6 GB decoded) is refused
MAX_IMAGE_PIXELS = 2**25
#: the bytes an image, disparity or depth file may have at most, checked before it is read: MAX_IMAGE_PIXELS
#: pixels of four float32 channels (the largest uncompressed file of an image that may be decoded), and 1 MiB
MAX_IMAGE_FILE_BYTES = MAX_IMAGE_PIXELS * 16 + 2**20
#: the points a LiDAR scan may hold at most, checked from its size before it is read (a KITTI HDL-64E scan holds
#: about 120 000)
MAX_SCAN_POINTS = 4_000_000
#: a disparity noise at most, pixels (beyond it no road fit is meaningful)
MAX_NOISE_PX = 100.0
#: the LiDAR hole filling at most, pixels
MAX_LIDAR_FILL_PX = 1000.0
#: a virtual camera's move (metres) or rotation (degrees) at most, per axis, as the training's pose ranges bound
#: them (:func:`freespace.geometry.pose_ranges`): far beyond it the road homography becomes singular
MAX_POSE = 1e6
#: the road fit's inlier threshold at most, pixels (a residual of 1000 px makes every pixel an inlier)
MAX_INLIER_THRESHOLD_PX = 1000.0
#: the share of a frame's height that ``--crop-top`` may leave out, exclusive (some road must stay in view)
MAX_CROP_TOP = 0.7


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity: the cores a SLURM job was given), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def max_workers() -> int:
    """The most worker processes an option may ask for on this machine: :data:`WORKERS_PER_CORE` per usable
    core (:func:`usable_cores`), at most :data:`MAX_WORKERS`."""
    return min(MAX_WORKERS, WORKERS_PER_CORE * usable_cores())


def check_workers(workers: int, name: str = "workers") -> int:
    """``workers`` if it is at most :func:`max_workers`, else an :class:`InvalidOptionError` naming the
    parameter ``name``."""
    most = max_workers()
    if workers > most:
        raise InvalidOptionError(f"{param(name)} {workers} is more than this machine runs usefully: at most "
                                 f"{most} ({WORKERS_PER_CORE} per CPU core, {usable_cores()} core"
                                 f"{'s' if usable_cores() > 1 else ''} here)")
    return workers


def check_threads(threads: int | None, name: str = "threads") -> int | None:
    """``threads`` (CPU threads a library call may use) when it is None (the default: the usable cores) or an int in
    ``1…``:func:`max_workers`; else an :class:`InvalidOptionError` naming the parameter ``name``, as the command
    line's threads option refuses it (0 is refused, not read as "all cores"; a million would allocate for a million
    threads)."""
    if threads is None:
        return None
    if isinstance(threads, bool) or not isinstance(threads, int):
        raise InvalidOptionError(f"{param(name)} must be a whole number of CPU threads (or None: the usable cores), "
                                 f"got {threads!r}")
    if threads < 1:
        raise InvalidOptionError(f"{param(name)} must be ≥ 1 (None: the usable cores), got {threads}")
    return check_workers(threads, name)


def _number(x: float) -> str:
    if isinstance(x, int):
        return str(x)
    short = f"{x:g}"
    return short if float(short) == x else repr(x)


@dataclass(frozen=True)
class Bounded:
    """The type of a numeric option: ``kind`` (int or float) in ``[low, high]`` (``low_open``/``high_open``:
    the end itself excluded); ``high`` may be a function (a bound of this machine, e.g. :func:`max_workers`),
    ``why`` a note said with the bound. Calling it on text returns the number, or raises
    :class:`InvalidOptionError` with what the value must be (``"must be an integer in 1…1024, got 0"``);
    floats must be finite (no NaN, no infinity, nothing that overflows to one such as ``1e400``)."""

    kind: type
    low: float | None = None
    high: float | Callable[[], float] | None = None
    low_open: bool = False
    high_open: bool = False
    why: str = ""

    @property
    def __name__(self) -> str:  # argparse names a type in its own messages
        return self.kind.__name__

    def upper(self) -> float | None:
        """``high``, evaluated."""
        return self.high() if callable(self.high) else self.high

    def describe(self) -> str:
        """What a value must be, as :class:`~freespace.engine.config.TrainConfig` says it of a YAML value:
        ``"an integer in [1, 1024]"``, ``"in (0, 10)"``, ``"≥ 0"`` (a float is finite in any case)."""
        what = "an integer " if self.kind is int else ""
        low, high = self.low, self.upper()
        if low is not None and high is not None:
            return (f"{what}in {'(' if self.low_open else '['}{_number(low)}, {_number(high)}"
                    f"{')' if self.high_open else ']'}")
        if low is not None:
            return f"{what}{'>' if self.low_open else '≥'} {_number(low)}"
        if high is not None:
            return f"{what}{'<' if self.high_open else '≤'} {_number(high)}"
        return what.strip() or "a finite number"

    def check(self, value: float) -> float:
        """``value`` when it lies within the bounds, else :class:`InvalidOptionError` (``"must be …, got …"``)."""
        low, high = self.low, self.upper()
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
              and (self.kind is not int or float(value).is_integer())
              and (low is None or (value > low if self.low_open else value >= low))
              and (high is None or (value < high if self.high_open else value <= high)))
        if not ok:
            finite = "a finite number " if isinstance(value, float) and not math.isfinite(value) else ""
            raise InvalidOptionError(f"must be {finite}{self.describe()}{f' ({self.why})' if self.why else ''}, "
                                     f"got {value!r}")
        return value

    def __call__(self, text: str) -> int | float:
        value: float
        try:
            value = int(text.strip(), 10) if self.kind is int else float(text)
        except (ValueError, AttributeError):
            raise InvalidOptionError(f"must be {self.describe()}, got {text!r}") from None
        return self.check(value)


def bounded_int(low: int | None = None, high: int | Callable[[], int] | None = None, why: str = "") -> Bounded:
    """The type of an integer option in ``low…high`` (either end None: open)."""
    return Bounded(int, low, high, why=why)


def bounded_float(low: float | None = None, high: float | Callable[[], float] | None = None, *,
                  low_open: bool = False, high_open: bool = False, why: str = "") -> Bounded:
    """The type of a number option (finite) in ``[low, high]``, or the open interval at an end asked for."""
    return Bounded(float, low, high, low_open, high_open, why)


def bounded_triple(most: float) -> Callable[[str], str]:
    """The type of an option of three numbers ``A,B,C`` (a virtual camera's move or rotation), each finite with
    ``|x| < most``; returns the text unchanged (the library parses it)."""
    def triple(text: str) -> str:
        parts = [p for p in text.replace(",", " ").split() if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = []
        if len(values) != 3 or not all(math.isfinite(v) and abs(v) < most for v in values):
            raise InvalidOptionError(f"must be three finite numbers A,B,C, each within ±{_number(most)}, got {text!r}")
        return text
    return triple
