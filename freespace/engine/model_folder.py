"""A model folder from a training run, like the published ones (``freespace export``, format ``folder``).

A *model folder* is what ``freespace predict`` (its ``model.onnx``), ``freespace adapt`` (``model``) and
``freespace train`` (``init``) take: ``model.onnx`` (float16, as ``freespace export`` writes it in float16: the
published models' speed and size), ``model.ckpt`` (the weights as trained, float32, batch-norm statistics
included, or with its convolution kernels in float16 for a smaller folder; weights only:
``torch.load(weights_only=True)``), ``README.md`` (the card: the network and its input,
the data it was trained on, its licence, what was measured) and ``metrics.json`` (the run's figures and those of
every ``freespace evaluate`` folder given). It is written all or nothing (:mod:`freespace.io.outdir`).
"""

from __future__ import annotations

import html
import json
import tempfile
from pathlib import Path
from typing import Any

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, param
from freespace.io.files import (
    PathLike,
    atomic_write_bytes,
    atomic_write_text,
    check_outputs,
    check_writable,
    write_json,
)

__all__ = ["export_model_folder", "model_folder_report", "CHECKPOINT", "KERNELS", "MAX_LICENCE_CHARS"]

#: the checkpoint of a model folder
CHECKPOINT = "model.ckpt"
#: the precisions ``model.ckpt``'s convolution kernels may be written in
KERNELS = ("float32", "float16")
#: the longest licence text a card takes (one line)
MAX_LICENCE_CHARS = 300
#: what an evaluation folder's figures give the card
_FIGURES = ("precision", "recall", "f_score", "iou")


def _plain(text: Any, most: int = 200) -> str:
    """``text`` as one line of a Markdown card: bounded, tags escaped (quotes kept readable: outside a tag they
    open nothing), table pipes and backticks neutralised."""
    line = " ".join(str(text).split())[:most]
    return html.escape(line, quote=False).replace("|", "\\|").replace("`", "'")


