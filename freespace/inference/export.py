"""Export: a checkpoint as an ONNX (float32, float16 or int8) or TorchScript file, checked against PyTorch."""

from __future__ import annotations

import io as _io
import json
import logging
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import CorruptFileError, InvalidOptionError, param
from freespace.inference.predictor import load_checkpoint
from freespace.io.files import PathLike, atomic_write_bytes, check_outputs, check_suffix, check_writable

log = logging.getLogger(__name__)

__all__ = ["export_model", "to_float16", "export_report"]

#: the size (H, W) of the example input an export is traced and checked with when the checkpoint states no
#: training size: KITTI road's
EXPORT_EXAMPLE_SIZE = (384, 1248)
#: the suffixes an export's file may end in, by format
EXPORT_SUFFIXES = {"onnx": (".onnx",), "torchscript": (".pt", ".pth")}
#: the largest road probability difference a float16 export may have from its checkpoint on the check inputs
FP16_MAX_PROB_DIFF = 0.05

#: a serialised model's forward pass: ``float32 N×3×H×W`` tensor → ``N×C×H×W`` class scores
Runner = Callable[[Any], np.ndarray]


def export_model(checkpoint: PathLike, fmt: str, out: PathLike, calibration: PathLike | None = None,
                 fp16: bool = False) -> dict[str, Any]:
    """Export a checkpoint to ONNX (dynamic N, H, W; opset 17) or TorchScript (traced; dynamic H, W),
    validated against PyTorch at the training size and at an odd size. Returns the max abs differences.

    With ``fp16`` (ONNX only) the file written is the float16 model (:func:`to_float16`: weights and
    computation in float16, the ``image`` input and ``logits`` output kept float32, so that
    :class:`~freespace.inference.predictor.Predictor` and ``freespace predict --onnx`` take it as any export;
    the metadata kept), about half the size. Its road probabilities are compared with the checkpoint's
    (PyTorch, float32) on the check inputs: the result's ``fp16`` entry gives the largest difference and the
    share of pixels whose road/non-road decision (p ≥ 0.5) is the same; a difference above
    :data:`FP16_MAX_PROB_DIFF` (or not finite: a float16 overflow) refuses the export and writes nothing.

    With ``calibration`` (ONNX only: a folder, glob or video of real frames) the file written is the int8
    model (:func:`freespace.inference.quantize.quantize_int8`, calibrated on up to
    :data:`~freespace.inference.quantize.CALIBRATION_FRAMES` of them at the training size), and the result's
    ``int8`` entry says how its masks agree with the float32 model's on those frames
    (:func:`~freespace.inference.quantize.compare_models`).

    Returns:
        ``format``, ``path``, ``max_abs_diff`` (class scores, export against PyTorch), ``checked_sizes``
        (``[N, 3, H, W]`` of each check input), and ``fp16`` or ``int8`` as above.
    """
    _check_export_options(fmt, calibration, fp16)
    check_writable(out)
    check_outputs({"out": out}, {"checkpoint": checkpoint, **({"calibration": calibration} if calibration else {})})
    check_suffix(out, EXPORT_SUFFIXES[fmt])
    import torch

    model, hp = load_checkpoint(checkpoint)
    size = tuple(hp.get("image_size") or EXPORT_EXAMPLE_SIZE)
    calib_inputs = None
    if calibration is not None:  # read before the export: a bad folder fails fast
        from freespace.inference.quantize import calibration_inputs

        calib_inputs = calibration_inputs(calibration, size, resize=hp.get("resize", "stretch"))
    gen = torch.Generator().manual_seed(0)  # the same check inputs every time: a refusal is repeatable
    example = torch.rand(1, 3, *size, generator=gen)
    checks = [torch.rand(1, 3, *size, generator=gen), torch.rand(2, 3, size[0] - 7, size[1] - 13, generator=gen)]
    meta = {"model": hp["model"], "image_size": json.dumps(list(size)), "producer": "freespace",
            "resize": hp.get("resize", "stretch")}
    with warnings.catch_warnings():
        if not log.isEnabledFor(logging.DEBUG):  # torch's deprecations and tracer notes, unless -v
            warnings.simplefilter("ignore")
        data, run = (_to_onnx if fmt == "onnx" else _to_torchscript)(model, example, meta)
        references, diffs = _differences(model, run, checks)
    if not np.isfinite(diffs).all():  # NaN or infinite class scores: of the checkpoint or of the export
        raise CorruptFileError(f"the model {checkpoint} gives NaN or infinite class scores on the check inputs, so it "
                               f"predicts no road probability; it is broken (e.g. an overflow): train it anew")
    result = {"format": fmt, "path": str(Path(out)), "max_abs_diff": max(diffs),
              "checked_sizes": [list(x.shape) for x in checks]}
    if fp16:
        half = to_float16(data, {**meta, "precision": "float16 (weights and computation; image and logits float32)"})
        result["fp16"] = _check_float16(half, [x.numpy() for x in checks], references, checkpoint)
        data = half
    if calib_inputs is not None:
        from freespace.inference.quantize import compare_models, quantize_int8

        quantized = quantize_int8(data, calib_inputs, {**meta, "quantization": "int8 static, QDQ, per-channel weights, "
                                                                             f"{len(calib_inputs)} calibration frames"})
        result["int8"] = compare_models(data, quantized, calib_inputs)
        data = quantized
    atomic_write_bytes(Path(out), data)
    return result


