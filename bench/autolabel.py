"""Quality of `freespace autolabel` against human labels: precision, recall and F of the road class on the
pixels the autolabel covers (not don't care), and coverage (the share of the human label's evaluated pixels
that the autolabel does not mark don't care). Counts are summed over each set's frames.

- rendered `test` (seed 0) and `shifted` (seed 1, the evidence run's wider rigs) sets, 320×240, frames 0…N−1
  of `freespace synth` with the evidence run's options (rendered in memory, byte-identical to the files),
  from the renderer's exact disparity and from SGBM (`--max-disparity 64`) on the rendered pair;
- the two real KITTI stereo 2015 frames (../shared/data/kitti_stereo_2015, road_mask/ the human label),
  from SGBM on the real pair and from the LiDAR disparity disp_occ_0 (baseline 0.54 m);
- the three real KITTI road frames with LiDAR depth (../shared/data/kitti_road_depth), and the KITTI raw
  frames of freespace/evaluation/real_frames.py (SGBM from the pair where there is a right image, LiDAR where
  there is a scan: $FREESPACE_KITTI_RAW), against its road polygons: the polygons mark road only, so only
  recall and coverage (inside the polygon) are measured there;
- on KITTI stereo 2015 also ``fused``: LiDAR and SGBM joined (freespace.data.disparity.fuse_disparities).

    .venv/bin/python bench/autolabel.py [--frames 40] [--csv OUT.csv] [--shared DIR] [--write]

`--write` puts the table into BENCHMARKS.md. A frame whose road plane is not found ("no label") counts
with every pixel don't care.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_section  # noqa: E402
from freespace.data.disparity import fuse_disparities  # noqa: E402
from freespace.data.synthetic import SynthConfig, render_sample  # noqa: E402
from freespace.datagen.autolabel import autolabel  # noqa: E402
from freespace.errors import DatasetError, RoadFitError  # noqa: E402
from freespace.evaluation.real_frames import KITTI_ROAD_POLYGONS as ROAD_POLYGONS  # noqa: E402
from freespace.evaluation.real_frames import ROAD_POLYGONS as ROAD_POLYGONS_BY_NAME  # noqa: E402
from freespace.evaluation.real_frames import polygon_mask  # noqa: E402
from freespace.geometry import compute_disparity  # noqa: E402
from freespace.geometry.depth import depth_to_disparity, rig_from_kitti  # noqa: E402
from freespace.io.codecs import read_depth, read_disparity, read_image, read_road_label  # noqa: E402
from freespace.io.kitti import read_kitti_calib  # noqa: E402
from freespace.labels import RoadLabel  # noqa: E402

SETS = {"test": (SynthConfig(width=320, height=240, frames_per_scenario=5), 0),
        "shifted": (SynthConfig(width=320, height=240, frames_per_scenario=5, max_roll_deg=6.0,
                                camera_heights=(1.0, 2.6), pitches_deg=(-5.0, 5.0), baselines=(0.2, 2.0)), 1)}
Case = tuple[str, str, np.ndarray, RoadLabel, float | None]  # set, source, disparity, human label, baseline


def rendered(frames: int) -> Iterator[Case]:
    for name, (config, seed) in SETS.items():
        for i in range(frames):
            s = render_sample(i, seed, config)
            yield f"rendered {name}", "exact", s.disparity, s.label, s.calibration.baseline
            yield f"rendered {name}", "SGBM", compute_disparity(s.left, s.right, max_disparity=64), s.label, \
                s.calibration.baseline


def kitti_stereo(shared: Path) -> Iterator[Case]:
    root = shared / "kitti_stereo_2015"
    for path in sorted((root / "road_mask").glob("*.png")):
        label = read_road_label(path)
        left, right = read_image(root / "image_2" / path.name), read_image(root / "image_3" / path.name)
        yield "KITTI stereo 2015", "SGBM", compute_disparity(left, right), label, 0.54
        lidar = read_disparity(root / "disp_occ_0" / path.name)
        yield "KITTI stereo 2015", "LiDAR", lidar, label, 0.54
        yield "KITTI stereo 2015", "fused", fuse_disparities(lidar, compute_disparity(left, right)), label, 0.54


def kitti_road_depth(shared: Path) -> Iterator[Case]:
    root = shared / "kitti_road_depth"
    for (split, name), polygon in sorted(ROAD_POLYGONS.items()):
        base = root / split
        rig = rig_from_kitti(read_kitti_calib(base / "calib" / f"{name}.txt"))
        disparity = depth_to_disparity(read_depth(base / "depth_u16" / f"{name}.png"), rig.fx, rig.baseline)
        road = np.zeros(disparity.shape, np.uint8)
        cv2.fillPoly(road, [np.array(polygon, np.int32)], 1)
        yield "KITTI road (polygons)", "LiDAR depth", disparity, RoadLabel(road > 0, road > 0), rig.baseline


def kitti_raw_polygons() -> Iterator[Case]:
    """The KITTI raw frames of real_frames.py's polygons, each from every source its drive has (SGBM where
    there is a right image, LiDAR where there is a scan, fused where both)."""
    from freespace.data import get_dataset
    from freespace.evaluation.real_frames import KITTI_RAW, SHARED

    wanted = {name: polygon for name, polygon in ROAD_POLYGONS_BY_NAME.items() if "_drive_" in name}
    for root in [r for r in (SHARED / "kitti_raw", KITTI_RAW) if r is not None and r.is_dir()]:
        for source, shown in (("sgbm", "SGBM"), ("lidar", "LiDAR"), ("fused", "fused")):
            try:
                ds = get_dataset("kitti-raw", root, disparity_source=source)
            except DatasetError:  # no frame has a scan (lidar)
                continue
            for name, polygon in sorted(wanted.items()):
                if name not in {f.name for f in ds.frames}:
                    continue
                frame = ds.frames[ds.index(name)]
                if (source == "sgbm" and frame.right is None) or (source == "lidar" and frame.velodyne is None) or \
                        (source == "fused" and (frame.right is None or frame.velodyne is None)):
                    continue
                sample = ds.load(ds.index(name), label=False)
                road = polygon_mask(polygon, sample.left.shape[:2])
                yield "KITTI raw (polygons)", shown, sample.disparity, RoadLabel(road, road), \
                    sample.calibration.baseline
        wanted = {n: p for n, p in wanted.items() if n not in {f.name for f in ds.frames}}  # the shared copy first


def measure(cases: Iterator[Case]) -> list[dict]:
    """Summed counts per (set, source) → rows with precision, recall, F, coverage (percent)."""
    acc: dict[tuple[str, str], np.ndarray] = {}
    for set_name, source, disparity, human, baseline in cases:
        t0 = time.perf_counter()
        try:
            auto = autolabel(disparity, baseline=baseline).label
            failed = 0
        except RoadFitError:  # no label: every pixel don't care
            auto = RoadLabel(np.zeros_like(human.road), np.zeros_like(human.road))
            failed = 1
        seconds = time.perf_counter() - t0
        evaluated = human.valid
        covered = auto.valid & evaluated
        counts = np.array([np.count_nonzero(auto.road & human.road & covered),
                           np.count_nonzero(auto.road & ~human.road & covered),
                           np.count_nonzero(~auto.road & human.road & covered),
                           np.count_nonzero(covered), np.count_nonzero(evaluated), 1, failed, seconds])
        acc[(set_name, source)] = acc.get((set_name, source), 0) + counts
    rows = []
    for (set_name, source), (tp, fp, fn, covered, evaluated, frames, failed, seconds) in acc.items():
        precision = tp / (tp + fp) if tp + fp and "(polygons)" not in set_name else float("nan")
        recall = tp / (tp + fn) if tp + fn else float("nan")
        f = 2 * precision * recall / (precision + recall) if np.isfinite(precision) else float("nan")
        rows.append({"set": set_name, "disparity": source, "frames": int(frames), "failed": int(failed),
                     "precision": 100 * precision,
                     "recall": 100 * recall, "F": 100 * f, "coverage": 100 * covered / evaluated,
                     "seconds_per_frame": seconds / frames})
    return rows


def table(rows: list[dict]) -> str:
    def pct(x: float) -> str:
        return f"{x:.1f}" if np.isfinite(x) else "–"

    lines = ["| set | disparity | frames | no label | precision % | recall % | F % | coverage % | s/frame |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['set']} | {r['disparity']} | {r['frames']} | {r['failed']} | {pct(r['precision'])} | "
                     f"{pct(r['recall'])} | {pct(r['F'])} | {pct(r['coverage'])} | {r['seconds_per_frame']:.2f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="rendered frames per set (default 40)")
    parser.add_argument("--csv", metavar="OUT.csv", help="also write the rows as CSV")
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "data", metavar="DIR",
                        help="the shared real samples (default ../shared/data beside the checkout)")
    parser.add_argument("--write", action="store_true", help="write the table into BENCHMARKS.md")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    cases = [rendered(args.frames)]
    if args.shared.is_dir():
        cases += [kitti_stereo(args.shared), kitti_road_depth(args.shared), kitti_raw_polygons()]
    else:
        print(f"({args.shared} not found: real frames skipped)")
    rows = [r for c in cases for r in measure(c)]
    text = table(rows)
    print(text)
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
            writer.writeheader()
            writer.writerows(rows)
    if args.write:
        write_section("Autolabel quality (`freespace autolabel` against human labels)",
                      f"`OMP_NUM_THREADS=1 .venv/bin/python bench/autolabel.py --frames {args.frames} --write` on "
                      f"{machine()}.\n\nPrecision, recall and F of the road class on the pixels the autolabel "
                      f"covers; coverage: the share of the human label's evaluated pixels that the autolabel does "
                      f"not mark don't care (counts summed over each set's frames). The KITTI road polygons mark "
                      f"road only: recall and coverage there are inside the polygons, no precision.\n\n{text}")


if __name__ == "__main__":
    main()