def _read_json(path: Path, what: str) -> dict[str, Any]:
    if not path.is_file():
        raise InputFileError(f"{what} {path.parent} has no {path.name}: give a folder that freespace evaluate wrote")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CorruptFileError(f"cannot read {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict) or not all(isinstance(data.get(k), (int, float)) for k in _FIGURES):
        raise CorruptFileError(f"{path} holds no precision, recall, F and IoU: not the metrics.json of freespace "
                               f"evaluate")
    return data


def _run_folder(checkpoint: Path) -> Path | None:
    """The run folder of a checkpoint in ``RUN/checkpoints/`` (one with config.yaml and metrics.json), or None."""
    run = checkpoint.resolve().parent.parent
    ok = checkpoint.resolve().parent.name == "checkpoints" and (run / "config.yaml").is_file()
    return run if ok and (run / "metrics.json").is_file() else None


def _figures_row(name: str, m: dict[str, Any]) -> str:
    ci = (m.get("intervals") or {}).get("f_score")
    interval = f" [{ci[0] * 100:.1f}, {ci[1] * 100:.1f}]" if isinstance(ci, list) and len(ci) == 2 else ""
    frames = m.get("frames")
    frames = frames if isinstance(frames, int) else sum(frames.values()) if isinstance(frames, dict) else "?"
    return (f"| {name} | {frames} | **{m['f_score'] * 100:.1f}**{interval} | {m['precision'] * 100:.1f} / "
            f"{m['recall'] * 100:.1f} | {m['iou'] * 100:.1f} |")


def _data_lines(config: dict[str, Any], metrics: dict[str, Any]) -> list[tuple[str, str]]:
    folder = metrics.get("labelled_folder")
    if folder:
        fmt = folder.get("label_format", {})
        preset = f"{folder['labels_like']} labels" if folder.get("labels_like") else f"{fmt.get('kind')} labels"
        data = (f"{folder['frames'].get('train')} frames of `{_plain(folder['images'])}` with {preset} from "
                f"`{_plain(folder['labels'])}` (road {_plain(fmt.get('road'))}, don't care "
                f"{_plain(fmt.get('ignore'))})")
        val = _plain(folder.get("validation"))
    else:
        data = f"{_plain(config.get('dataset'))} at `{_plain(config.get('root'))}`"
        val = "the run's validation frames"
    init = metrics.get("init")
    start = (f"fine-tuned from `{_plain(init['path'])}` (frozen: {init['freeze']})" if init else
             f"encoder weights {_plain(config.get('encoder_weights') or 'random')}")
    return [("training data", data), ("validation", val), ("start", start)]


def _card(name: str, checkpoint: Path, hp: dict[str, Any], export: dict[str, Any], config: dict[str, Any],
          run_metrics: dict[str, Any], figures: dict[str, dict[str, Any]], licence: str,
          kernels: str = "float32") -> str:
    """The model folder's card (Markdown): what it is, the data and start, the licence, the figures."""
    size = hp.get("image_size")
    rows = ([_figures_row("the run's validation frames (chose its checkpoint)", run_metrics)]
            if all(isinstance(run_metrics.get(k), (int, float)) for k in _FIGURES) else [])
    rows += [_figures_row(f"`{_plain(folder)}` ({_plain(m.get('images') or m.get('root') or '')})", m)
             for folder, m in figures.items()]
    facts = [("network", f"{hp['model']} {_plain(json.dumps(hp.get('model_options', {})))}"),
             ("input", f"any RGB frame, resized to **{size[0]}×{size[1]}** (H×W)" if size else "its own size"),
             ("files", f"`model.onnx` float16 (largest road probability difference from the checkpoint "
                       f"{export['fp16']['max_prob_diff']:.4f}); `{CHECKPOINT}` "
                       + ("float32, the weights as trained" if kernels == "float32" else
                          "the weights as trained, convolution kernels in float16 (as `model.onnx` holds them), "
                          "batch norms and biases float32")),
             *_data_lines(config, run_metrics), ("licence", _plain(licence, MAX_LICENCE_CHARS))]
    table = "\n".join(f"| {k} | {v} |" for k, v in facts)
    measured = "\n".join(rows) or "| (nothing measured: export with folders of `freespace evaluate`) | | | | |"
    return f"""# {_plain(name)} — a road model trained with freespace

Written by `freespace export` (a model folder) from `{_plain(checkpoint)}`. Use it as the published models are used:
`freespace predict` with its `model.onnx`, `freespace adapt` on your unlabelled frames, or `freespace train` from it
(its `init`) on more labelled frames.

| | |
|---|---|
{table}

## Measured

Pooled over each set's frames (road where p ≥ 0.5); F with its 95 % frame-level bootstrap interval.

| set | frames | F | precision / recall | IoU |
|---|---:|---|---|---:|
{measured}
"""


def export_model_folder(checkpoint: PathLike, out: PathLike, *, licence: str,
                        measured: list[PathLike] | tuple[PathLike, ...] = (),
                        kernels: str = "float32") -> dict[str, Any]:
    """Write the model folder ``out`` (see the module docstring) from the training checkpoint ``checkpoint``
    (``RUN/checkpoints/best.ckpt``: the run folder around it gives the card its data and figures).

    Args:
        checkpoint: a training checkpoint; its run folder (config.yaml, metrics.json), when it is in one, names
            the data and gives the run's figures.
        out: the new model folder (new, or one this command wrote).
        licence: the licence of the model: the data's terms (e.g. "CC BY-NC-SA 3.0, from KITTI"); one line.
        measured: folders written by ``freespace evaluate`` with this model (on frames apart from its training
            frames): their figures go into the card and ``metrics.json``.
        kernels: ``"float32"``: ``model.ckpt`` holds every weight as trained; ``"float16"``: its convolution
            kernels in float16 (as ``model.onnx`` holds them; the batch norms, biases and statistics float32), about
            half the size, for a big network whose folder must stay small. ``model.onnx`` is exported from the
            checkpoint written, so the two agree bit for bit either way.

    Returns:
        ``{"out", "onnx": the float16 export's check, "figures": {name: metrics}}``.

    Raises:
        InvalidOptionError: an empty or too long licence, ``out`` among the inputs. InputFileError,
            CorruptFileError: a missing or damaged checkpoint or evaluation folder.
    """
    from freespace.engine.adapt_io import save_checkpoint
    from freespace.inference.export import export_model
    from freespace.inference.predictor import load_checkpoint
    from freespace.io.codecs import load_yaml
    from freespace.io.outdir import claim_folder

    if kernels not in KERNELS:
        raise InvalidOptionError(f"{param('kernels')} is one of {', '.join(KERNELS)}, got {kernels!r}")
    licence = " ".join(str(licence or "").split())
    if not licence or len(licence) > MAX_LICENCE_CHARS:
        raise InvalidOptionError(f"{param('licence')} must state the model's licence in one line of at most "
                                 f"{MAX_LICENCE_CHARS} characters (the training data's terms), got "
                                 f"{len(licence)} characters")
    checkpoint = Path(checkpoint)
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"checkpoint": checkpoint, **{f"measured[{i}]": m for i, m in enumerate(measured)}})
    net, hp = load_checkpoint(checkpoint)
    figures = {Path(m).name: _read_json(Path(m) / "metrics.json", "evaluation folder") for m in measured}
    run = _run_folder(checkpoint)
    config = load_yaml(run / "config.yaml") if run else {}
    run_metrics = json.loads((run / "metrics.json").read_text()) if run else {}
    size = hp.get("image_size")
    with claim_folder(out, "export") as owned, owned.staged() as stage:
        save_checkpoint(net, {"model": hp["model"], "model_options": hp.get("model_options", {}),
                              "image_size": size, "resize": hp.get("resize", "stretch")}, stage / CHECKPOINT,
                        half_kernels=kernels == "float16")
        with tempfile.TemporaryDirectory() as tmp:  # export refuses a path inside the stage's .freespace folder
            export = export_model(stage / CHECKPOINT, "onnx", Path(tmp) / "model.onnx", fp16=True)
            atomic_write_bytes(stage / "model.onnx", (Path(tmp) / "model.onnx").read_bytes())
        card = _card(Path(out).resolve().name, checkpoint, hp, export, config, run_metrics, figures, licence,
                     kernels)
        atomic_write_text(stage / "README.md", card)
        write_json(stage / "metrics.json", {"run": run_metrics, "measured": figures, "licence": licence,
                                            "checkpoint": str(checkpoint.resolve()), "kernels": kernels,
                                            "fp16": export["fp16"]})
    return {"out": str(out), "onnx": export["fp16"], "figures": figures}


def model_folder_report(result: dict[str, Any]) -> str:
    """What ``freespace export`` prints of a model folder: the folder and the float16 export's check."""
    return (f"model folder {result['out']}: model.onnx (float16, largest probability difference "
            f"{result['onnx']['max_prob_diff']:.4f}), model.ckpt, README.md, metrics.json")
