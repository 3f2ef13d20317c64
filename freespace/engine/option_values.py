"""The training options whose values are more than a number or a name — ``augment``, pose ranges, ``image_size``,
paths, ``encoder_weights`` — each parsed from the spellings it accepts and written back in one spelling.

Each value type is an annotated type that pydantic (:mod:`freespace.engine.config_yaml`) parses with its
``BeforeValidator`` and writes with its ``PlainSerializer``; the ``parse_*`` functions parse one value outside a
configuration, refusing it in one line that names the parameter.
"""

from __future__ import annotations

import os
import re
from typing import Annotated, Any, Final, Literal

from pydantic import BeforeValidator, PlainSerializer

from freespace.errors import InvalidOptionError, param
from freespace.io.codecs import MAX_IMAGE_SIDE

__all__ = ["AUGMENT_NAMES", "AUGMENTS", "FIRST_FRAME_SIZE", "weights_path", "parse_augment", "augment_text",
           "ranges_text", "parse_size", "number", "Augment", "Ranges", "ImageSize", "PathText", "DatasetName",
           "dataset_choices", "model_choices", "disparity_source_choices"]

#: the augmentations ``augment`` combines, in their one order (duplicate: the step-count control of homography)
AUGMENT_NAMES = ("homography", "virtual", "duplicate")
#: the combinations ``augment`` takes, as config.yaml spells them (``()`` is spelled ``none``)
AUGMENTS = ("none", "homography", "virtual", "homography,virtual", "duplicate")
#: ``image_size`` of a run that takes the size of the first labelled frame (resolved when the run starts;
#: config.yaml spells it ``null``, and ``auto`` is read as it too)
FIRST_FRAME_SIZE: Final = "first-frame"

#: names of encoder weights that are no file (segmentation-models-pytorch's, and the Lite encoders' imagenet)
_WEIGHT_NAME = re.compile(r"[A-Za-z0-9_+-]+")


def weights_path(value: str | None) -> bool:
    """Whether ``encoder_weights`` ``value`` names a file (then config.yaml keeps it resolved and the run
    records its content hash) rather than weights by name (``imagenet``, smp's ``ssl``, ``swsl``, ...): a
    value with a ``/``, a ``.`` or a leading ``~``, or the name of an existing file that is not ``imagenet``."""
    if not value:
        return False
    if not _WEIGHT_NAME.fullmatch(value):
        return True
    return value != "imagenet" and os.path.isfile(value)


# --- the value types: each parses the spellings it accepts and writes its one spelling ------------------


def _augment(value: Any) -> tuple[str, ...]:
    """``augment`` (see :func:`parse_augment`) from its text or a tuple of names; a ValueError says what it
    must be."""
    names = [n.strip() for n in value.split(",") if n.strip()] if isinstance(value, str) else \
        list(value) if isinstance(value, tuple) and all(isinstance(n, str) for n in value) else None
    if names is not None:
        if names == ["none"] or (isinstance(value, tuple) and not names):
            return ()
        tokens = tuple(n for n in AUGMENT_NAMES if n in names)
        if tokens and len(tokens) == len(names) and ",".join(tokens) in AUGMENTS:
            return tokens
    raise ValueError(f"must be one of {', '.join(AUGMENTS)}")


def augment_text(augment: tuple[str, ...]) -> str:
    """The spelling of an ``augment`` value: ``("homography", "virtual")`` → ``"homography,virtual"``,
    ``()`` → ``"none"``."""
    return ",".join(augment) or "none"


def parse_augment(value: str | tuple[str, ...]) -> tuple[str, ...]:
    """``"virtual, homography"`` (or the tuple) → ``("homography", "virtual")``, the names of
    :data:`AUGMENT_NAMES` in their one order; ``"none"`` → ``()``.

    Raises:
        InvalidOptionError: not one of :data:`AUGMENTS` (e.g. ``duplicate``, the control of ``homography``,
            together with ``homography``).
    """
    try:
        return _augment(value)
    except ValueError as exc:
        raise InvalidOptionError(f"{param('augment')} {exc}, got {value!r}") from None


def number(x: float) -> str:
    """The shortest spelling of ``x`` that reads back as ``x`` (``0.0`` → ``"0"``, ``0.5`` → ``"0.5"``; an int
    as itself)."""
    if isinstance(x, int):
        return str(x)
    short = f"{x:g}"
    return short if float(short) == x else repr(x)


