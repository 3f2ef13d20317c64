"""The built-in demo: render stereo road scenes, run the DS-Generator on them, then train a light network
with and without the augmentation, evaluate both and compare (``full``: the six-network protocol); it ends
by running every published real-road model on the real example frames shipped with it
(:func:`run_published_models`).

``freespace demo`` (and ``make demo``) runs it end to end on a fresh machine, with no data files.

A published model is a folder ``models/<name>/`` of the repository: ``model.onnx`` (``freespace export``),
``README.md`` (its model card) and ``examples/`` (a few real frames, PNG, with their ``LICENSE``).
"""

from __future__ import annotations

import glob
import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.kitti_road import KittiRoad
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.data.synthetic.dataset import MAX_FRAMES
from freespace.datagen.generate import generate_dataset
from freespace.errors import FreespaceError, InputFileError, InvalidOptionError, check_seed, param
from freespace.evaluation.viz import caption, colorize_disparity, grid, overlay_road
from freespace.geometry import compute_disparity, fit_road_model
from freespace.io.codecs import read_disparity, read_image, read_road_label, write_image
from freespace.io.files import PathLike, check_writable, write_json
from freespace.io.outdir import claim_folder

log = logging.getLogger(__name__)

__all__ = ["run_demo", "demo_report", "models_folder", "published_models", "run_published_models", "published_lines"]

#: what the demo writes into OUT (:mod:`freespace.io.outdir` entries); ``real/<name>/``: each published
#: model's predictions on its example frames
OUT_ENTRIES = ("dataset/", "generated/", "figures/", "experiment/", "real/", "demo_summary.json")

#: the environment variable that names another folder of published models than the repository's ``models/``
MODELS_ENV = "FREESPACE_MODELS"


def models_folder() -> Path:
    """The folder of published models: ``$FREESPACE_MODELS`` when set, else the repository's ``models/`` (next
    to the ``freespace`` package; absent from an installed package, which has none)."""
    env = os.environ.get(MODELS_ENV)
    if env:
        return Path(env)
    import freespace

    return Path(freespace.__file__).resolve().parents[1] / "models"


def published_models(folder: PathLike | None = None) -> list[Path]:
    """The published models of ``folder`` (default :func:`models_folder`): its ``<name>/model.onnx`` files,
    sorted by name; none when the folder does not exist."""
    folder = Path(folder) if folder is not None else models_folder()
    return sorted(p for p in folder.glob("*/model.onnx") if p.is_file()) if folder.is_dir() else []


def run_published_models(out: PathLike, folder: PathLike | None = None, batch_size: int = 4) -> list[dict[str, Any]]:
    """Run every published model of ``folder`` (:func:`published_models`) on its ``examples/*.png`` as
    ``freespace predict --onnx MODEL --input 'examples/*.png' --out OUT/real/<name>`` does (the same
    :class:`~freespace.inference.predictor.Predictor` and :func:`~freespace.inference.predict.predict_folder`:
    8-bit road confidence maps, ``overlays/`` and ``summary.json``).

    Returns:
        One entry per model, in name order: ``name``, ``model`` (its file), and either ``out`` (the folder
        of confidence maps), ``overlays``, ``frames`` and ``frames_per_second`` (end to end, first frame read
        to last written), or ``error`` (one line: the model or its examples cannot be read; the other models
        still run).
    """
    from freespace.inference.predict import predict_folder
    from freespace.inference.predictor import Predictor

    results = []
    for model in published_models(folder):
        name = model.parent.name
        target = Path(out) / "real" / name
        entry: dict[str, Any] = {"name": name, "model": str(model)}
        try:
            examples = model.parent / "examples"
            if not any(examples.glob("*.png")):
                raise InputFileError(f"{examples} holds no example frames (*.png); a published model ships a few")
            summary = predict_folder(Predictor(onnx=model), glob.escape(str(examples)) + "/*.png", target,
                                     batch_size=batch_size, progress=False)
            entry.update(out=str(target), overlays=str(target / "overlays"), frames=summary["frames"],
                         frames_per_second=summary["frames_per_second"])
        except FreespaceError as exc:
            log.warning("published model %s: %s", name, exc)
            entry["error"] = str(exc)
        results.append(entry)
    return results


