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

import csv
import json
import os
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.synthetic.render import StereoSample, render_sample
from freespace.data.synthetic.scene import SynthConfig
from freespace.errors import InvalidOptionError, check_seed
from freespace.io import (PathLike, atomic_write_text, check_writable, road_label_to_kitti, write_csv,
                          write_disparity, write_image, write_json)

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


def _init_worker(parent: int) -> None:
    import cv2

    from freespace.parallel import init_worker

    init_worker(parent)
    cv2.setNumThreads(1)


MAX_FRAMES = 1_000_000


def _claim_output(out: Path, settings: dict[str, Any], overwrite: bool) -> None:
    """Refuse to mix frames of other settings into ``out`` (unless ``overwrite``, which removes the old tree)."""
    if not out.is_dir() or not any(out.iterdir()):
        return
    recorded: Any = None
    try:
        recorded = json.loads((out / "synth.json").read_text())
    except (OSError, ValueError):
        pass
    if not isinstance(recorded, dict):
        raise InvalidOptionError(f"--out {out} holds files that freespace synth did not write; choose a new or "
                                 f"empty folder")
    defaults = json.loads(json.dumps(asdict(SynthConfig())))  # keys added since the folder was written
    old = {"seed": recorded.get("seed"), **defaults, **(recorded.get("config") or {})}
    new = {"seed": settings["seed"], **settings["config"]}
    differ = [k for k in new if old.get(k) != new[k]]
    if differ and not overwrite:
        what = ", ".join(f"{k} {old.get(k)!r} → {new[k]!r}" for k in differ)
        raise InvalidOptionError(f"--out {out} holds a dataset rendered with other settings ({what}); choose "
                                 f"another --out, or add --overwrite to replace it")
    if overwrite:
        for name in ("data_road", "data_road_right"):
            shutil.rmtree(out / name, ignore_errors=True)
        for name in ("index.csv", "synth.json"):
            (out / name).unlink(missing_ok=True)


def write_dataset(out: PathLike, num: int, *, seed: int = 0, config: SynthConfig = SynthConfig(),
                  workers: int = 1, progress: bool = True, overwrite: bool = False) -> list[dict[str, Any]]:
    """Render frames ``0 … num−1`` and write them as a KITTI road tree (see the module docstring).

    ``num`` is at most :data:`MAX_FRAMES`, ``seed`` in ``0 … 2³²−1``. A folder that already holds a dataset
    rendered with other settings (seed or configuration, from its ``synth.json``) is refused unless
    ``overwrite``, which removes it first; with the same settings the frames are (re)written and the
    index covers frames ``0 … num−1``.

    Returns:
        The rows of ``index.csv`` (frame, category, scenario id, weather, rig parameters).
    """
    config.check()
    if not 1 <= num <= MAX_FRAMES:
        raise InvalidOptionError(f"--num must be in 1…{MAX_FRAMES:,}, got {num}")
    check_seed(seed)
    if workers < 1:
        raise InvalidOptionError(f"--workers must be ≥ 1, got {workers}")
    out = Path(out)
    check_writable(out, folder=True)
    settings = {"seed": seed, "config": json.loads(json.dumps(asdict(config)))}
    _claim_output(out, settings, overwrite)
    from freespace.log import progress_bar

    jobs = ((i, seed, config, str(out)) for i in range(num))
    bar = progress_bar(None, total=num, desc="synth", unit="frame", enabled=progress)
    rows: list[dict[str, Any]] = []
    if workers == 1:
        for job in jobs:
            rows.append(_render_and_write(job))
            bar.update()
    else:
        from freespace.parallel import worker_pool

        with worker_pool(workers, _init_worker, (os.getpid(),)) as pool:  # ends at once on Ctrl-C
            for row in pool.map(_render_and_write, jobs, chunksize=max(1, min(64, num // (4 * workers)))):
                rows.append(row)
                bar.update()
    bar.close()
    rows = _merge_index(out, rows)
    write_csv(out / "index.csv", INDEX_FIELDS, rows)
    write_json(out / "synth.json", {**settings, "num": len(rows)})
    return rows


def _merge_index(out: Path, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The index of every frame in ``out``: the rows just rendered, plus earlier rows (same settings) of
    frames that are still on disk and were not rendered again."""
    path = out / "index.csv"
    done = {r["frame"] for r in rows}
    kept = []
    if path.is_file():
        with path.open(newline="") as f:
            kept = [r for r in csv.DictReader(f) if r.get("frame") not in done
                    and (out / "data_road" / "training" / "image_2" / f"{r.get('frame')}.png").is_file()]
    return sorted(kept + rows, key=lambda r: int(r["index"]))
