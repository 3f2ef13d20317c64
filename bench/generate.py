"""Speed of the DS-Generator per KITTI-size frame (1242×375), and of `freespace generate` end to end.

Compares the robust fit + warp with the floor (plain least squares + one cv2.remap) and with a literal
per-pixel implementation of the paper's formula. Uses the real KITTI frame in ../shared/data when it is
there, otherwise a rendered frame of the same size. Prints the figures and writes them to BENCHMARKS.md.

    .venv/bin/python bench/generate.py
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_section  # noqa: E402
from freespace.geometry import fit_road_model, generate_view  # noqa: E402
from freespace.io.codecs import read_disparity, read_image, write_image  # noqa: E402

SHARED = ROOT.parent / "shared" / "data" / "kitti_stereo_2015"
POLYGON = [(400, 374), (400, 240), (570, 190), (615, 190), (700, 225), (880, 300), (880, 374)]


def load_frame():
    if (SHARED / "image_2" / "000000_10.png").is_file():
        left = read_image(SHARED / "image_2" / "000000_10.png")
        right = read_image(SHARED / "image_3" / "000000_10.png")
        disp_path = SHARED / "disp_occ_0" / "000000_10.png"
        source = "real KITTI stereo 2015 frame 000000_10, LiDAR disparity"
        road = np.zeros(left.shape[:2], np.uint8)
        cv2.fillPoly(road, [np.array(POLYGON, np.int32)], 1)
        return left, right, read_disparity(disp_path), road.astype(bool), disp_path, source
    from freespace.data.synthetic import SynthConfig, render_sample  # the built-in renderer at KITTI's size

    sample = render_sample(0, 0, SynthConfig(width=1242, height=375))
    disp_path = Path(tempfile.mkdtemp()) / "d.npy"
    np.save(disp_path, np.nan_to_num(sample.disparity, nan=0.0))  # sky: no disparity
    source = "rendered 1242×375 frame (freespace synth, frame 0 of seed 0), exact disparity, its road label"
    return sample.left, sample.right, read_disparity(disp_path), sample.label.road, disp_path, source


def floor(left: np.ndarray, right: np.ndarray, disp: np.ndarray, road: np.ndarray) -> np.ndarray:
    """Plain least squares on the valid road pixels + one cv2.remap: the least any implementation does."""
    v, u = np.nonzero(road & (disp > 0))
    A = np.stack([u, v, np.ones_like(u)], axis=1).astype(np.float64)
    a, b, c = np.linalg.lstsq(A, disp[v, u].astype(np.float64), rcond=None)[0]
    h, w = disp.shape
    uu = np.arange(w, dtype=np.float32)[None, :]
    vv = np.arange(h, dtype=np.float32)[:, None]
    map_x = ((1 - a) * uu - b * vv - c).astype(np.float32)
    map_y = np.broadcast_to(vv, (h, w)).astype(np.float32)
    return cv2.remap(right, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def literal(left: np.ndarray, right: np.ndarray, disp: np.ndarray, road: np.ndarray) -> np.ndarray:
    """The paper's formulas pixel by pixel in Python: sums for the fit, g(p) = t(H p) bilinear per pixel."""
    h, w = disp.shape
    n = su = sv = sd = suu = svv = suv = sud = svd = 0.0
    for v in range(h):
        for u in range(w):
            d = disp[v, u]
            if road[v, u] and d > 0:
                n += 1
                su += u
                sv += v
                sd += d
                suu += u * u
                svv += v * v
                suv += u * v
                sud += u * d
                svd += v * d
    M = np.array([[suu, suv, su], [suv, svv, sv], [su, sv, n]])
    a, b, c = np.linalg.solve(M, np.array([sud, svd, sd]))
    out = left.copy()
    for v in range(h):
        for u in range(w):
            x = (1 - a) * u - b * v - c
            if 0 <= x <= w - 1:
                x0 = min(int(x), w - 2)
                f = x - x0
                out[v, u] = (1 - f) * right[v, x0] + f * right[v, x0 + 1]
    return out


def alternated(fns: list, rounds: int = 200, warmup: int = 5) -> list[float]:
    """Median wall seconds of each of ``fns``, timed in turn within every round (so that a slower or faster
    stretch of the machine falls on all of them alike, which timing one after the other does not)."""
    for _ in range(warmup):
        for fn in fns:
            fn()
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(rounds):
        for k, fn in enumerate(fns):
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    return [statistics.median(t) for t in times]


def cli_seconds(args: list[str], repeat: int = 7) -> float:
    exe = str(Path(sys.executable).with_name("freespace"))
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([exe, *args], check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    left, right, disp, road, disp_path, source = load_frame()
    model = fit_road_model(disp, road)
    t_floor, t_fit, t_warp, t_ours = alternated([lambda: floor(left, right, disp, road),
                                                 lambda: fit_road_model(disp, road),
                                                 lambda: generate_view(left, right, model),
                                                 lambda: generate_view(left, right, fit_road_model(disp, road))])
    t0 = time.perf_counter()
    literal(left, right, disp, road)
    t_literal = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_image(tmp / "L.png", left)
        write_image(tmp / "R.png", right)
        write_image(tmp / "gt.png", road.astype(np.uint8) * 255)
        base = ["generate", "--reference", str(tmp / "L.png"), "--target", str(tmp / "R.png"),
                "--road-mask", str(tmp / "gt.png"), "--out", str(tmp / "G.png")]
        t_cli_file = cli_seconds(base + ["--disparity", str(disp_path)])
        t_cli_sgbm = cli_seconds(base)
    rows = [
        ("floor: plain least squares + one cv2.remap", t_floor),
        ("robust fit (MSAC + 0/1-reweighted least squares)", t_fit),
        ("warp (`generate_view`)", t_warp),
        ("**robust fit + warp (ours)**", t_ours),
        ("literal per-pixel Python implementation of the paper's formulas", t_literal),
    ]
    table = "| step | ms per frame |\n|---|---:|\n" + "\n".join(f"| {k} | {v * 1e3:.1f} |" for k, v in rows)
    body = f"""Machine: {machine()}.
Frame: {source}, 1242×375, {int(road.sum())} road pixels in the label ({model.num_valid} with a disparity).
Command: `.venv/bin/python bench/generate.py` (medians of 200 rounds, the four timed in turn within each round; the
literal implementation once).

{table}

- robust fit + warp / floor: **{t_ours / t_floor:.2f}×** (target ≤ 1.5×, issue 71); literal / ours:
  {t_literal / t_ours:.0f}×.
- `freespace generate` for one pair, process start to exit (median of 7): **{t_cli_file:.2f} s** with a
  disparity file, **{t_cli_sgbm:.2f} s** with SGBM disparity and left-right check (target < 1 s).
"""
    print(body)
    write_section("DS-Generator (bench/generate.py)", body)


if __name__ == "__main__":
    main()
