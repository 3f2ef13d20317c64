"""The built-in demo: render stereo road scenes, run the DS-Generator on them, measure and draw.

``freespace demo`` (and ``make demo``) runs it end to end on a fresh machine, with no data files.
Torch-free.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.kitti_road import KittiRoad
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.errors import InvalidOptionError
from freespace.generate import generate_dataset
from freespace.geometry import compute_disparity, fit_road_model
from freespace.io import PathLike, read_disparity, read_image, read_road_label, write_image, write_json
from freespace.viz import caption, colorize_disparity, grid, overlay_road

log = logging.getLogger(__name__)

__all__ = ["run_demo"]


def _mae(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b.astype(np.float64))[mask].mean())


def run_demo(out: PathLike, num_frames: int = 4, seed: int = 0, config: SynthConfig | None = None) -> dict[str, Any]:
    """Render ``num_frames`` stereo frames, generate their augmented views, and report.

    Writes under ``out``: ``dataset/`` (KITTI road tree), ``generated/`` (DS-Generator output and
    reports), ``figures/<frame>.jpg`` (left, right, disparity, label, generated view) and
    ``demo_summary.json``. Returns the summary: per frame the true and fitted roll (from the exact and
    from SGBM disparity) and the mean absolute difference to the left image on the road of the raw
    right image and of the generated image.
    """
    if num_frames < 1:
        raise InvalidOptionError(f"--num must be ≥ 1, got {num_frames}")
    out = Path(out)
    config = config or SynthConfig(frames_per_scenario=1)
    t0 = time.perf_counter()
    log.info("rendering %d stereo frames into %s", num_frames, out / "dataset")
    rows = write_dataset(out / "dataset", num_frames, seed=seed, config=config)
    dataset = KittiRoad(out / "dataset")
    frames = dataset.frames
    log.info("running the DS-Generator")
    summary = generate_dataset(dataset, out / "generated")
    per_frame = []
    for frame, row in zip(frames, sorted(rows, key=lambda r: r["frame"])):
        left, right = read_image(frame.left), read_image(frame.right)
        generated = read_image(out / "generated" / f"{frame.name}.png")
        label = read_road_label(frame.label)
        disparity = read_disparity(frame.disparity)
        road = label.road & label.valid
        sgbm = compute_disparity(left, right)
        fit_true = fit_road_model(disparity, road)
        fit_sgbm = fit_road_model(sgbm, road)
        per_frame.append({
            "frame": frame.name, "weather": row["weather"], "true_roll_deg": float(row["roll_deg"]),
            "fitted_roll_deg": fit_true.roll_deg, "sgbm_roll_deg": fit_sgbm.roll_deg,
            "sgbm_inlier_fraction": fit_sgbm.num_inliers / fit_sgbm.num_valid,
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
        "max_sgbm_roll_error_deg": float(max(abs(f["sgbm_roll_deg"] - f["true_roll_deg"]) for f in per_frame)),
        "generate_failed": summary["failed"],
        "seconds": round(time.perf_counter() - t0, 2),
        "figures": str(out / "figures"),
    }
    write_json(out / "demo_summary.json", result)
    return result
