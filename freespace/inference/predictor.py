"""Trained networks for prediction: :func:`load_checkpoint` and :class:`Predictor` (a checkpoint or an
exported ONNX model → road probabilities at each image's own size).

Used by ``freespace evaluate`` (:mod:`freespace.inference.evaluate`), ``predict``/``export``/``kitti-submit``
(:mod:`freespace.inference.predict`) and ``reproduce``'s figures (:mod:`freespace.experiments.reproduce`). PyTorch is
imported only to read a checkpoint, onnxruntime only to read an ONNX file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from freespace.errors import CorruptFileError, FreespaceError, InvalidOptionError, param
from freespace.io.codecs import MAX_IMAGE_SIDE
from freespace.io.files import PathLike, missing_input

if TYPE_CHECKING:
    import torch

    from freespace.models import SegmentationModel

__all__ = ["load_checkpoint", "read_checkpoint_file", "checkpoint_state_dict", "rebuild_model", "check_weights",
           "Predictor", "session_options", "machine_threads"]


def read_checkpoint_file(path: PathLike) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU: a checkpoint runs no code. A damaged or crafted
    file (pickle, zip or torch errors) ends in one :class:`CorruptFileError` line."""
    import warnings

    import torch

    try:
        with warnings.catch_warnings():  # torch warns about the pickle protocol of crafted files
            warnings.simplefilter("ignore")
            return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # pickle, zip and torch errors: the file is not a plain checkpoint
        raise CorruptFileError(f"{path} is not a freespace training checkpoint, or is damaged "
                               f"({type(exc).__name__}); it was not loaded") from None


def load_checkpoint(path: PathLike) -> tuple[SegmentationModel, dict[str, Any]]:
    """A network (in eval mode) and its hyper-parameters from a training checkpoint.

    The file is read with ``torch.load(weights_only=True)``: it runs no code. The network is rebuilt
    without pretrained weights (``encoder_weights=None``: the checkpoint holds every weight, and no
    network access is needed), then the checkpoint's weights are loaded into it.

    Raises:
        InputFileError: the file is missing. CorruptFileError: it is not a freespace training checkpoint,
        or its weights do not fit the network (the message says which).
    """
    path = Path(path)
    if not path.is_file():
        raise missing_input(path, "checkpoint")
    ckpt = read_checkpoint_file(path)
    state = checkpoint_state_dict(ckpt, path)
    hp = ckpt.get("hyper_parameters")
    if not isinstance(hp, dict) or not isinstance(hp.get("model"), str) \
            or not isinstance(hp.get("model_options", {}), dict):
        raise CorruptFileError(f"{path} is not a freespace training checkpoint (no network name and options in "
                               f"its hyper_parameters)")
    model = rebuild_model(hp["model"], hp.get("model_options", {}), path)
    state = {k[len("net."):]: v for k, v in state.items() if k.startswith("net.")}
    check_weights(model, state, path)
    model.load_state_dict(state)
    return model.eval(), hp


def checkpoint_state_dict(ckpt: Any, path: PathLike) -> dict[str, Any]:
    """The ``state_dict`` of a loaded checkpoint, checked: a mapping of parameter names to finite tensors.

    Raises:
        CorruptFileError: ``ckpt`` is not a mapping with such a ``state_dict``.
    """
    import torch

    state = ckpt.get("state_dict") if isinstance(ckpt, dict) else None
    if not isinstance(state, dict):
        raise CorruptFileError(f"{path} is not a freespace training checkpoint (no state_dict mapping of weights)")
    for k, v in state.items():
        if not isinstance(k, str) or not isinstance(v, torch.Tensor):
            raise CorruptFileError(f"{path} is not a freespace training checkpoint (its state_dict maps {k!r} to a "
                                   f"{type(v).__name__}, not a tensor)")
        if v.is_floating_point() and not bool(torch.isfinite(v).all()):
            raise CorruptFileError(f"{path} holds non-finite weights ({k} has NaN or infinity); it cannot predict")
    return state