def _check_export_options(fmt: str, calibration: PathLike | None, fp16: bool) -> None:
    """Refuse an unknown ``fmt``, and int8 (``calibration``) or ``fp16`` for anything but ONNX or together.

    Raises:
        InvalidOptionError: naming the parameters that do not go together.
    """
    if fmt not in ("onnx", "torchscript"):
        raise InvalidOptionError(f"{param('fmt')} must be onnx or torchscript, got {fmt!r}")
    if calibration is not None and fmt != "onnx":
        raise InvalidOptionError(f"int8 quantisation ({param('calibration')}) is for {param('fmt')} onnx")
    if fp16 and fmt != "onnx":
        raise InvalidOptionError(f"{param('fp16')} is for {param('fmt')} onnx (a float16 ONNX model); leave it out "
                                 f"for {fmt}")
    if fp16 and calibration is not None:
        raise InvalidOptionError(f"{param('fp16')} and int8 quantisation ({param('calibration')}) exclude each other: "
                                 f"a model is exported in float16 or in int8; leave out one of them")


def _to_onnx(model: Any, example: Any, meta: dict[str, str]) -> tuple[bytes, Runner]:
    """``model`` traced on ``example`` (``1×3×H×W``) as ONNX bytes (opset 17; dynamic N, H, W; ``meta`` as its
    metadata) and its forward pass in ONNX Runtime (CPU)."""
    import onnx
    import onnxruntime as ort
    import torch

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model"
        torch.onnx.export(model, (example,), str(path), dynamo=False, opset_version=17,
                          input_names=["image"], output_names=["logits"],
                          dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}, "logits": {0: "n", 2: "h", 3: "w"}})
        proto = onnx.load(str(path))
    for k, v in meta.items():
        proto.metadata_props.add(key=k, value=v)
    data = proto.SerializeToString()
    session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])

    def run(x: Any) -> np.ndarray:
        return session.run(None, {"image": x.numpy()})[0]
    return data, run


def _to_torchscript(model: Any, example: Any, meta: dict[str, str]) -> tuple[bytes, Runner]:
    """``model`` traced on ``example`` as TorchScript bytes (``meta`` as the extra file ``freespace.json``) and
    the forward pass of the file read back."""
    import torch

    with torch.no_grad():
        traced = torch.jit.trace(model, example, check_trace=False)
    buf = _io.BytesIO()
    torch.jit.save(traced, buf, _extra_files={"freespace.json": json.dumps(meta)})
    data = buf.getvalue()
    loaded = torch.jit.load(_io.BytesIO(data))

    def run(x: Any) -> np.ndarray:
        with torch.no_grad():
            return loaded(x).numpy()
    return data, run


