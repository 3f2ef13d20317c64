"""What goes into ``freespace adapt`` and what comes out: the frames (:func:`read_frames`), the checkpoint a model
folder carries (:func:`save_checkpoint`; :func:`checkpoint_from_onnx` rebuilt the published ones') and the adapted
model folder (:func:`write_model_folder`: checkpoint, float16 ONNX, card, picture, run record).

The folder is a model folder like the published ones (``models/<name>/``): ``model.onnx`` (exported as ``freespace
export`` does in float16: the same input size and graph, so the same speed), ``model.ckpt`` (the weights-only
checkpoint adapt continues from), ``README.md`` (the card: from which model, on which frames — count, sizes, a
hash —, with which settings, in how long, how the prediction changed), ``before_after.jpg`` (held-out frames,
the road before and after, side by side), and the run's record: ``config.json`` (the settings), ``rounds.csv``
(one row per round) and ``summary.json`` (commit, torch, the figures of the card).
"""

from __future__ import annotations

import hashlib
import html
import io as _io
import math
import os
import re
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.errors import FreespaceError, InputFileError, InvalidOptionError, param
from freespace.io.codecs import MIN_FRAME_SIDE
from freespace.io.files import PathLike, atomic_write_bytes

__all__ = ["Frames", "read_frames", "frame_paths", "save_checkpoint", "checkpoint_from_onnx", "write_model_folder",
           "before_after", "thin", "CHECKPOINT", "MAX_FRAMES", "MIN_FRAME_SIDE", "MAX_CARD_BYTES", "MAX_TITLE_CHARS"]

#: the checkpoint a model folder carries for adapt (weights only: ``torch.load(weights_only=True)``)
CHECKPOINT = "model.ckpt"
#: frames adapt uses at most (evenly spaced among more): 1000 frames at 192×640 hold 370 MB in memory
MAX_FRAMES = 1000
#: the bytes of the published model's card read at most for its title, and the title's characters at most
MAX_CARD_BYTES, MAX_TITLE_CHARS = 64 * 1024, 200

#: the width (pixels) of each panel of ``before_after.jpg``, and how many held-out frames it shows
PANEL_WIDTH, PICTURE_FRAMES = 480, 4
_ROUND_FIELDS = ("round", "loss", "confident", "steps", "stopped", "road_share", "confidence", "source_agreement",
                 "gained", "overridden", "conflicts", "completed", "vetoed", "seconds")


@dataclass
class Frames:
    """Frames read for adapt, resized to the network's size.

    Attributes:
        images: ``N×h×w×3 uint8`` RGB at the network's size (area interpolation, as prediction resizes).
        names: each frame's name (the image's stem, or ``<video stem>_<index>``).
        sizes: the distinct original sizes ``(H, W)`` in pixels.
        skipped: unreadable images skipped. total: frames found (before :data:`MAX_FRAMES` thinned them).
        sha256: a hash of the input files' bytes (names and contents, in order), first 16 hex digits.
    """

    images: np.ndarray
    names: list[str]
    sizes: list[tuple[int, int]] = field(default_factory=list)
    skipped: int = 0
    total: int = 0
    sha256: str = ""


def frame_paths(spec: PathLike, what: str = "input") -> tuple[str, list[Path]]:
    """``("images", paths)`` for a folder, a glob or an image (natural order, as ``predict`` reads them), or
    ``("video", [path])``; the images are not opened here (unreadable ones are skipped later). ``what``: the
    parameter that named ``spec`` (``"input"``, ``"source"``), which the messages name.

    Raises:
        InputFileError: nothing there, or no image in it. CorruptFileError: a file that is no video.
    """
    from freespace.io.video import IMAGE_SUFFIXES, _natural_key, open_frames

    path = Path(spec)
    if path.is_dir():
        paths = [p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
                 and not p.name.startswith(".")]
    elif path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES:
        paths = [path]
    elif path.is_file():
        return "video", [open_frames(path).paths[0]]  # an undecodable video fails here, in one line
    else:
        import glob

        paths = [Path(p) for p in glob.glob(str(spec))
                 if Path(p).is_file() and Path(p).suffix.lower() in IMAGE_SUFFIXES]
        if not paths and not any(c in str(spec) for c in "*?["):
            raise InputFileError(f"{param(what)} not found: {spec} (name a folder of frames, a glob or a video)")
    if not paths:
        raise InputFileError(f"{param(what)} {spec} holds no frames ({', '.join(IMAGE_SUFFIXES)} images, or a "
                             f"video); name a folder of frames, a glob such as 'frames/*.png' or a video")
    return "images", sorted(paths, key=_natural_key)


