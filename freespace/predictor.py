"""Trained networks for prediction: :func:`load_checkpoint` and :class:`Predictor` (a checkpoint or an
exported ONNX model → road probabilities at each image's own size).

Used by ``freespace evaluate`` (:mod:`freespace.engine.evaluate`), ``predict``/``export``/``kitti-submit``
(:mod:`freespace.infer`) and ``reproduce``'s figures (:mod:`freespace.experiments.reproduce`). PyTorch is
imported only to read a checkpoint, onnxruntime only to read an ONNX file.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InvalidOptionError
from freespace.io import MAX_IMAGE_SIDE, PathLike, missing_input

if TYPE_CHECKING:
    from freespace.models import SegmentationModel

__all__ = ["load_checkpoint", "Predictor"]


def load_checkpoint(path: PathLike) -> tuple[SegmentationModel, dict[str, Any]]:
    """A network (in eval mode) and its hyper-parameters from a training checkpoint.

    The file is read with ``torch.load(weights_only=True)``: it runs no code.

    Raises:
        InputFileError: the file is missing. CorruptFileError: it is not a freespace training checkpoint.
    """
    import torch

    from freespace.models import create_model

    path = Path(path)
    if not path.is_file():
        raise missing_input(path, "checkpoint")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        hp = ckpt["hyper_parameters"]
        model = create_model(hp["model"], **hp.get("model_options", {}))
        state = {k[len("net."):]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")}
        model.load_state_dict(state)
    except (KeyError, RuntimeError, ValueError, TypeError, EOFError, OSError, pickle.UnpicklingError) as exc:
        raise CorruptFileError(f"{path} is not a freespace training checkpoint ({type(exc).__name__})") from None
    return model.eval(), hp


def _image_size(size: Any, source: PathLike) -> tuple[int, int] | None:
    """The training size ``(H, W)`` a model file states, checked: 1…MAX_IMAGE_SIDE pixels a side."""
    if size is None:
        return None
    if (not isinstance(size, (list, tuple)) or len(size) != 2
            or not all(isinstance(x, int) and not isinstance(x, bool) and 1 <= x <= MAX_IMAGE_SIDE for x in size)):
        raise CorruptFileError(f"{source} states an image size of {size!r}; a freespace model's is [H, W] with "
                               f"1…{MAX_IMAGE_SIDE} pixels a side")
    return int(size[0]), int(size[1])


def _check_onnx_signature(session: Any, path: Path) -> None:
    """Refuse an ONNX model that does not take one N×3×H×W image and give N×C×H×W logits (C ≥ 2)."""
    inputs, outputs = session.get_inputs(), session.get_outputs()
    ok = (len(inputs) == 1 and len(outputs) >= 1 and len(inputs[0].shape) == 4 and inputs[0].shape[1] in (3, "3")
          and "float" in inputs[0].type and len(outputs[0].shape) == 4
          and not (isinstance(outputs[0].shape[1], int) and outputs[0].shape[1] < 2))
    if not ok:
        got = ", ".join(f"{i.name} {i.shape}" for i in inputs)
        raise CorruptFileError(f"{path} is not a freespace road model: its input is {got or 'nothing'}, expected one "
                               f"float image N×3×H×W (export one with freespace export --format onnx)")


class Predictor:
    """Road probabilities from a training checkpoint (PyTorch) or an exported ONNX model (onnxruntime).

    Images are resized to the model's training size (kept in the checkpoint / the ONNX metadata) and the
    probabilities back to each image's own size.
    """

    def __init__(self, checkpoint: PathLike | None = None, onnx: PathLike | None = None) -> None:
        if (checkpoint is None) == (onnx is None):
            raise InvalidOptionError("give exactly one of --checkpoint and --onnx")
        self.image_size: tuple[int, int] | None = None
        if checkpoint is not None:
            self.model, hp = load_checkpoint(checkpoint)
            self.image_size = _image_size(hp.get("image_size"), checkpoint)
            self.name = hp["model"]
            self.session = None
        else:
            import onnxruntime as ort

            path = Path(onnx)  # type: ignore[arg-type]
            if not path.is_file():
                raise missing_input(path, "ONNX model")
            try:
                self.session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
            except Exception as exc:  # onnxruntime raises its own types for corrupt files
                raise CorruptFileError(f"cannot load {path} as an ONNX model ({type(exc).__name__})") from None
            _check_onnx_signature(self.session, path)
            meta = self.session.get_modelmeta().custom_metadata_map
            try:
                size = json.loads(meta["image_size"]) if meta.get("image_size") else None
            except ValueError:
                size = "unreadable"
            self.image_size = _image_size(size, path)
            self.name = meta.get("model", path.stem)
            self.model = None

    def _run(self, batch: np.ndarray) -> np.ndarray:
        if self.session is None:
            import torch

            with torch.no_grad():
                return torch.softmax(self.model(torch.from_numpy(batch)), 1)[:, 1].numpy()
        logits = self.session.run(None, {self.session.get_inputs()[0].name: batch})[0]
        e = np.exp(logits - logits.max(1, keepdims=True))
        return (e[:, 1] / e.sum(1)).astype(np.float32)

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]:
        """Road probability (``float32 H×W`` in [0, 1]) of each ``H×W×3 uint8`` RGB image, at its own size."""
        by_size: dict[tuple[int, int], list[int]] = {}
        resized = []
        for i, img in enumerate(images):
            if img.ndim != 3 or img.shape[2] != 3:
                raise InvalidOptionError(f"expected RGB images, got shape {img.shape}")
            if self.image_size and img.shape[:2] != self.image_size:
                img = cv2.resize(img, (self.image_size[1], self.image_size[0]), interpolation=cv2.INTER_AREA)
            resized.append(img)
            by_size.setdefault(img.shape[:2], []).append(i)
        out: list[np.ndarray | None] = [None] * len(images)
        for idx in by_size.values():
            batch = np.stack([resized[i].transpose(2, 0, 1) for i in idx]).astype(np.float32) / 255.0
            for i, prob in zip(idx, self._run(batch)):
                h, w = images[i].shape[:2]
                out[i] = prob if prob.shape == (h, w) else cv2.resize(prob, (w, h), interpolation=cv2.INTER_LINEAR)
        return out  # type: ignore[return-value]