def _differences(model: Any, run: Runner, checks: list[Any]) -> tuple[list[np.ndarray], list[float]]:
    """PyTorch's class scores on each check input (``float32 N×3×H×W``) and the largest absolute difference of
    the export's (``run``) from them, per input (NaN where either is not finite)."""
    import torch

    with torch.no_grad():
        references = [model(x).numpy() for x in checks]
    return references, [float(np.abs(run(x) - ref).max()) for x, ref in zip(checks, references)]


def to_float16(model: bytes, metadata: dict[str, str]) -> bytes:
    """The float16 version of the float32 ONNX ``model`` (onnxruntime's ``convert_float_to_float16``): weights
    and computation in float16, the graph's input and output kept float32 (``keep_io_types``: a cast after
    the input and before the output), so that it is called as the float32 model is; ``metadata`` is set on
    it (replacing what it had)."""
    import onnx
    from onnxruntime.transformers.float16 import convert_float_to_float16

    proto = convert_float_to_float16(onnx.load_from_string(model), keep_io_types=True)
    del proto.metadata_props[:]
    for k, v in metadata.items():
        proto.metadata_props.add(key=k, value=v)
    return proto.SerializeToString()


def _road_probability(logits: np.ndarray) -> np.ndarray:
    """Softmax road probability (``N×H×W``, float64) of ``N×C×H×W`` class scores."""
    logits = logits.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # infinite logits (a float16 overflow) give NaN: refused
        e = np.exp(logits - logits.max(1, keepdims=True))
        return e[:, 1] / e.sum(1)


def _check_float16(model: bytes, inputs: list[np.ndarray], references: list[np.ndarray],
                   checkpoint: PathLike) -> dict[str, Any]:
    """Run the float16 ONNX ``model`` on ``inputs`` (``float32 N×3×H×W``) and compare its road probabilities
    with the checkpoint's logits ``references``: ``max_prob_diff`` and ``mask_agreement`` (p ≥ 0.5).

    Raises:
        InvalidOptionError: the difference exceeds :data:`FP16_MAX_PROB_DIFF` or is not finite.
    """
    import onnxruntime as ort

    session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
    diff, same, total = 0.0, 0, 0
    for x, ref in zip(inputs, references):
        a, b = _road_probability(ref), _road_probability(session.run(None, {"image": x})[0])
        d = float(np.abs(a - b).max())
        diff = d if not np.isfinite(d) else max(diff, d)
        same, total = same + int(((a >= 0.5) == (b >= 0.5)).sum()), total + a.size
    if not diff <= FP16_MAX_PROB_DIFF:  # NaN too: a float16 overflow
        raise InvalidOptionError(f"{checkpoint}: in float16 the road probabilities differ from the checkpoint's by up "
                                 f"to {diff:.3g} (allowed {FP16_MAX_PROB_DIFF}); export it without {param('fp16')}")
    return {"max_prob_diff": diff, "mask_agreement": same / total, "tolerance": FP16_MAX_PROB_DIFF}


def export_report(result: dict[str, Any]) -> str:
    """One line on what :func:`export_model` wrote (``result``: its return value): the file, and how it agrees
    with PyTorch (float32), with the checkpoint (``fp16``) or with the float32 model (``int8``)."""
    sizes = ", ".join("×".join(map(str, s[2:])) for s in result["checked_sizes"])
    if "fp16" in result:
        h = result["fp16"]
        return (f"onnx float16 → {result['path']}  against the checkpoint: max probability difference "
                f"{h['max_prob_diff']:.2e} (allowed {h['tolerance']}), masks agree on "
                f"{100 * h['mask_agreement']:.2f} % of the pixels (sizes {sizes})")
    if "int8" in result:
        q = result["int8"]
        return (f"onnx int8 → {result['path']}  (float32 export: max abs difference to PyTorch "
                f"{result['max_abs_diff']:.2e}); against float32 on {q['frames']} calibration frames: masks agree on "
                f"{100 * q['mask_agreement']:.2f} % of the pixels, F {100 * q['f_vs_float']:.2f} (float32's masks as "
                f"the reference), max probability difference {q['max_prob_diff']:.3f}")
    return f"{result['format']} → {result['path']}  max abs difference to PyTorch {result['max_abs_diff']:.2e} " \
           f"(sizes {sizes})"
