"""Write the built-in renderer's frames as a KITTI road tree (``freespace synth``).

Tree written under ``OUT``::

    OUT/data_road/training/image_2/<cat>_<id>.png          left images
    OUT/data_road/training/gt_image_2/<cat>_road_<id>.png  road labels (KITTI colours)
    OUT/data_road/training/calib/<cat>_<id>.txt            KITTI calibration text
    OUT/data_road/training/disparity/<cat>_<id>.png        exact left disparity (KITTI uint16)
    OUT/data_road_right/training/image_3/<cat>_<id>.png    right images
    OUT/index.csv                                          frame, category, scenario, weather, rig
    OUT/synth.json                                         seed and configuration

``pitch_deg`` in ``index.csv`` (and ``SynthConfig.pitches_deg``) is positive when the camera looks down at the road.
``<id>`` is the global frame index, so frame i has the same name and bytes for a given seed and
configuration whatever ``num`` is.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.synthetic.render import StereoSample, render_sample
from freespace.data.synthetic.scene import SynthConfig
from freespace.errors import InvalidOptionError, check_seed, param
from freespace.io.codecs import png_disparity_overflow, road_label_to_kitti, write_disparity, write_image
from freespace.io.files import PathLike, atomic_write_text, check_writable, write_csv, write_json
from freespace.io.outdir import check_settings, claim_folder

__all__ = ["write_dataset", "write_sample", "format_kitti_calib", "INDEX_FIELDS"]

log = logging.getLogger(__name__)

#: the sign of ``pitch_deg`` and ``pitches_deg``, recorded in ``synth.json``: a folder written when positive
#: meant looking up is refused (its index.csv would mix the two signs)
PITCH_SIGN = "positive down"

INDEX_FIELDS = ["frame", "index", "category", "scenario", "weather", "roll_deg", "pitch_deg", "baseline_m",
                "focal_px", "camera_height_m", "lanes", "planar"]


def format_kitti_calib(calib: dict[str, np.ndarray]) -> str:
    """KITTI calibration text (``KEY: v1 v2 ...`` in %.12e, row-major) of a matrix dict."""
    lines = []
    for key in ("P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_cam_to_road"):
        if key in calib:
            lines.append(f"{key}: " + " ".join(f"{x:.12e}" for x in np.asarray(calib[key]).ravel()))
    return "\n".join(lines) + "\n"


def write_sample(sample: StereoSample, out: PathLike, split: str = "training") -> int:
    """Write one rendered frame into a KITTI road tree at ``out`` (atomic writes).

    Returns:
        How many of its disparities exceed the KITTI PNG's 255.996 px (written as invalid; the caller reports
        them, and the PNG writer's own warning is silenced).
    """
    out = Path(out)
    base = out / "data_road" / split
    cat, idx = sample.name.split("_")
    write_image(base / "image_2" / f"{sample.name}.png", sample.left)
    write_image(base / "gt_image_2" / f"{cat}_road_{idx}.png", road_label_to_kitti(sample.label))
    atomic_write_text(base / "calib" / f"{sample.name}.txt", format_kitti_calib(sample.kitti_calib))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        write_disparity(base / "disparity" / f"{sample.name}.png", sample.disparity)
    write_image(out / "data_road_right" / split / "image_3" / f"{sample.name}.png", sample.right)
    return png_disparity_overflow(sample.disparity)


def _index_row(sample: StereoSample) -> dict[str, Any]:
    m = sample.meta
    return {"frame": sample.name, "index": sample.index, "category": sample.category, "scenario": sample.scenario,
            "weather": m["weather"], "roll_deg": f"{m['roll_deg']:.6f}", "pitch_deg": f"{m['pitch_deg']:.6f}",
            "baseline_m": f"{m['baseline_m']:.6f}", "focal_px": f"{m['focal_px']:.4f}",
            "camera_height_m": f"{m['camera_height_m']:.6f}", "lanes": m["lanes"], "planar": int(m["planar"])}


def _render_and_write(job: tuple[int, int, SynthConfig, str]) -> tuple[dict[str, Any], int]:
    """Render and write one frame; its ``index.csv`` row and its disparities beyond the PNG's range."""
    index, seed, config, out = job
    sample = render_sample(index, seed, config)
    return _index_row(sample), write_sample(sample, out)


