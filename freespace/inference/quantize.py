"""int8 static quantisation of an exported ONNX road model, calibrated on real frames, with its accuracy change
against float32 measured: ``freespace export --format onnx --int8 --calibration DIR``.

ONNX Runtime's ``quantize_static`` in the QDQ format: weights int8 per output channel (symmetric),
activations uint8 per tensor, their ranges from the minima and maxima the float model reaches on the
calibration frames. The frames are prepared as :class:`~freespace.inference.predictor.Predictor` prepares them
(resized to the model's training size, RGB in [0, 1]): calibrate on frames like those the model will see —
a few dozen real ones from the same camera; rendered or random frames give other activation ranges.

onnxruntime and onnx are imported only when called; never torch.
"""

from __future__ import annotations

import itertools
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import InputFileError, param
from freespace.io.files import PathLike
from freespace.io.video import open_frames

__all__ = ["CALIBRATION_FRAMES", "calibration_inputs", "quantize_int8", "compare_models"]

#: frames calibration uses at most, spread evenly over the source
CALIBRATION_FRAMES = 32


def calibration_inputs(source: PathLike, size: tuple[int, int] | None,
                       limit: int = CALIBRATION_FRAMES, resize: str = "stretch") -> list[np.ndarray]:
    """Up to ``limit`` frames of ``source`` (a folder, glob or video: :func:`~freespace.io.video.open_frames`),
    evenly spread, as network inputs: ``float32 1×3×H×W`` in [0, 1], fitted to ``size`` = (H, W) as ``resize``
    says (:func:`freespace.io.frame_fit.fit`: the model's own way) or left at their own size when None.

    Raises:
        InputFileError: the source is missing or holds no frames (the message names the parameter ``calibration``).
        CorruptFileError: a frame cannot be decoded.
    """
    from freespace.io.frame_fit import fit

    try:
        frames = open_frames(source)
    except InputFileError as exc:
        raise InputFileError(f"{param('calibration')}: {exc}") from None
    step = max(1, len(frames) // limit)
    out = []
    for frame in itertools.islice(itertools.islice(frames, 0, None, step), limit):
        image = frame.image
        if size is not None and image.shape[:2] != tuple(size):
            image = fit(image, tuple(size), resize)
        out.append(image.transpose(2, 0, 1)[None].astype(np.float32) / 255.0)
    return out


class _Reader:
    """onnxruntime's ``CalibrationDataReader`` interface over prepared inputs."""

    def __init__(self, name: str, inputs: list[np.ndarray]) -> None:
        self._it = iter([{name: x} for x in inputs])

    def get_next(self) -> dict[str, np.ndarray] | None:
        return next(self._it, None)


def quantize_int8(model: bytes, inputs: list[np.ndarray], metadata: dict[str, str] | None = None) -> bytes:
    """The int8 (QDQ, per-channel weights) version of the float32 ONNX ``model``, calibrated on ``inputs``
    (``float32 1×3×H×W`` each, :func:`calibration_inputs`); ``metadata`` is set on it (the float model's
    ``model`` and ``image_size``, so that the predictor reads it like any export).

    The model is first pre-processed as onnxruntime recommends (shape inference and graph optimisation:
    batch norms folded into convolutions, so they are quantised together).
    """
    import onnx
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if not inputs:
        raise InputFileError(f"{param('calibration')} gave no frames to calibrate on")
    with tempfile.TemporaryDirectory() as tmp:
        src, pre, dst = Path(tmp) / "float.onnx", Path(tmp) / "pre.onnx", Path(tmp) / "int8.onnx"
        src.write_bytes(model)
        quant_pre_process(str(src), str(pre), skip_symbolic_shape=True)
        name = onnx.load(str(pre)).graph.input[0].name
        quantize_static(str(pre), str(dst), _Reader(name, inputs), quant_format=QuantFormat.QDQ, per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        calibrate_method=CalibrationMethod.MinMax)
        proto = onnx.load(str(dst))
    del proto.metadata_props[:]
    for k, v in (metadata or {}).items():
        proto.metadata_props.add(key=k, value=v)
    return proto.SerializeToString()


def compare_models(reference: bytes, other: bytes, inputs: list[np.ndarray], threshold: float = 0.5) -> dict[str, Any]:
    """How ``other``'s road masks (probability ≥ ``threshold``) agree with ``reference``'s on ``inputs``, both
    run in onnxruntime on the CPU.

    Returns:
        ``frames``; ``mask_agreement``: the share of pixels whose road/non-road decision is the same;
        ``f_vs_float``: the F-score of ``other``'s road against ``reference``'s taken as the truth (1.0 when
        neither finds road); ``max_prob_diff``: the largest difference of road probability.
    """
    import onnxruntime as ort

    from freespace.inference.predictor import session_options

    sessions = [ort.InferenceSession(m, session_options(), providers=["CPUExecutionProvider"])
                for m in (reference, other)]
    same = total = tp = fp = fn = 0
    diff = 0.0
    for x in inputs:
        probs = []
        for s in sessions:
            logits = s.run(None, {s.get_inputs()[0].name: x})[0].astype(np.float64)
            e = np.exp(logits - logits.max(1, keepdims=True))
            probs.append(e[:, 1] / e.sum(1))
        a, b = probs[0] >= threshold, probs[1] >= threshold
        same += int((a == b).sum())
        total += a.size
        tp, fp, fn = tp + int((a & b).sum()), fp + int((~a & b).sum()), fn + int((a & ~b).sum())
        diff = max(diff, float(np.abs(probs[0] - probs[1]).max()))
    f = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
    return {"frames": len(inputs), "mask_agreement": same / total if total else 1.0, "f_vs_float": f,
            "max_prob_diff": diff}