def published_lines(results: list[dict[str, Any]], folder: PathLike | None = None) -> list[str]:
    """What the demo prints of :func:`run_published_models`' ``results``: one line per model (where its
    overlays are, and its frame rate; or why it failed), or one line saying that ``folder`` (default
    :func:`models_folder`) holds no published model."""
    if not results:
        where = Path(folder) if folder is not None else models_folder()
        return [f"real frames: no published model in {where} (models/<name>/model.onnx with examples/*.png), "
                f"nothing to show"]
    lines = []
    for r in results:
        if "error" in r:
            lines.append(f"real frames, model {r['name']}: failed: {r['error']}")
        else:
            fps = r["frames_per_second"]
            lines.append(f"real frames, model {r['name']}: {r['frames']} example frames, overlays in {r['overlays']} "
                         f"({fps:.1f} frames per second end to end)" if fps else
                         f"real frames, model {r['name']}: {r['frames']} example frames, overlays in {r['overlays']}")
    return lines


#: said where the demo prints HA-X − X: one seed of a short run, and what the studies found such a gain to be
_GAIN_NOTE = ("HA-X − X above is one seed of a short run from scratch. The studies find such a gain to be HA-X's extra "
              "steps, not its views: against X-dup (the same frames seen as often) the views add +0.30 [−0.25, +0.85] "
              "F on rendered data trained to convergence (ten seeds), and −0.37 [−1.15, +0.41] on real KITTI stereo "
              "(five seeds; the README's What the studies found).")


def demo_report(result: dict[str, Any], out: PathLike) -> tuple[str, bool]:
    """What ``freespace demo`` prints of :func:`run_demo`'s ``result`` (written into ``out``): per frame the true
    and fitted roll and the road's grey-level differences, the results table, where the figures are and the
    published models' lines (:func:`published_lines`); and whether everything succeeded (no frame failed to
    generate, no published model failed)."""
    lines = [f"{'frame':<12} {'weather':<8} {'roll':>7} {'fit':>7} {'SGBM fit':>8}   road |L−R|  road |L−G|"]
    for f in result["frames"]:
        sgbm = f"{f['sgbm_roll_deg']:+8.3f}" if f["sgbm_roll_deg"] is not None else f"{'—':>8}"
        lines.append(f"{f['frame']:<12} {f['weather']:<8} {f['true_roll_deg']:+7.3f} {f['fitted_roll_deg']:+7.3f} "
                     f"{sgbm}   {f['road_mae_right']:10.1f}  {f['road_mae_generated']:10.1f}")
    lines.append(f"on the road the generated view differs from the left image by "
                 f"{result['mean_road_mae_generated']:.1f} grey levels on average, the raw right image by "
                 f"{result['mean_road_mae_right']:.1f}")
    if "results_md" in result:
        lines += ["", Path(result["results_md"]).read_text().rstrip(), "", _GAIN_NOTE]
    lines.append(f"figures: {result['figures']}, {out}/experiment/figures   ({result['seconds']:.0f} s)")
    lines += published_lines(result["real"], result["models_folder"])
    return "\n".join(lines), not (result["generate_failed"] or any("error" in r for r in result["real"]))


def _mae(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b.astype(np.float64))[mask].mean())


