"""Speed of the built-in stereo scene renderer: seconds per 640×480 stereo pair on one core, and the
throughput of `freespace synth --workers 2`. Prints the figures and writes them to BENCHMARKS.md.

    .venv/bin/python bench/synth.py
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, write_section  # noqa: E402
from freespace.data.synthetic import SynthConfig, render_sample, write_dataset  # noqa: E402

FRAMES = 30


def per_frame(config: SynthConfig) -> tuple[float, float]:
    render_sample(0, seed=0, config=config)  # warm-up
    times = []
    for i in range(FRAMES):
        t0 = time.perf_counter()
        render_sample(i * 7, seed=0, config=config)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), max(times)


def main() -> None:
    cv2.setNumThreads(1)
    planar = per_frame(SynthConfig())
    non_planar = per_frame(SynthConfig(planar=False))
    cv2.setNumThreads(0)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_dataset(Path(tmp) / "w2", 40, config=SynthConfig(), workers=2, progress=False)
        t_w2 = (time.perf_counter() - t0) / 40
    body = f"""Machine: {machine()}.
Command: `.venv/bin/python bench/synth.py` ({FRAMES} frames each, OpenCV limited to one thread).

| 640×480 stereo pair (left + right + disparity + label) | median s | max s |
|---|---:|---:|
| planar road, one core | **{planar[0]:.3f}** | {planar[1]:.3f} |
| non-planar road (slopes, camber), one core | {non_planar[0]:.3f} | {non_planar[1]:.3f} |

- target ≤ 0.25 s per pair on one core.
- `freespace synth --workers 2`, rendering and writing PNGs: {t_w2:.3f} s per frame (40 frames).
"""
    print(body)
    write_section("Stereo scene renderer (bench/synth.py)", body)


if __name__ == "__main__":
    main()