def rebuild_model(name: str, options: dict[str, Any], path: PathLike) -> SegmentationModel:
    """The network ``name`` with ``options`` as a checkpoint states them, built without pretrained weights
    (whatever ``encoder_weights`` the options ask for: the checkpoint's own weights replace them).

    Raises:
        CorruptFileError: an unknown network, preset or option, or a bad option value.
    """
    from freespace.models import create_model, model_options

    try:
        if "encoder_weights" in model_options(name):
            options = {**options, "encoder_weights": None}
        return create_model(name, **options)
    except (FreespaceError, TypeError, ValueError, RuntimeError, MemoryError) as exc:  # also absurd sizes
        raise CorruptFileError(f"{path} names a network freespace cannot build "
                               f"({str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__})") from None


def check_weights(model: torch.nn.Module, state: dict[str, Any], path: PathLike) -> None:
    """Check that ``state`` has exactly the names of ``model``'s weights, each of the same shape (what a
    strict ``load_state_dict`` needs), before loading it.

    Raises:
        CorruptFileError: names missing or unexpected, or tensors of another shape; the message counts
        them and names the first.
    """
    own = model.state_dict()
    missing = [k for k in own if k not in state]
    unexpected = [k for k in state if k not in own]
    shapes = [k for k in own if k in state and tuple(state[k].shape) != tuple(own[k].shape)]
    if missing or unexpected or shapes:
        first = (f"first missing: {missing[0]}" if missing else f"first unexpected: {unexpected[0]}" if unexpected
                 else f"{shapes[0]} is {tuple(state[shapes[0]].shape)}, expected {tuple(own[shapes[0]].shape)}")
        raise CorruptFileError(f"{path}: its weights do not fit the network ({len(missing)} missing, "
                               f"{len(unexpected)} unexpected, {len(shapes)} of another shape; {first})")


def _image_size(size: Any, source: PathLike) -> tuple[int, int] | None:
    """The training size ``(H, W)`` a model file states, checked: 1…MAX_IMAGE_SIDE pixels a side."""
    if size is None:
        return None
    if (not isinstance(size, (list, tuple)) or len(size) != 2
            or not all(isinstance(x, int) and not isinstance(x, bool) and 1 <= x <= MAX_IMAGE_SIDE for x in size)):
        raise CorruptFileError(f"{source} states an image size of {size!r}; a freespace model's is [H, W] with "
                               f"1…{MAX_IMAGE_SIDE} pixels a side")
    return int(size[0]), int(size[1])


_EXPORT_HINT = "export one with freespace export --format onnx"


