"""The weights a training run starts from: a model's (fine-tuning, ``freespace train`` with ``init``), or encoder
weights that are checked to load (:func:`check_encoder`).

``init`` names a model folder (``models/real-road-fast``: its ``model.ckpt``) or a training checkpoint. The run
takes the init's network, its options and its input size (:func:`resolve_init`: an explicit other network or
size is refused), and starts from every one of its weights, batch-norm statistics included (``models/real-road-fast``
ships its training checkpoint's; a checkpoint rebuilt from an ONNX file, as ``models/real-road-unet``'s, has them the
identity, the normalisation folded into its convolutions; ``freeze`` ``norm`` keeps them as they are).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, param
from freespace.io.files import PathLike
from freespace.io.frame_fit import check_resize

__all__ = ["InitWeights", "init_checkpoint", "read_init", "teacher_network", "resolve_init", "check_encoder",
           "CHECKPOINT"]

#: the checkpoint of a model folder
CHECKPOINT = "model.ckpt"


@dataclass(frozen=True)
class InitWeights:
    """A run's starting weights: the checkpoint's ``path``, its network's weights (``state``: names without the
    ``net.`` prefix, as the network names them) and its ``hp`` (``model``, ``model_options``, ``image_size``)."""

    path: Path
    state: dict[str, Any]
    hp: dict[str, Any]

    def image_size(self) -> tuple[int, int] | None:
        """The (H, W) the init was trained at, or None when its checkpoint does not say."""
        size = self.hp.get("image_size")
        return (int(size[0]), int(size[1])) if size else None


def init_checkpoint(init: PathLike, option: str = "init") -> Path:
    """The checkpoint that ``init`` names: a model folder's :data:`CHECKPOINT`, or the file itself; ``option``: the
    parameter that named it, for the messages (``init`` or ``teacher``).

    Raises:
        InputFileError: nothing at ``init``, or a folder without :data:`CHECKPOINT`.
    """
    path = Path(init)
    if path.is_dir():
        ckpt = path / CHECKPOINT
        if not ckpt.is_file():
            raise InputFileError(f"{param(option)} {path} is a folder without {CHECKPOINT}; give a model folder "
                                 f"(models/real-road-fast) or a training checkpoint (RUN/checkpoints/best.ckpt)")
        return ckpt
    if not path.is_file():
        raise InputFileError(f"{param(option)} not found: {path} (a model folder or a .ckpt file)")
    return path


def teacher_network(teacher: PathLike) -> Any:
    """The network of ``teacher`` (a model folder or a training checkpoint, as ``init``; read with
    ``torch.load(weights_only=True)``), in eval mode with its gradients off: a ``torch.nn.Module`` that maps an
    ``N×3×H×W`` batch (RGB in [0, 1], as training feeds the network) to ``N×2×H×W`` logits (not road, road).

    Raises:
        InputFileError: nothing at ``teacher``. CorruptFileError: not a freespace checkpoint, or weights that do
            not fit the network it names.
    """
    from freespace.inference.predictor import rebuild_model

    found = read_init(teacher, "teacher")  # the file TrainConfig.check read, not read again
    net = rebuild_model(found.hp["model"], found.hp["model_options"], found.path)
    net.load_state_dict(found.state)
    return net.eval().requires_grad_(False)


def read_init(init: PathLike, option: str = "init") -> InitWeights:
    """The weights and hyper-parameters of ``init`` (:func:`init_checkpoint`), read with
    ``torch.load(weights_only=True)`` (no code runs), checked to rebuild their network; read once per process
    for an unchanged file.

    Raises:
        InputFileError: nothing there. CorruptFileError: not a freespace checkpoint, or weights that do not fit
            the network it names, or an input size that is not two positive sides.
    """
    path = init_checkpoint(init, option).resolve()
    st = path.stat()
    return _read(path, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def _read(path: Path, mtime: int, size: int) -> InitWeights:
    from freespace.inference.predictor import load_checkpoint
    from freespace.io.codecs import MAX_IMAGE_SIDE, MIN_FRAME_SIDE

    net, hp = load_checkpoint(path)
    image_size = hp.get("image_size")
    sides = range(MIN_FRAME_SIDE, MAX_IMAGE_SIDE + 1)
    if image_size is not None and not (isinstance(image_size, (list, tuple)) and len(image_size) == 2
                                       and all(isinstance(v, int) and v in sides for v in image_size)):
        raise CorruptFileError(f"{path} states the input size {image_size!r}; a checkpoint's image_size is [H, W], "
                               f"{MIN_FRAME_SIDE} to {MAX_IMAGE_SIDE} pixels a side")
    return InitWeights(path, {k: v.detach().clone() for k, v in net.state_dict().items()},
                       {"model": hp["model"], "model_options": dict(hp.get("model_options") or {}),
                        "image_size": list(image_size) if image_size else None,
                        "resize": check_resize(hp.get("resize", "stretch"), "init")})


def resolve_init(config: Any) -> Any:
    """``config`` (a :class:`~freespace.engine.config.TrainConfig`) with the network and image size of its
    ``init`` (itself without one): a network, preset, encoder or image size given that differs from the init's is
    refused, as are encoder weights (the init gives every weight).

    Raises:
        InvalidOptionError: an option that contradicts the init. InputFileError, CorruptFileError: as
            :func:`read_init`.
    """
    if config.init is None:
        return config
    from freespace.engine.option_values import FIRST_FRAME_SIZE

    weights = read_init(config.init)
    if config.encoder_weights is not None:
        raise InvalidOptionError(f"{param('init')} gives every weight; leave out {param('encoder_weights')}")
    defaults = type(config).__dataclass_fields__
    theirs = {"model": weights.hp["model"], "encoder_name": weights.hp["model_options"].get("encoder_name"),
              "resize": weights.hp["resize"]}
    for key, value in theirs.items():
        mine = getattr(config, key)
        if mine != defaults[key].default and mine != value:
            raise InvalidOptionError(f"{param('init')} {config.init} is a {weights.hp['model']} "
                                     f"({key} {value}); {param(key)} {mine} contradicts it: leave it out")
    size = weights.image_size()
    if config.image_size != FIRST_FRAME_SIZE and size is not None and tuple(config.image_size) != size:
        raise InvalidOptionError(f"{param('init')} {config.init} was trained at {size[0]}x{size[1]} (HxW); "
                                 f"{param('image_size')} {config.image_size[0]}x{config.image_size[1]} would change "
                                 f"what its weights see: leave it out")
    return replace(config, **theirs, image_size=size if size is not None else config.image_size)


def check_encoder(model: str, preset: str, encoder_name: str | None, encoder_weights: str | None) -> None:
    """Refuse a network's ``encoder_name``/``encoder_weights`` that the network does not take or that cannot be
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
