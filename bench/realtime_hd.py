"""Real time at the camera's own resolution (issue 71): `freespace predict` end to end on 1080p frames and video
and on KITTI-size frames, with and without overlays, and where a frame's time goes.

    .venv/bin/python bench/realtime_hd.py --frames-1080 DIR --video-1080 FILE --kitti DIR
        [--onnx models/real-road-fast/model.onnx] [--baseline TREE] [--rounds 3] [--write-benchmarks]

- ``--frames-1080``: a folder of 1920×1080 PNG frames; ``--video-1080``: a 1920×1080 video (e.g. the highway video
  of ``real_dev/make.sh`` scaled ×2: real road frames at 1080p); ``--kitti``: KITTI-size (1242×375) PNG frames
  (the shared KITTI raw drive).
- ``--baseline``: the root of another checkout (e.g. a git worktree of an earlier commit): each case is run with
  its package too, alternated with this one in every round, so that both see the same machine.

Each run is a fresh `freespace predict` process; the figure is its own (first frame read to last output written,
start-up excluded: ``summary.json``'s ``frames_per_second``; a video's from the printed line). Medians over the
rounds. The profile (each stage's milliseconds per frame, ``--profile``) is this checkout's. Writes
``bench/out/realtime_hd.json`` and, with ``--write-benchmarks``, BENCHMARKS.md's section (for another ``--onnx``
than the fast model's, a section named after the model's folder).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_section  # noqa: E402

SECTION = "Real time at 1080p (bench/realtime_hd.py)"


def _run(tree: Path, args: list[str]) -> dict:
    """``freespace predict ARGS`` with the package of ``tree``; its frames per second and profile."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-m", "freespace.cli", "predict", *args, "--no-progress"], env=env,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"predict failed ({tree}): {done.stderr.strip().splitlines()[-1:]}")
    fps = float(re.search(r"([0-9.]+) frames per second", done.stdout).group(1))
    out = Path(args[args.index("--out") + 1])
    summary = out / "summary.json" if out.is_dir() else None
    profile = json.loads(summary.read_text()).get("profile_ms_per_frame") if summary and summary.exists() else None
    return {"fps": fps, "profile": profile}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames-1080", type=Path, required=True)
    p.add_argument("--video-1080", type=Path, required=True)
    p.add_argument("--kitti", type=Path, required=True)
    p.add_argument("--onnx", type=Path, default=ROOT / "models" / "real-road-fast" / "model.onnx")
    p.add_argument("--baseline", type=Path, help="another checkout's root, alternated with this one")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--write-benchmarks", action="store_true")
    a = p.parse_args()
    head = machine()
    cases = {"1080p folder → masks": (a.frames_1080, "dir", ["--no-overlays"]),
             "1080p folder → masks + overlays": (a.frames_1080, "dir", []),
             "1080p folder → masks + JPEG overlays": (a.frames_1080, "dir", ["--overlay-format", "jpg"]),
             "1080p video → overlay video": (a.video_1080, "mp4", []),
             "KITTI folder → masks": (a.kitti, "dir", ["--no-overlays"]),
             "KITTI folder → masks + overlays": (a.kitti, "dir", [])}
    trees = {"this": ROOT, **({"baseline": a.baseline} if a.baseline else {})}
    fps: dict[str, dict[str, list[float]]] = {c: {t: [] for t in trees} for c in cases}
    profiles: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(a.rounds):
            for case, (src, kind, extra) in cases.items():
                for name, tree in trees.items():
                    if name != "this" and "--overlay-format" in extra:  # an option earlier checkouts lack
                        continue
                    out = Path(tmp) / ("out.mp4" if kind == "mp4" else "out")
                    r = _run(tree, ["--onnx", str(a.onnx), "--input", str(src), "--out", str(out), *extra]
                             + (["--profile"] if name == "this" else []))
                    fps[case][name].append(r["fps"])
                    if r["profile"]:
                        profiles[case] = r["profile"]
                    shutil.rmtree(out) if out.is_dir() else out.unlink()
    rows = ["| case | " + " | ".join(f"{t}: frames per second" for t in trees) + " |",
            "|---|" + "---:|" * len(trees)]
    for case in cases:
        rows.append(f"| {case} | " + " | ".join(
            f"{statistics.median(v):.1f} ({', '.join(f'{x:.1f}' for x in v)})" if v else "—"
            for v in fps[case].values()) + " |")
    prof = ["| case | " + " | ".join(["decode", "preprocess", "network", "postprocess", "write", "end to end"]) + " |",
            "|---|" + "---:|" * 6]
    for case, pr in profiles.items():
        prof.append(f"| {case} | " + " | ".join(f"{pr[k]:.1f}" for k in ("decode", "preprocess", "network",
                                                                         "postprocess", "write", "end_to_end"))
                    + " |")
    model = a.onnx.relative_to(ROOT) if a.onnx.is_relative_to(ROOT) else a.onnx
    text = (f"`bench/realtime_hd.py` on {head}; model `{model}` (ONNX Runtime, the cores this process may use); "
            f"medians over {a.rounds} rounds (each round's figures in brackets)"
            f"{', alternated with ' + str(a.baseline) if a.baseline else ''}.\n\n" + "\n".join(rows)
            + "\n\nWhere a frame's time goes (this checkout, `predict --profile`, milliseconds per frame, each "
              "stage's own time; in the pipeline the stages overlap across threads):\n\n" + "\n".join(prof))
    (ROOT / "bench" / "out").mkdir(parents=True, exist_ok=True)
    (ROOT / "bench" / "out" / "realtime_hd.json").write_text(json.dumps({"machine": head, "fps": fps,
                                                                         "profiles": profiles}, indent=2))
    print(text)
    if a.write_benchmarks:  # another model than the fast one gets a section of its own
        default = a.onnx.resolve() == (ROOT / "models" / "real-road-fast" / "model.onnx").resolve()
        write_section(SECTION if default else f"{SECTION}: {a.onnx.resolve().parent.name}", text)


if __name__ == "__main__":
    main()