def _init_worker(parent: int) -> None:
    import cv2

    from freespace.runtime.parallel import init_worker

    init_worker(parent)
    cv2.setNumThreads(1)


MAX_FRAMES = 1_000_000


#: what ``synth`` writes into OUT (:mod:`freespace.io.outdir` entries)
OUT_ENTRIES = ("data_road/", "data_road_right/", "index.csv", "synth.json")


def _recorded(synth_json: dict[str, Any]) -> dict[str, Any]:
    """The settings of a ``synth.json`` as ``write_dataset`` compares them: keys that an older version did not
    write take their defaults (index.csv's pitch was positive up before it followed the package)."""
    defaults = json.loads(json.dumps(asdict(SynthConfig())))
    return {"seed": synth_json.get("seed"), "pitch_sign": synth_json.get("pitch_sign", "positive up"), **defaults,
            **(synth_json.get("config") or {})}


def write_dataset(out: PathLike, num: int, *, seed: int = 0, config: SynthConfig = SynthConfig(),
                  workers: int = 1, progress: bool = True, overwrite: bool = False) -> list[dict[str, Any]]:
    """Render frames ``0 … num−1`` and write them as a KITTI road tree (see the module docstring).

    ``num`` is at most :data:`MAX_FRAMES`, ``seed`` in ``0 … 2³²−1``. A folder that already holds a dataset
    rendered with other settings (seed or configuration, from its ``synth.json``) is refused unless
    ``overwrite``, which first removes what synth wrote there; with the same settings the frames are (re)written and the
    index covers frames ``0 … num−1``.

    Returns:
        The rows of ``index.csv`` (frame, category, scenario id, weather, rig parameters).
    """
    config.check()
    if not 1 <= num <= MAX_FRAMES:
        raise InvalidOptionError(f"{param('num')} must be in 1…{MAX_FRAMES:,}, got {num}")
    check_seed(seed)
    if workers < 1:
        raise InvalidOptionError(f"{param('workers')} must be ≥ 1, got {workers}")
    out = Path(out)
    check_writable(out, folder=True)
    # pitch_sign: index.csv's pitch_deg and pitches_deg were positive up before they followed the package
    settings = {"seed": seed, "pitch_sign": PITCH_SIGN, "config": json.loads(json.dumps(asdict(config)))}
    with claim_folder(out, "synth", entries=OUT_ENTRIES) as folder:
        check_settings(out / "synth.json", {"seed": seed, "pitch_sign": PITCH_SIGN, **settings["config"]}, overwrite,
                       "a dataset rendered", _recorded)
        if overwrite:
            folder.forget(OUT_ENTRIES)
            folder.record(OUT_ENTRIES)
        write_json(out / "synth.json", settings)  # before the first frame: an interrupted run resumes
        return _render_frames(out, num, seed, config, settings, workers, progress)


def _render_frames(out: Path, num: int, seed: int, config: SynthConfig, settings: dict[str, Any], workers: int,
                   progress: bool) -> list[dict[str, Any]]:
    """Render frames ``0 … num−1`` into ``out`` and write ``index.csv`` and ``synth.json``."""
    from freespace.runtime.log import progress_bar

    jobs = ((i, seed, config, str(out)) for i in range(num))
    bar = progress_bar(None, total=num, desc="synth", unit="frame", enabled=progress)
    rows: list[dict[str, Any]] = []
    beyond: dict[str, int] = {}  # frame → disparities beyond the PNG's range

    def done(result: tuple[dict[str, Any], int]) -> None:
        rows.append(result[0])
        if result[1]:
            beyond[result[0]["frame"]] = result[1]
        bar.update()

    if workers == 1:
        for job in jobs:
            done(_render_and_write(job))
    else:
        from freespace.runtime.parallel import worker_pool

        with worker_pool(workers, _init_worker, (os.getpid(),)) as pool:  # ends at once on Ctrl-C
            for result in pool.map(_render_and_write, jobs, chunksize=max(1, min(64, num // (4 * workers)))):
                done(result)
    bar.close()
    if beyond:
        log.warning("%d disparities in %d of %d frames (first %s) exceed the 255.996 px of KITTI's disparity PNG "
                    "and are stored as invalid; a smaller baseline range or image width keeps them",
                    sum(beyond.values()), len(beyond), len(rows), min(beyond))
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
