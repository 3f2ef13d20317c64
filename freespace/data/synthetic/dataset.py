"""Write the built-in renderer's frames as a KITTI road tree (``freespace synth``).

Tree written under ``OUT``::

    OUT/data_road/training/image_2/<cat>_<id>.png          left images
    OUT/data_road/training/gt_image_2/<cat>_road_<id>.png  road labels (KITTI colours)
    OUT/data_road/training/calib/<cat>_<id>.txt            KITTI calibration text
    OUT/data_road/training/disparity/<cat>_<id>.png        exact left disparity (KITTI uint16)
    OUT/data_road_right/training/image_3/<cat>_<id>.png    right images
    OUT/index.csv                                          frame, category, scenario, weather, rig
    OUT/synth.json                                         seed and configuration

``<id>`` is the global frame index, so frame i has the same name and bytes for a given seed and
configuration whatever ``num`` is.
"""

from __future__ import annotations

import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.synthetic.render import StereoSample, render_sample
from freespace.data.synthetic.scene import SynthConfig
from freespace.errors import InvalidOptionError
from freespace.io import (PathLike, atomic_write_text, road_label_to_kitti, write_csv, write_disparity, write_image,
                          write_json)

__all__ = ["write_dataset", "write_sample", "format_kitti_calib", "INDEX_FIELDS"]

INDEX_FIELDS = ["frame", "index", "category", "scenario", "weather", "roll_deg", "pitch_deg", "baseline_m",
                "focal_px", "camera_height_m", "lanes", "planar"]


def format_kitti_calib(calib: dict[str, np.ndarray]) -> str:
    """KITTI calibration text (``KEY: v1 v2 ...`` in %.12e, row-major) of a matrix dict."""
    lines = []
    for key in ("P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_cam_to_road"):
        if key in calib:
            lines.append(f"{key}: " + " ".join(f"{x:.12e}" for x in np.asarray(calib[key]).ravel()))
    return "\n".join(lines) + "\n"


def write_sample(sample: StereoSample, out: PathLike, split: str = "training") -> None:
    """Write one rendered frame into a KITTI road tree at ``out`` (atomic writes)."""
    out = Path(out)
    base = out / "data_road" / split
    cat, idx = sample.name.split("_")
    write_image(base / "image_2" / f"{sample.name}.png", sample.left)
    write_image(base / "gt_image_2" / f"{cat}_road_{idx}.png", road_label_to_kitti(sample.label))
    atomic_write_text(base / "calib" / f"{sample.name}.txt", format_kitti_calib(sample.kitti_calib))
    write_disparity(base / "disparity" / f"{sample.name}.png", sample.disparity)
    write_image(out / "data_road_right" / split / "image_3" / f"{sample.name}.png", sample.right)


def _index_row(sample: StereoSample) -> dict[str, Any]:
    m = sample.meta
    return {"frame": sample.name, "index": sample.index, "category": sample.category, "scenario": sample.scenario,
            "weather": m["weather"], "roll_deg": f"{m['roll_deg']:.6f}", "pitch_deg": f"{m['pitch_deg']:.6f}",
            "baseline_m": f"{m['baseline_m']:.6f}", "focal_px": f"{m['focal_px']:.4f}",
            "camera_height_m": f"{m['camera_height_m']:.6f}", "lanes": m["lanes"], "planar": int(m["planar"])}


def _render_and_write(job: tuple[int, int, SynthConfig, str]) -> dict[str, Any]:
    index, seed, config, out = job
    sample = render_sample(index, seed, config)
    write_sample(sample, out)
    return _index_row(sample)


def _init_worker() -> None:
    import cv2

    cv2.setNumThreads(1)


def write_dataset(out: PathLike, num: int, *, seed: int = 0, config: SynthConfig = SynthConfig(),
                  workers: int = 1, progress: bool = True) -> list[dict[str, Any]]:
    """Render frames ``0 … num−1`` and write them as a KITTI road tree (see the module docstring).

    Returns:
        The rows of ``index.csv`` (frame, category, scenario id, weather, rig parameters).
    """
    config.check()
    if num < 1:
        raise InvalidOptionError(f"--num must be ≥ 1, got {num}")
    if workers < 1:
        raise InvalidOptionError(f"--workers must be ≥ 1, got {workers}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InvalidOptionError(f"--out {out} is a file; give a folder for the dataset")
    from tqdm import tqdm

    jobs = [(i, seed, config, str(out)) for i in range(num)]
    bar = tqdm(total=num, desc="synth", unit="frame", disable=not progress)
    rows: list[dict[str, Any]] = []
    if workers == 1:
        for job in jobs:
            rows.append(_render_and_write(job))
            bar.update()
    else:
        with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                                 mp_context=multiprocessing.get_context("spawn")) as pool:
            for row in pool.map(_render_and_write, jobs, chunksize=max(1, num // (4 * workers))):
                rows.append(row)
                bar.update()
    bar.close()
    write_csv(out / "index.csv", INDEX_FIELDS, rows)
    write_json(out / "synth.json", {"seed": seed, "num": num, "config": json.loads(json.dumps(asdict(config)))})
    return rows
