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

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError
from freespace.io import PathLike

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
        raise InputFileError(f"checkpoint not found: {path}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        hp = ckpt["hyper_parameters"]
        model = create_model(hp["model"], **hp.get("model_options", {}))
        state = {k[len("net."):]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")}
        model.load_state_dict(state)
    except (KeyError, RuntimeError, ValueError, TypeError, EOFError, OSError, pickle.UnpicklingError) as exc:
        raise CorruptFileError(f"{path} is not a freespace training checkpoint ({type(exc).__name__})") from None
    return model.eval(), hp


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
            self.image_size = tuple(hp["image_size"]) if hp.get("image_size") else None
            self.name = hp["model"]
            self.session = None
        else:
            import onnxruntime as ort

            path = Path(onnx)  # type: ignore[arg-type]
            if not path.is_file():
                raise InputFileError(f"ONNX model not found: {path}")
            try:
                self.session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
            except Exception as exc:  # onnxruntime raises its own types for corrupt files
                raise CorruptFileError(f"cannot load {path} as an ONNX model ({type(exc).__name__})") from None
            meta = self.session.get_modelmeta().custom_metadata_map
            self.image_size = tuple(json.loads(meta["image_size"])) if meta.get("image_size") else None
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