def _least_frames(frames_per_scenario: int, seed: int) -> int:
    """The fewest rendered frames whose paper split (by drive) leaves train, val and test non-empty."""
    from freespace.data.splits import make_splits

    n = frames_per_scenario
    while not all(make_splits([(f"{i:06d}", str(i // frames_per_scenario)) for i in range(n)], seed=seed).values()):
        n += frames_per_scenario
    return n


def run_demo(out: PathLike, num_frames: int = 60, seed: int = 0, config: SynthConfig | None = None,
             train: bool = True, full: bool = False, epochs: int | None = None, figures: int = 4) -> dict[str, Any]:
    """Render ``num_frames`` stereo frames, generate their augmented views, and report; then (``train``)
    run :func:`freespace.experiments.reproduce.reproduce` on them: U-Net (light) with and without the
    augmentation, one seed — or, with ``full``, all six networks and three seeds.

    Writes under ``out``: ``dataset/`` (KITTI road tree), ``generated/`` (DS-Generator output and
    reports), ``figures/<frame>.jpg`` (left, right, disparity, label, generated view, for the first
    ``figures`` frames), ``experiment/`` (runs, results.md/csv, prediction figures), ``real/<name>/`` (each
    published model on its real example frames: :func:`run_published_models`) and ``demo_summary.json``.
    Returns the summary: per frame the true and fitted roll (from the exact and from SGBM disparity) and
    the mean absolute difference to the left image on the road of the raw right image and of the generated
    image; the results table; ``real`` (:func:`run_published_models`) and ``models_folder``."""
    config = config or SynthConfig(width=160, height=128, frames_per_scenario=4)
    check_seed(seed)
    least = _least_frames(config.frames_per_scenario, seed) if train else 1
    if not least <= num_frames <= MAX_FRAMES:
        raise InvalidOptionError(f"{param('num_frames')} must be in {least}…{MAX_FRAMES:,}"
                                 + (f" (training needs drives of {config.frames_per_scenario} frames for train, val "
                                    f"and test)" if train else "") + f", got {num_frames}")
    if epochs is not None and epochs < 1:
        raise InvalidOptionError(f"{param('epochs')} must be ≥ 1, got {epochs}")
    check_writable(out, folder=True)
    with claim_folder(out, "demo", entries=OUT_ENTRIES):
        return _demo(Path(out), num_frames, seed, config, train, full, epochs, figures)


def _demo(out: Path, num_frames: int, seed: int, config: SynthConfig, train: bool, full: bool,
          epochs: int | None, figures: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    log.info("rendering %d stereo frames into %s", num_frames, out / "dataset")
    rows = write_dataset(out / "dataset", num_frames, seed=seed, config=config)
    dataset = KittiRoad(out / "dataset")
    frames = dataset.frames
    log.info("running the DS-Generator")
    summary = generate_dataset(dataset, out / "generated")
    per_frame = []
    for frame, row in list(zip(frames, sorted(rows, key=lambda r: r["frame"])))[:figures]:
        left, right = read_image(frame.left), read_image(frame.right)
        generated = read_image(out / "generated" / f"{frame.name}.png")
        label = read_road_label(frame.label)
        disparity = read_disparity(frame.disparity)
        road = label.road & label.valid
        # search as far as the true road disparity goes (the rig's baseline varies per scenario)
        reach = int(np.ceil(np.nanmax(np.where(road, disparity, np.nan)) / 16.0 + 0.5)) * 16
        sgbm = compute_disparity(left, right, max_disparity=min(max(reach, 16), 256))
        fit_true = fit_road_model(disparity, road)
        try:
            fit_sgbm = fit_road_model(sgbm, road)
        except FreespaceError as exc:
            log.warning("%s: no road model from SGBM (%s)", frame.name, exc)
            fit_sgbm = None
        per_frame.append({
            "frame": frame.name, "weather": row["weather"], "true_roll_deg": float(row["roll_deg"]),
            "fitted_roll_deg": fit_true.roll_deg, "sgbm_roll_deg": fit_sgbm.roll_deg if fit_sgbm else None,
            "sgbm_inlier_fraction": fit_sgbm.num_inliers / fit_sgbm.num_valid if fit_sgbm else None,
            "road_mae_right": _mae(right, left, road), "road_mae_generated": _mae(generated, left, road),
        })
        figure = grid([[caption(left, f"left {frame.name} ({row['weather']})"), caption(right, "right"),
                        caption(colorize_disparity(disparity), "disparity (exact)")],
                       [caption(overlay_road(left, road), "road label"),
                        caption(colorize_disparity(sgbm), "disparity (SGBM)"),
                        caption(generated, f"generated view, roll {fit_true.roll_deg:+.2f} deg")]], width=480)
        write_image(out / "figures" / f"{frame.name}.jpg", figure)
    result = {
        "frames": per_frame,
        "mean_road_mae_right": float(np.mean([f["road_mae_right"] for f in per_frame])),
        "mean_road_mae_generated": float(np.mean([f["road_mae_generated"] for f in per_frame])),
        "max_roll_error_deg": float(max(abs(f["fitted_roll_deg"] - f["true_roll_deg"]) for f in per_frame)),
        "max_sgbm_roll_error_deg": max((abs(f["sgbm_roll_deg"] - f["true_roll_deg"]) for f in per_frame
                                        if f["sgbm_roll_deg"] is not None), default=None),
        "generate_failed": summary["failed"],
        "seconds": round(time.perf_counter() - t0, 2),
        "figures": str(out / "figures"),
    }
    if train:
        from freespace.experiments import PAPER_NETWORKS
        from freespace.experiments.reproduce import reproduce

        log.info("training %s with and without the augmentation", "all six networks" if full else "U-Net")
        epochs = epochs if epochs is not None else 30 if full else 12
        experiment = reproduce("kitti", out / "dataset", out / "experiment",
                               models=list(PAPER_NETWORKS) if full else ["unet"], seeds=3 if full else 1,
                               epochs=epochs, patience=5, batch_size=8, figures=3, variants=("X", "HA-X"))
        result["results"] = experiment["table"]
        result["results_md"] = str(out / "experiment" / "results.md")
    log.info("running the published real-road models on their example frames")
    folder = models_folder()
    result["models_folder"] = str(folder)
    result["real"] = run_published_models(out, folder)
    result["seconds"] = round(time.perf_counter() - t0, 2)
    write_json(out / "demo_summary.json", result)
    return result