def thin(total: int, most: int) -> np.ndarray:
    """The indices kept of ``total`` frames when at most ``most`` may be: all of them when they are not more,
    else exactly ``most``, evenly spread from the first to the last (1050 frames at most 1000: 1000, not 525)."""
    if total <= most:
        return np.arange(total)
    return np.unique(np.linspace(0, total - 1, most).round().astype(int))


def read_frames(spec: PathLike, size: tuple[int, int], what: str = "input",
                max_frames: int = MAX_FRAMES) -> Frames:
    """The frames of a folder, glob, image or video (what ``predict`` reads), resized to ``size`` = (h, w).

    Unreadable images among readable ones are skipped and counted; more than ``max_frames`` frames are
    thinned to ``max_frames`` evenly spaced ones (:func:`thin`). ``what``: the parameter that named ``spec``.

    Raises:
        InputFileError: nothing found, or no readable frame. CorruptFileError: an undecodable video.
        InvalidOptionError: a frame smaller than :data:`MIN_FRAME_SIDE` pixels a side (no camera frame).
    """
    from freespace.io.codecs import MultiFrameImageError, read_image
    from freespace.io.video import open_frames

    kind, paths = frame_paths(spec, what)
    digest = hashlib.sha256()
    images: list[np.ndarray] = []
    names: list[str] = []
    sizes: set[tuple[int, int]] = set()
    skipped = 0

    def keep(name: str, image: np.ndarray) -> None:
        if image.ndim == 2:
            image = np.repeat(image[:, :, None], 3, axis=2)
        if min(image.shape[:2]) < MIN_FRAME_SIDE:
            raise InvalidOptionError(
                f"{param(what)} {spec}: frame {name} is {image.shape[1]}×{image.shape[0]} pixels, too small to show a "
                f"road (adapt needs camera frames of at least {MIN_FRAME_SIDE}×{MIN_FRAME_SIDE}; the model runs at "
                f"{size[1]}×{size[0]}): remove it or give the camera's frames")
        sizes.add(image.shape[:2])
        names.append(name)
        images.append(cv2.resize(image, (size[1], size[0]), interpolation=cv2.INTER_AREA))

    if kind == "video":
        with open(paths[0], "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                digest.update(chunk)
        source = open_frames(paths[0])
        chosen = set(thin(len(source), max_frames).tolist())
        stride = max(1, len(source) // max_frames)  # past the container's count, which may be an estimate
        total = 0
        for frame in source:
            total += 1
            if frame.index in chosen or (frame.index >= len(source) and frame.index % stride == 0):
                keep(frame.name, frame.image)
            if len(images) > max_frames:  # more frames than the count said: evenly thinned again, bounded
                kept = thin(len(images), max_frames)
                images[:], names[:] = [images[i] for i in kept], [names[i] for i in kept]
                stride *= 2
    else:
        total = len(paths)
        for i in thin(total, max_frames):
            path = paths[i]
            try:
                image = read_image(path, what="frame")
            except MultiFrameImageError:  # no damaged frame to skip: a sequence to split (as predict says)
                raise
            except FreespaceError:
                skipped += 1
                continue
            digest.update(os.fsencode(path.name) + b"\0" + path.read_bytes())  # a name of any bytes
            keep(path.stem, image)
    if not images:
        raise InputFileError(f"{param(what)} {spec}: none of its {total} frames could be read ({skipped} unreadable); "
                             f"give frames that OpenCV decodes (PNG, JPEG, …)")
    return Frames(np.stack(images), names, sorted(sizes), skipped, total, digest.hexdigest()[:16])


def save_checkpoint(net: Any, hyper_parameters: dict[str, Any], path: PathLike, *, half_kernels: bool = True) -> None:
    """Write ``net``'s weights as a weights-only checkpoint (``{"state_dict": {"net.<name>": tensor},
    "hyper_parameters": ...}``, what :func:`freespace.inference.predictor.load_checkpoint` reads). With
    ``half_kernels`` (adapt's folders) the convolution kernels are float16, as the published float16 ONNX holds
    them, and the rest (biases, batch norms, the input normalisation) float32, so that an export folds them back
    exactly: about half the size. Without, every tensor as it is (float32 as trained)."""
    import torch

    kernels = {k for k, v in net.named_parameters() if v.dim() > 1} if half_kernels else set()
    state = {f"net.{k}": (v.detach().half() if k in kernels else v.detach().clone())
             for k, v in net.state_dict().items()}
    buf = _io.BytesIO()
    torch.save({"state_dict": state, "hyper_parameters": hyper_parameters}, buf)
    atomic_write_bytes(path, buf.getvalue())


def checkpoint_from_onnx(onnx_path: PathLike, model: str, options: dict[str, Any],
                         image_size: tuple[int, int]) -> Any:
    """The network ``create_model(model, **options)`` with the weights of its ONNX export ``onnx_path`` (what
    gave the published folders their ``model.ckpt``): each convolution takes its ONNX kernel and bias in the
    order the network runs them; a batch norm after a bias-free convolution becomes the identity plus that
    bias (the export folded it into the convolution). Exporting the result gives the same weights again.

    Raises:
        CorruptFileError: the ONNX graph's convolutions do not match the network's (count or shapes).
    """
    import onnx
    import torch
    from onnx import numpy_helper

    from freespace.errors import CorruptFileError
    from freespace.models import create_model

    graph = onnx.load(str(onnx_path)).graph
    init = {i.name: numpy_helper.to_array(i).astype(np.float32) for i in graph.initializer}
    convs = [n for n in graph.node if n.op_type == "Conv"]
    net = create_model(model, **options).eval()
    order: list[str] = []
    hooks = [m.register_forward_hook(lambda *_, name=name: order.append(name))
             for name, m in net.named_modules() if isinstance(m, torch.nn.Conv2d)]
    with torch.no_grad():
        net(torch.zeros(1, 3, *image_size))
    for h in hooks:
        h.remove()
    modules = dict(net.named_modules())
    names = list(modules)
    state = net.state_dict()
    if len(order) != len(convs):
        raise CorruptFileError(f"{onnx_path} has {len(convs)} convolutions, {model} runs {len(order)}")
    for name, node in zip(order, convs):
        weight, bias = init[node.input[1]], init[node.input[2]]
        if tuple(state[f"{name}.weight"].shape) != weight.shape:
            raise CorruptFileError(f"{onnx_path}: {name} is {weight.shape} there, "
                                   f"{tuple(state[name + '.weight'].shape)} in {model}")
        state[f"{name}.weight"] = torch.from_numpy(weight)
        after = names[names.index(name) + 1] if names.index(name) + 1 < len(names) else ""
        norm = modules.get(after)
        if modules[name].bias is None and isinstance(norm, torch.nn.BatchNorm2d):
            state[f"{after}.running_mean"] = torch.zeros(len(bias))
            state[f"{after}.running_var"] = torch.ones(len(bias))
            state[f"{after}.weight"] = torch.full((len(bias),), math.sqrt(1 + norm.eps))
            state[f"{after}.bias"] = torch.from_numpy(bias)
        else:
            state[f"{name}.bias"] = torch.from_numpy(bias)
    for k in ("mean", "std"):
        state[k] = torch.from_numpy(init[k]).reshape(state[k].shape)
    net.load_state_dict(state)
    return net


def before_after(images: np.ndarray, before: np.ndarray, after: np.ndarray, aspect: float) -> np.ndarray:
    """One picture (``H×W×3 uint8`` RGB): a row per frame, the road (p ≥ 0.5, magenta) before on the left and
    after on the right, each panel :data:`PANEL_WIDTH` wide and ``aspect`` (height / width of the original
    frames) high.

    Args:
        images: ``N×h×w×3 uint8`` frames at the network's size. before, after: ``N×h×w`` road probabilities.
    """
    from freespace.inference.predict import fast_overlay

    h = max(1, int(round(PANEL_WIDTH * aspect)))
    rows = []
    for image, p0, p1 in zip(images, before, after):
        panels = []
        for prob, label in ((p0, "before"), (p1, "after")):
            panel = cv2.resize(fast_overlay(image, prob >= 0.5), (PANEL_WIDTH, h), interpolation=cv2.INTER_AREA)
            cv2.putText(panel, label, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
            panels.append(panel)
        rows.append(np.concatenate([panels[0], np.full((h, 4, 3), 255, np.uint8), panels[1]], axis=1))
    return np.concatenate(rows, axis=0)


def _picture(stage: Path, run: dict[str, Any], frames: Frames) -> None:
    """Write ``before_after.jpg`` from up to :data:`PICTURE_FRAMES` held-out frames, evenly spread."""
    held, (p0, p1) = run["held"], run["held_probs"]
    pick = np.unique(np.linspace(0, len(held) - 1, min(PICTURE_FRAMES, len(held))).round().astype(int))
    h, w = frames.sizes[0]
    rgb = before_after(frames.images[held[pick]], p0[pick].astype(np.float32), p1[pick].astype(np.float32), h / w)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
    atomic_write_bytes(stage / "before_after.jpg", data.tobytes())


def _card_line(folder: Path) -> str:
    """The first line of the model folder's ``README.md``, read only when it is a regular file of the folder itself
    (no symbolic link, which could lead anywhere; no pipe, which would block) and only its first
    :data:`MAX_CARD_BYTES` bytes (bytes that are no UTF-8 shown as U+FFFD); "" when there is none."""
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(folder / "README.md", flags)
    except OSError:  # none, a link (O_NOFOLLOW), unreadable
        return ""
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return ""
        head = os.read(fd, MAX_CARD_BYTES)
    except OSError:
        return ""
    finally:
        os.close(fd)
    return head.split(b"\n", 1)[0].decode("utf-8", errors="replace")


def _markdown_text(text: str) -> str:
    """``text`` as literal Markdown inside a line: one line (control characters as spaces), HTML's ``& < >`` as
    entities and the marks of emphasis, code, links, strike-through and tables (``\\ ` * _ [ ] ~ |``) escaped,
    so that it renders as the text it is."""
    line = "".join(c if c.isprintable() else " " for c in text)
    return re.sub(r"([\\`*_\[\]~|])", r"\\\1", html.escape(line, quote=False))


def _code_span(text: str) -> str:
    """``text`` as an inline Markdown code span (a path, a folder name): control characters shown escaped,
    fenced by more backticks than it holds in a row."""
    line = "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)
    fence = "`" * (max((len(run) for run in re.findall("`+", line)), default=0) + 1)
    pad = " " if line.startswith("`") or line.endswith("`") else ""
    return f"{fence}{pad}{line}{pad}{fence}"


def _title(folder: Path) -> str:
    """The published model's title for the new card, as Markdown: the first line of its card (the regular file
    ``README.md`` of the folder, :func:`_card_line`) without its heading marks, at most :data:`MAX_TITLE_CHARS`
    characters, escaped (:func:`_markdown_text`); else the folder's name."""
    first = _card_line(folder).lstrip("# ").strip()
    if len(first) > MAX_TITLE_CHARS:
        first = first[:MAX_TITLE_CHARS - 1].rstrip() + "…"
    return _markdown_text(first or folder.name)


def _frames_line(frames: Frames, what: str) -> str:
    sizes = ", ".join(f"{w}×{h}" for h, w in frames.sizes[:4]) + (" …" if len(frames.sizes) > 4 else "")
    thinned = f" (evenly chosen among {frames.total})" if frames.total > len(frames.names) + frames.skipped else ""
    return (f"{len(frames.names)} {what} frames{thinned}, {sizes} pixels, {frames.skipped} unreadable skipped; "
            f"sha256 of the files `{frames.sha256}`")


def _change_table(summary: dict[str, Any]) -> tuple[str, str]:
    """The card's table of the held-out measures: its header (two lines) and rows; a column of the measures right
    after the batch-norm statistics were re-estimated when they were."""
    b, a, t = summary["before"], summary["after"], summary.get("before_tta", {})
    n = summary.get("after_norm_stats")
    rows = [("road share (p ≥ 0.5)", "road_share"), ("mean confidence, max(p, 1 − p)", "confidence")]
    if "source_agreement" in a:
        rows.append(("source frames: mask agreement with the published model", "source_agreement"))
    cols = [b, t, *([n] if n else []), a]
    names = ["before", "before, with tta", *(["batch norms re-estimated, before self-training"] if n else []), "after"]
    head = f"| | {' | '.join(names)} |\n|{'---|' * (len(names) + 1)}"

    def cell(c: dict[str, float], k: str) -> str:  # the published model agrees with itself on the source frames
        return f"{c[k]:.1%}" if k in c else f"{1.0:.1%}" if c is b else "—"

    return head, "\n".join(f"| {label} | {' | '.join(cell(c, k) for c in cols)} |" for label, k in rows)


def _across_line(across: dict[str, Any]) -> str:
    """The card's line on labels carried along time (:func:`freespace.engine.adapt_time.plan_sequence`'s record)."""
    if across["setting"] == "off":
        return "not carried (setting `off`)"
    fitted = f"{across['pairs_fitted']} of {across['pairs']} consecutive pairs share a road homography"
    if not across["used"]:
        return f"not carried: {fitted}, not a sequence (setting `{across['setting']}`)"
    return f"carried from the next frames along the road plane's homographies: {fitted} (setting `{across['setting']}`)"


def _completion_line(settings: dict[str, Any]) -> str:
    """The card's line on labels completed by appearance (``complete`` and ``release`` of the settings)."""
    if not settings.get("complete"):
        return "not completed"
    release = settings.get("release", 0.0)
    rows = "" if settings.get("release_far", 1.0) == 1 else f", in its top {settings['release_far']:g} of rows"
    also = (f"; so may the confident not road within {release:g} × the frame's height of the road{rows} (`release`)"
            if release else "")
    return f"completed: the teacher's unsure pixels take a graph cut's side (`complete`){also}"


def _look_line(summary: dict[str, Any]) -> str:
    """The card's line on the look check (``look`` of the settings, the classifier's row in the summary)."""
    band = summary["settings"].get("look")
    if band is None:
        return "not checked"
    row = summary["look"]
    return (f"road that does not look like the lane ahead (columns {band[0]:g}–{band[1]:g} of the width) made don't "
            f"care (`look`): the look learnt from {row['road_examples']} road and {row['not_road_examples']} "
            f"not-road cells, {100 * row['road_recall']:.1f} % and {100 * row['not_road_recall']:.1f} % of them "
            f"told apart")


def _card(summary: dict[str, Any], folder: Path, frames: Frames, src: Frames | None) -> str:
    """The adapted model's card (Markdown)."""
    s = summary["settings"]
    head, table = _change_table(summary)
    norms = (" and with its batch-norm statistics re-estimated on these frames (before any training)"
             if summary.get("after_norm_stats") else "")
    size = summary["image_size"]
    limit = f", at most {s['minutes']:g} min" if s["minutes"] else ""
    facts = "\n".join(f"| {k} | {v} |" for k, v in (
        ("", ""), ("---", "---"),
        ("input", f"any RGB frame, resized to **{size[0]}×{size[1]}** (H×W) as the published model's"),
        ("file", f"`model.onnx`, float16 (as `freespace export` writes it in float16: largest road probability "
                 f"difference from the checkpoint {summary['export']['fp16']['max_prob_diff']:.4f}); "
                 f"`{CHECKPOINT}`, the weights adapt continues from"),
        ("adapted on", f"{_frames_line(frames, 'unlabelled')}; {summary['held_out']} of them held out of training "
                       f"for the collapse guard"),
        ("source frames", _frames_line(src, "source") if src is not None else "none (no source frames rehearsed)"),
        ("batch-norm statistics", f"{_markdown_text(summary['norm_stats'])}, before self-training (AdaBN; "
                                  f"setting `{s['norm_stats']}`)"),
        ("labels along time", _across_line(summary["across_time"])),
        ("labels by appearance", _completion_line(s)),
        ("labels by look", _look_line(summary)),
        ("settings", f"{s['epochs']} rounds{limit}, confidence threshold {s['threshold']:g}, AdamW lr {s['lr']:g}, "
                     f"batch {s['batch_size']}, teacher EMA {s['ema']:g}, max drift {s['max_drift']:g}, "
                     f"seed {s['seed']}"),
        ("took", f"{summary['seconds'] / 60:.1f} min, {summary['rounds']} rounds, {summary['threads']} CPU threads"),
        ("licence", f"derived from {_code_span(folder.name)}: its card's licence applies, and that of the frames")))
    return f"""# {_markdown_text(summary['name'])} — {_code_span(folder.name)} adapted to new frames without a label

Made by `freespace adapt` from **{_title(folder)}** ({_code_span(str(folder))}): self-training on the user's unlabelled
frames, a mean teacher relabelling them every round (module `freespace.engine.adapt`). No frame here was
labelled by a person; nothing was measured against a label.

Use it as the published models are used: `freespace predict` with this folder's `model.onnx` (the README's
quickstart).

{facts}

## How the prediction changed (the held-out frames)

The published model as it is, as `freespace predict` runs it with test-time augmentation (`tta`: light
normalised, mirror averaged; what adapt must add to, since its teacher sees frames so){norms}, and adapted:

{head}
{table}

![held-out frames: the road (magenta) before (left) and after (right) adaptation](before_after.jpg)

The run's record: `config.json` (settings), `rounds.csv` (one row per round), `summary.json`.
"""


def write_model_folder(stage: Path, run: dict[str, Any], hp: dict[str, Any], folder: Path, frames: Frames,
                       src: Frames | None, config: dict[str, Any], seconds: float, out: Path) -> dict[str, Any]:
    """Write the adapted model folder into ``stage`` (the staged output of ``out``; see the module). Returns
    the summary (also ``summary.json``).

    Args:
        run: what :func:`freespace.engine.adapt._self_train` returns. hp: the published checkpoint's
            hyper-parameters. folder: the published model folder. config: the run's settings
            (:class:`freespace.engine.adapt.AdaptSettings` as a dict). seconds: the run's wall time so far.
    """
    import torch

    from freespace.engine.record import package_commit
    from freespace.inference.export import export_model
    from freespace.io.files import atomic_write_text, write_csv, write_json

    size = list(frames.images.shape[1:3])
    save_checkpoint(run["net"], {"model": hp["model"], "model_options": hp.get("model_options", {}),
                                 "image_size": size, "adapted_from": folder.name, "adapt": config},
                    stage / CHECKPOINT)
    with tempfile.TemporaryDirectory() as tmp:  # export refuses a path inside the stage's .freespace folder
        export = export_model(stage / CHECKPOINT, "onnx", Path(tmp) / "model.onnx", fp16=True)
        atomic_write_bytes(stage / "model.onnx", (Path(tmp) / "model.onnx").read_bytes())
    _picture(stage, run, frames)
    write_csv(stage / "rounds.csv", _ROUND_FIELDS, run["rounds"])
    write_json(stage / "config.json", {"model": str(folder), "frames": len(frames.names), **config})
    summary = {"name": out.name, "out": str(out), "model": str(folder), "image_size": size,
               "frames": len(frames.names), "skipped": frames.skipped, "frames_sha256": frames.sha256,
               "frame_sizes": [list(s) for s in frames.sizes], "source_frames": len(src.names) if src else 0,
               "held_out": len(run["held"]), "train_frames": run["train_frames"], "settings": config,
               "rounds": len(run["rounds"]), "seconds": round(seconds, 1), "threads": run["threads"],
               "norm_stats": run["norm_stats"], "across_time": run["across_time"], "before": run["before"],
               "before_tta": run["before_tta"],
               **({"after_norm_stats": run["after_norm_stats"]} if "after_norm_stats" in run else {}),
               "after": run["after"], **({"look": run["look"]} if "look" in run else {}),
               "export": {"fp16": export["fp16"]},
               "record": {"commit": package_commit(), "torch": torch.__version__}}
    atomic_write_text(stage / "README.md", _card(summary, folder, frames, src))
    write_json(stage / "summary.json", summary)
    return summary
