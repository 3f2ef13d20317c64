"""Trained networks for prediction: :func:`load_checkpoint` and :class:`Predictor` (a checkpoint or an
exported ONNX model → road probabilities at each image's own size).

Used by ``freespace evaluate`` (:mod:`freespace.inference.evaluate`), ``predict``/``export``/``kitti-submit``
(:mod:`freespace.inference.predict`) and ``reproduce``'s figures (:mod:`freespace.experiments.reproduce`). PyTorch is
imported only to read a checkpoint, onnxruntime only to read an ONNX file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from freespace.errors import CorruptFileError, FreespaceError, InvalidOptionError, param
from freespace.io.codecs import MAX_IMAGE_SIDE
from freespace.io.files import PathLike, missing_input, unicode_name
from freespace.io.frame_fit import RESIZE_MODES, fit, unfit
from freespace.limits import MAX_BATCH_SIZE, MAX_CROP_TOP, check_threads, usable_cores

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
    not the machine's count), at least 1 (:func:`freespace.limits.usable_cores`)."""
    return usable_cores()


def session_options(threads: int | None = None) -> Any:
    """ONNX Runtime session options for prediction on the CPU: every graph optimisation (``ORT_ENABLE_ALL``:
    constant folding, node fusions such as Conv+BN+ReLU, layout changes), ``threads`` intra-op threads
    (None: :func:`machine_threads`), one inter-op thread, and no spinning of idle worker threads, so that a
    pipeline's reader and writer threads get the cores while the network waits for its next batch.

    Raises:
        InvalidOptionError: ``threads`` is not None or a whole number in 1…:func:`~freespace.limits.max_workers`
            (:func:`~freespace.limits.check_threads`: 0 is refused, not read as "all cores"), checked first.
    """
    check_threads(threads)
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.log_severity_level = 4  # its failures become one-line errors here, not log lines
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads if threads is not None else machine_threads()
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