def _ranges(value: Any) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
    """Three pose ranges as ``(low, high)`` intervals (:func:`freespace.geometry.pose_ranges`), from
    ``"0.5,-3:0.9,0"`` (``h`` is ±h, ``LO:HI`` an interval) or a sequence of three numbers or pairs."""
    from freespace.geometry.plane import pose_ranges

    if isinstance(value, str):
        items: list[Any] = []
        for part in value.split(","):
            try:
                items.append(tuple(float(x) for x in part.split(":")) if ":" in part else float(part))
            except ValueError:
                items.append(None)
        value = [v if not isinstance(v, tuple) or len(v) == 2 else None for v in items]
    return pose_ranges(value)


def ranges_text(values: tuple[tuple[float, float], ...]) -> str:
    """How config.yaml and messages spell pose ranges (``(low, high)`` intervals, e.g. ``virtual_shift``):
    ``"0.5,-3:0.9,0"``, a symmetric range as its half-range, any other as ``LO:HI``."""
    return ",".join(number(hi) if lo == -hi else f"{number(lo)}:{number(hi)}" for lo, hi in values)


def _size(value: Any) -> tuple[int, int] | str:
    """``"384x1248"`` or ``[384, 1248]`` → ``(384, 1248)`` (height × width); ``None``, ``"auto"`` →
    :data:`FIRST_FRAME_SIZE`."""
    if value is None or (isinstance(value, str) and value.strip().lower() in ("auto", FIRST_FRAME_SIZE)):
        return FIRST_FRAME_SIZE
    pair = None
    if isinstance(value, str):
        m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", value)
        pair = (int(m.group(1)), int(m.group(2))) if m else None
    elif isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(x, int) and not isinstance(x, bool)
                                                                      for x in value):
        pair = (int(value[0]), int(value[1]))
    if pair is None or min(pair) < 32 or max(pair) > MAX_IMAGE_SIDE:
        raise ValueError(f"must be HxW with both in 32…{MAX_IMAGE_SIDE} (e.g. 384x1248)")
    return pair


def _size_plain(size: tuple[int, int] | str) -> list[int] | None:
    return None if size == FIRST_FRAME_SIZE else list(size)


def parse_size(value: str | tuple[int, int] | list[int] | None) -> tuple[int, int] | str:
    """``"384x1248"`` → ``(384, 1248)`` (height × width); ``None`` or ``"auto"`` → :data:`FIRST_FRAME_SIZE`.

    Raises:
        InvalidOptionError: not HxW with both sides in 32…MAX_IMAGE_SIDE.
    """
    try:
        return _size(value)
    except ValueError as exc:
        raise InvalidOptionError(f"{param('image_size')} {exc}, got {value!r}") from None


def _path_text(value: Any) -> Any:
    value = os.fspath(value) if isinstance(value, os.PathLike) else value
    if isinstance(value, str) and not value.strip():  # Path("") is the current folder
        raise ValueError("must be a path, not empty")
    return value


#: ``augment``: a tuple of :data:`AUGMENT_NAMES` (``()`` none), spelled ``"homography,virtual"`` or ``"none"``
Augment = Annotated[tuple[str, ...], BeforeValidator(_augment), PlainSerializer(augment_text)]
#: three pose ranges as ``(low, high)`` intervals (``virtual_shift`` metres, ``virtual_rotate`` degrees), spelled
#: ``"0.5,-3:0.9,0"``
Ranges = Annotated[tuple[tuple[float, float], tuple[float, float], tuple[float, float]], BeforeValidator(_ranges),
                   PlainSerializer(ranges_text)]
#: ``image_size``: (H, W) pixels or :data:`FIRST_FRAME_SIZE`, spelled ``[H, W]`` or ``null``
ImageSize = Annotated[tuple[int, int] | Literal["first-frame"], BeforeValidator(_size),
                      PlainSerializer(_size_plain)]
#: a file or folder name, never empty (``""`` would be the current folder)
PathText = Annotated[str, BeforeValidator(_path_text)]


# --- the choices of named values (read when first offered: the lists import their modules) -------------------


def _layout_name(value: Any) -> Any:
    """A dataset name as its layout's own (``synth`` → ``kitti``): configs written with an alias load as the same
    configuration."""
    from freespace.data.registry import layout_name

    return layout_name(value)


def dataset_choices() -> tuple[str, ...]:
    """The dataset layouts ``dataset`` takes (their own names, no alias)."""
    from freespace.data.registry import list_datasets

    return tuple(list_datasets(aliases=False))


def model_choices() -> tuple[str, ...]:
    """The networks ``model`` takes."""
    from freespace.models import list_models  # imports torch: only called for training

    return tuple(list_models())


def disparity_source_choices() -> tuple[str, ...]:
    """Where ``disparity_source`` takes the DS-Generator's disparities from."""
    from freespace.data.disparity import DISPARITY_SOURCES

    return DISPARITY_SOURCES


#: a dataset layout's name, an alias read as its layout's own
DatasetName = Annotated[str, BeforeValidator(_layout_name)]