def machine_threads() -> int:
    """The CPU cores this process may run on (``os.sched_getaffinity``: a container's or ``taskset``'s share,
    not the machine's count), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def session_options(threads: int | None = None) -> Any:
    """ONNX Runtime session options for prediction on the CPU: every graph optimisation (``ORT_ENABLE_ALL``:
    constant folding, node fusions such as Conv+BN+ReLU, layout changes), ``threads`` intra-op threads
    (None: :func:`machine_threads`), one inter-op thread, and no spinning of idle worker threads, so that a
    pipeline's reader and writer threads get the cores while the network waits for its next batch.

    Raises:
        InvalidOptionError: ``threads`` < 1.
    """
    import onnxruntime as ort

    if threads is not None and threads < 1:
        raise InvalidOptionError(f"{param('threads')} must be ≥ 1, got {threads}")
    options = ort.SessionOptions()
    options.log_severity_level = 4  # its failures become one-line errors here, not log lines
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads or machine_threads()
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return options


def _check_onnx_signature(session: Any, path: Path) -> None:
    """Refuse an ONNX model that does not take one float32 N×3×H×W image, or does not give N×C×H×W
    logits (C ≥ 2) first; the message says whether the input or the output is wrong."""
    inputs, outputs = session.get_inputs(), session.get_outputs()
    if len(inputs) != 1 or len(inputs[0].shape) != 4 or inputs[0].shape[1] not in (3, "3") \
            or inputs[0].type != "tensor(float)":
        got = ", ".join(f"{i.name} {i.shape} {i.type}" for i in inputs)
        raise CorruptFileError(f"{path} is not a freespace road model: its input is {got or 'nothing'}, expected one "
                               f"float32 image N×3×H×W ({_EXPORT_HINT})")
    first = outputs[0] if outputs else None
    if first is None or len(first.shape) != 4 or (isinstance(first.shape[1], int) and first.shape[1] < 2):
        got = f"{first.name} {first.shape}" if first is not None else "nothing"
        raise CorruptFileError(f"{path} is not a freespace road model: its output is {got}, expected N×C×H×W "
                               f"class scores with C ≥ 2 (non-road, road) ({_EXPORT_HINT})")


def _fixed(dim: Any) -> int | None:
    """An ONNX input dimension as a number when the model fixes it, else None (a name or unknown)."""
    return dim if isinstance(dim, int) and not isinstance(dim, bool) and dim > 0 else None


class Predictor:
    """Road probabilities from a training checkpoint (PyTorch; on the GPU when this machine has one) or an
    exported ONNX model (onnxruntime, on the CPU).

    Images are resized to ``resize_to``, the model's training size (H, W) kept in the checkpoint / the ONNX
    metadata, and the probabilities back to each image's own size; a model that states none has ``resize_to``
    None: each image goes to the network at its own size. An ONNX model whose input height and width are
    fixed gets its images resized to that size (whatever its metadata says: it takes no other), and one
    whose batch size is fixed gets batches of that size (the last padded).

    A model trained at a reduced size thus runs at that size on larger frames: the probabilities are
    upsampled bilinearly to the frame's size before any threshold (a mask at the input's size). The three
    steps of :meth:`predict` are also callable apart, so that a pipeline runs them in different threads:
    :meth:`prepare` (resize, scale to [0, 1], CHW), :meth:`infer` (the network) and :meth:`restore` (back to
    the frame's size). ``threads``: the network's CPU threads (≥ 1; None: the cores this process may use):
    ONNX Runtime's intra-op threads (:func:`session_options`), or with a checkpoint PyTorch's
    (``torch.set_num_threads``, which holds for the whole process).
    """

    def __init__(self, checkpoint: PathLike | None = None, onnx: PathLike | None = None,
                 threads: int | None = None) -> None:
        if (checkpoint is None) == (onnx is None):
            raise InvalidOptionError(f"give exactly one of {param('checkpoint')} and {param('onnx')}")
        self.resize_to: tuple[int, int] | None = None
        self.path = Path(checkpoint if checkpoint is not None else onnx)  # type: ignore[arg-type]
        if checkpoint is not None:
            import torch

            if threads is not None:
                if threads < 1:
                    raise InvalidOptionError(f"{param('threads')} must be ≥ 1, got {threads}")
                torch.set_num_threads(threads)
            self.model, hp = load_checkpoint(checkpoint)
            self.device = "cuda" if torch.cuda.is_available() else "cpu"
            self.model.to(self.device)
            self.resize_to = _image_size(hp.get("image_size"), checkpoint)
            self.name = hp["model"]
            self.session, self.batch = None, None
        else:
            import onnxruntime as ort

            path = Path(onnx)  # type: ignore[arg-type]
            if not path.is_file():
                raise missing_input(path, "ONNX model")
            try:
                self.session = ort.InferenceSession(str(path), session_options(threads),
                                                    providers=["CPUExecutionProvider"])
            except Exception as exc:  # onnxruntime raises its own types for corrupt files
                raise CorruptFileError(f"cannot load {path} as an ONNX model ({type(exc).__name__})") from None
            _check_onnx_signature(self.session, path)
            meta = self.session.get_modelmeta().custom_metadata_map
            try:
                size = json.loads(meta["image_size"]) if meta.get("image_size") else None
            except ValueError:
                size = "unreadable"
            shape = self.session.get_inputs()[0].shape
            fixed = (_fixed(shape[2]), _fixed(shape[3]))
            if all(fixed):
                size = list(fixed)
            elif any(fixed):
                raise CorruptFileError(f"{path} fixes one side of its input only ({shape}); freespace resizes images "
                                       f"to a fixed height and width, or to none ({_EXPORT_HINT})")
            self.resize_to = _image_size(size, path)
            self.batch = _fixed(shape[0])
            self.name = meta.get("model", path.stem)
            self.model = None

    def _run(self, batch: np.ndarray) -> np.ndarray:
        """Road probabilities (``float32 N×h×w``) of a prepared batch (``float32 N×3×h×w``).

        Raises:
            CorruptFileError: the network fails on it, or gives scores of another shape or not finite.
        """
        if self.session is None:
            import torch

            with torch.no_grad():
                logits = self.model(torch.from_numpy(batch).to(self.device))
                self._check_finite(bool(torch.isfinite(logits).all()), batch)
                return torch.softmax(logits, 1)[:, 1].cpu().numpy()
        n = len(batch)
        if self.batch is not None and n != self.batch:  # a fixed batch size: chunks of it, the last padded
            chunks = [batch[i:i + self.batch] for i in range(0, n, self.batch)]
            chunks[-1] = np.concatenate([chunks[-1], np.zeros((self.batch - len(chunks[-1]), *batch.shape[1:]),
                                                              batch.dtype)])
            return np.concatenate([self._run(c) for c in chunks])[:n]
        try:
            logits = self.session.run(None, {self.session.get_inputs()[0].name: batch})[0]
        except Exception as exc:  # onnxruntime's own error types: the graph cannot run on this input
            raise CorruptFileError(f"the ONNX model {self.path} failed on a batch of {n}×3×{batch.shape[2]}×"
                                   f"{batch.shape[3]} images: {str(exc).splitlines()[0][:200]}") from None
        if logits.ndim != 4 or logits.shape[0] != n or logits.shape[1] < 2:
            raise CorruptFileError(f"the ONNX model {self.path} gave {list(logits.shape)} for {n} images, expected "
                                   f"{n}×C×H×W class scores with C ≥ 2 ({_EXPORT_HINT})")
        self._check_finite(bool(np.isfinite(logits).all()), batch)
        e = np.exp(logits - logits.max(1, keepdims=True))
        return (e[:, 1] / e.sum(1)).astype(np.float32)

    def _check_finite(self, finite: bool, batch: np.ndarray) -> None:
        """Refuse the model when its class scores for ``batch`` (``N×3×h×w``) were not all ``finite``: NaN or
        infinity gives no road probability (it would be written as a mask of no road)."""
        if not finite:
            raise CorruptFileError(f"the model {self.path} gave NaN or infinite class scores on a batch of "
                                   f"{len(batch)}×3×{batch.shape[2]}×{batch.shape[3]} images, so it predicts no road "
                                   f"probability; it is broken (e.g. an overflow): train or export it anew")

    def prepare(self, image: np.ndarray) -> np.ndarray:
        """The network's input for one ``H×W×3 uint8`` RGB image: ``float32 3×h×w`` in [0, 1], resized to
        :attr:`resize_to` (area interpolation) when the model states a size.

        Raises:
            InvalidOptionError: the image is not H×W×3.
        """
        if image.ndim != 3 or image.shape[2] != 3:
            raise InvalidOptionError(f"expected RGB images, got shape {image.shape}")
        if self.resize_to is not None and image.shape[:2] != self.resize_to:
            image = cv2.resize(image, (self.resize_to[1], self.resize_to[0]), interpolation=cv2.INTER_AREA)
        return image.transpose(2, 0, 1).astype(np.float32) / 255.0

    def infer(self, inputs: list[np.ndarray]) -> list[np.ndarray]:
        """Road probabilities (``float32 h×w``) of prepared inputs (:meth:`prepare`), at the network's size;
        inputs of one size go through the network together."""
        by_size: dict[tuple[int, ...], list[int]] = {}
        for i, x in enumerate(inputs):
            by_size.setdefault(x.shape, []).append(i)
        out: list[np.ndarray | None] = [None] * len(inputs)
        for idx in by_size.values():
            for i, prob in zip(idx, self._run(np.stack([inputs[i] for i in idx]))):
                out[i] = prob
        return out  # type: ignore[return-value]

    @staticmethod
    def restore(prob: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """``prob`` (``float32 h×w``) at ``size`` = (H, W): bilinear on the probabilities (a threshold after it
        gives a smooth mask boundary, not the network's blocks)."""
        h, w = size
        return prob if prob.shape == (h, w) else cv2.resize(prob, (w, h), interpolation=cv2.INTER_LINEAR)

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]:
        """Road probability (``float32 H×W`` in [0, 1]) of each ``H×W×3 uint8`` RGB image, at its own size."""
        probs = self.infer([self.prepare(img) for img in images])
        return [self.restore(p, img.shape[:2]) for p, img in zip(probs, images)]