def _resize_mode(mode: Any, source: PathLike) -> str:
    """The way a model's frames are fitted to its input (:data:`~freespace.io.frame_fit.RESIZE_MODES`), as its
    checkpoint or ONNX metadata records it (models before the record: ``stretch``).

    Raises:
        CorruptFileError: a record that names no such way.
    """
    if mode not in RESIZE_MODES:
        raise CorruptFileError(f"{source} records the input fit {mode!r}; freespace knows {', '.join(RESIZE_MODES)}")
    return mode


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
    the frame's size). ``threads``: the network's CPU threads (None: the cores this process may use; else a whole
    number in 1…:func:`~freespace.limits.max_workers`, checked before anything else: 0 is refused, not read as
    "all cores"): ONNX Runtime's intra-op threads (:func:`session_options`), or with a checkpoint PyTorch's
    (``torch.set_num_threads``, which holds for the whole process).

    The images it takes (:meth:`predict`, :meth:`prepare`) are RGB, ``H×W×3`` (grey ``H×W`` ones are repeated to
    three channels, as :mod:`freespace.io.video` does), of one of three pixel types: ``uint8`` (0…255), ``uint16``
    (0…65535, scaled by 1/65535) or float (values in [0, 1]); see :meth:`predict`.

    ``tta`` (test-time augmentation): each frame is seen as ``freespace adapt``'s teacher sees it, its light
    normalised (:func:`~freespace.data.photometry.normalise_light`, at the network's size) and the probability
    averaged with that of its mirror image (mirrored back): two passes of the network a frame, and the road found
    in frames darker or lighter than the model's training frames.

    ``crop_top`` (a fraction of the height in [0, :data:`~freespace.limits.MAX_CROP_TOP`); 0: off): the top
    ``round(crop_top × H)`` rows of each frame, above the horizon of a fixed camera, are left out of the network's
    input and scored 0 (not road); the rest is resized to ``resize_to`` as a whole frame would be, so the road fills
    more of the input (a region of interest).
    """

    def __init__(self, checkpoint: PathLike | None = None, onnx: PathLike | None = None,
                 threads: int | None = None, tta: bool = False, crop_top: float = 0.0) -> None:
        check_threads(threads)
        if not isinstance(tta, bool):
            raise InvalidOptionError(f"{param('tta')} is True or False, got {tta!r}")
        if isinstance(crop_top, bool) or not isinstance(crop_top, (int, float)) or not 0 <= crop_top < MAX_CROP_TOP:
            raise InvalidOptionError(f"{param('crop_top')} is a fraction of the frame's height in "
                                     f"[0, {MAX_CROP_TOP}), got {crop_top!r}")
        self.tta, self.crop_top = tta, float(crop_top)
        if (checkpoint is None) == (onnx is None):
            raise InvalidOptionError(f"give exactly one of {param('checkpoint')} and {param('onnx')}")
        self.resize_to: tuple[int, int] | None = None
        self.path = Path(checkpoint if checkpoint is not None else onnx)  # type: ignore[arg-type]
        if checkpoint is not None:
            import torch

            if threads is not None:
                torch.set_num_threads(threads)
            self.model, hp = load_checkpoint(checkpoint)
            self.device = "cuda" if torch.cuda.is_available() else "cpu"
            self.model.to(self.device)
            self.resize_to = _image_size(hp.get("image_size"), checkpoint)
            self.resize = _resize_mode(hp.get("resize", "stretch"), checkpoint)
            self.name = hp["model"]
            self.session, self.batch = None, None
        else:
            import onnxruntime as ort

            path = Path(onnx)  # type: ignore[arg-type]
            if not path.is_file():
                raise missing_input(path, "ONNX model")
            try:  # a name that is no valid Unicode (bytes that are not UTF-8): its bytes, which onnxruntime takes
                self.session = ort.InferenceSession(str(path) if unicode_name(str(path)) else path.read_bytes(),
                                                    session_options(threads), providers=["CPUExecutionProvider"])
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
            self.resize = _resize_mode(meta.get("resize", "stretch"), path)
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
        """The network's input for one RGB image (``H×W×3`` or grey ``H×W``: ``uint8``, ``uint16`` or float in
        [0, 1], as :meth:`predict` takes them): ``float32 3×h×w`` in [0, 1], resized to :attr:`resize_to` (area
        interpolation) when the model states a size.

        Raises:
            InvalidOptionError: the image is not RGB or grey of those pixel types, is empty, or is float beyond
                [0, 1].
        """
        return self._prepare(_rgb_image(image))

    def _prepare(self, image: np.ndarray) -> np.ndarray:
        """:meth:`prepare` of an image already checked (:func:`_rgb_image`)."""
        image = image[self._cut(image.shape[0]):]  # the rows crop_top leaves out, before any conversion
        if image.dtype != np.uint8:  # uint16 and float: to [0, 1] first (cv2 resizes float32, not float16)
            image = image.astype(np.float32) * np.float32(1 / 65535 if image.dtype == np.uint16 else 1)
        if self.resize_to is not None and image.shape[:2] != self.resize_to:
            image = fit(image, self.resize_to, self.resize)
        if self.tta:  # the light normalised at the network's size (as adapt's teacher sees frames)
            from freespace.data.photometry import normalise_light  # (the data package: only when asked)

            if image.dtype != np.uint8:
                image = np.clip(np.rint(image * 255), 0, 255).astype(np.uint8)
            image = normalise_light(image)
        chw = image.transpose(2, 0, 1).astype(np.float32)
        return chw / np.float32(255) if image.dtype == np.uint8 else chw

    def infer(self, inputs: list[np.ndarray]) -> list[np.ndarray]:
        """Road probabilities (``float32 h×w``) of prepared inputs (:meth:`prepare`), at the network's size;
        inputs of one size go through the network together (with ``tta``, and their mirror images)."""
        by_size: dict[tuple[int, ...], list[int]] = {}
        for i, x in enumerate(inputs):
            by_size.setdefault(x.shape, []).append(i)
        out: list[np.ndarray | None] = [None] * len(inputs)
        for idx in by_size.values():
            batch = np.stack([inputs[i] for i in idx])
            probs = self._run(batch)
            if self.tta:  # the mirror image's probability, mirrored back, averaged in
                probs = (probs + self._run(np.ascontiguousarray(batch[..., ::-1]))[..., ::-1]) / 2
            for i, prob in zip(idx, probs):
                out[i] = np.ascontiguousarray(prob)
        return out  # type: ignore[return-value]

    def restore(self, prob: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """``prob`` (``float32 h×w``) at ``size`` = (H, W): the frame's part of the input (:attr:`resize`), bilinear
        on the probabilities (a threshold after it gives a smooth mask boundary, not the network's blocks); the rows
        that :attr:`crop_top` left out are 0."""
        top = self._cut(size[0])
        if top == 0:
            return unfit(prob, size, self.resize)
        out = np.zeros(size, np.float32)
        out[top:] = unfit(prob, (size[0] - top, size[1]), self.resize)
        return out

    def _cut(self, height: int) -> int:
        """The rows :attr:`crop_top` leaves out of a frame ``height`` rows high (at least one row is kept)."""
        return min(int(round(self.crop_top * height)), height - 1)

    def predict(self, images: np.ndarray | Iterable[np.ndarray], batch_size: int = 8) -> list[np.ndarray]:
        """Road probability (``float32 H×W`` in [0, 1]) of each image, at its own size, in order.

        Args:
            images: RGB images, each ``H×W×3`` (or grey, ``H×W`` or ``H×W×1``: repeated to three channels, as
                :func:`freespace.io.codecs.read_image` gives grey files) with pixels ``uint8`` (0…255), ``uint16``
                (0…65535: scaled by 1/65535) or float (``float16/32/64`` in [0, 1], as they are), any size (sizes
                may differ): one image (an ``H×W×3`` or ``H×W`` array), a batch (an ``N×H×W×3`` array, or a list
                or tuple of images), or any iterable of images (a generator: read once, ``batch_size`` images at a
                time, so that a long one is never all in memory; the probabilities are).
            batch_size: images per network call (1…:data:`~freespace.limits.MAX_BATCH_SIZE`).

        Returns:
            A list of one probability map per image (a list of one for one image).

        Raises:
            InvalidOptionError: no image at all; a path instead of an image (read it first:
                :func:`freespace.io.codecs.read_image`); an image of other channels (RGBA: drop the alpha; 2, 5,
                …), an empty one (a side of 0), one of another pixel type (bool, signed integers) or float outside
                [0, 1] (NaN included: a 0…255 float image must be divided by 255 first); a bad ``batch_size``.
        """
        if isinstance(batch_size, bool) or not isinstance(batch_size, int) or not 1 <= batch_size <= MAX_BATCH_SIZE:
            raise InvalidOptionError(f"{param('batch_size')} must be an integer in 1…{MAX_BATCH_SIZE}, got "
                                     f"{batch_size!r}")
        out: list[np.ndarray] = []
        batch: list[np.ndarray] = []
        for image in _images(images):
            batch.append(image)
            if len(batch) == batch_size:
                out += self._predict_batch(batch, len(out))
                batch = []
        if batch:
            out += self._predict_batch(batch, len(out))
        if not out:
            raise InvalidOptionError("Predictor.predict was given no image; give one or more RGB images (H×W×3)")
        return out

    def _predict_batch(self, images: list[np.ndarray], first: int) -> list[np.ndarray]:
        """:meth:`predict` of a list of images, the first of them image ``first`` of the input (for messages)."""
        checked = []
        for i, img in enumerate(images):
            try:
                checked.append(_rgb_image(img))
            except InvalidOptionError as exc:
                raise InvalidOptionError(f"image {first + i} (counted from 0) given to Predictor.predict: "
                                         f"{exc.render()}") from None
        probs = self.infer([self._prepare(img) for img in checked])
        return [self.restore(p, img.shape[:2]) for p, img in zip(probs, checked)]


def _describe(x: Any) -> str:
    """What ``x`` is, as a message says it: ``"an array of float64 of shape (4, 4, 3)"`` or ``"a value of type
    str"``."""
    if isinstance(x, np.ndarray):
        return f"an array of {x.dtype} of shape {x.shape}"
    return f"a value of type {type(x).__name__}"


_PIXELS = "uint8 0…255, uint16 0…65535 or float in [0, 1]"


def _rgb_image(image: Any) -> np.ndarray:
    """``image`` as an ``H×W×3`` array of one of the pixel types :meth:`Predictor.predict` takes, checked (a grey
    ``H×W`` or ``H×W×1`` image repeated to three channels, as :mod:`freespace.io.video` gives grey frames).

    Raises:
        InvalidOptionError: what is wrong with it, in one line.
    """
    if isinstance(image, (str, bytes, os.PathLike)):
        raise InvalidOptionError(f"expected an RGB image array (H×W×3), got the path {image!r}; read it first "
                                 f"(freespace.io.codecs.read_image)")
    try:
        arr = image if isinstance(image, np.ndarray) else np.asarray(image)
    except (ValueError, TypeError):  # ragged nested lists
        raise InvalidOptionError(f"expected an RGB image array (H×W×3), got {_describe(image)}, which is "
                                 f"none") from None
    grey = arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 1)
    if not grey and (arr.ndim != 3 or arr.shape[2] != 3):
        hint = "; drop the alpha channel (image[:, :, :3])" if arr.ndim == 3 and arr.shape[2] == 4 else ""
        raise InvalidOptionError(f"expected an RGB image H×W×3 (or grey H×W), got {_describe(image)}{hint}")
    if arr.size == 0:
        raise InvalidOptionError(f"expected an RGB image H×W×3, got an empty one of shape {arr.shape}")
    if arr.dtype not in (np.uint8, np.uint16) and not np.issubdtype(arr.dtype, np.floating):
        raise InvalidOptionError(f"expected an RGB image of pixels {_PIXELS}, got {_describe(image)}")
    if np.issubdtype(arr.dtype, np.floating):
        low, high = float(np.min(arr)), float(np.max(arr))
        if not (0.0 <= low and high <= 1.0):  # NaN fails both
            bad = "NaN" if np.isnan(arr).any() else f"values in [{low:g}, {high:g}]"
            raise InvalidOptionError(f"expected a float RGB image in [0, 1], got {bad} ({arr.dtype}); divide a "
                                     f"0…255 image by 255 (or give it as uint8)")
    if grey:
        arr = np.repeat(arr.reshape(arr.shape[0], arr.shape[1], 1), 3, axis=2)
    return arr


def _images(images: Any) -> Iterator[Any]:
    """The images of what :meth:`Predictor.predict` takes (one image, a batch array, an iterable), one by one;
    each is checked by :meth:`Predictor.prepare`.

    Raises:
        InvalidOptionError: ``images`` is a path, or an array neither an image nor a batch, or no iterable.
    """
    if isinstance(images, (str, bytes, os.PathLike)):
        raise InvalidOptionError(f"Predictor.predict takes RGB images (arrays H×W×3), got the path {images!r}; "
                                 f"read it first (freespace.io.codecs.read_image)")
    if isinstance(images, np.ndarray):
        if images.ndim in (2, 3):  # one image: RGB H×W×3 (or grey)
            yield images
            return
        if images.ndim == 4:
            yield from images
            return
        raise InvalidOptionError(f"Predictor.predict takes an RGB image (H×W×3), a batch of them (N×H×W×3) or a "
                                 f"list of images, got {_describe(images)}")
    try:
        it = iter(images)
    except TypeError:
        raise InvalidOptionError(f"Predictor.predict takes an RGB image (H×W×3), a batch (N×H×W×3) or an "
                                 f"iterable of images, got {_describe(images)}") from None
    yield from it
