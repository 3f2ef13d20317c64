"""Real time on the CPU (issue 48): frames per second end to end and for the network alone, the profile of one
frame, F on real and rendered labelled frames, int8 against float32 — for the fast model and the best model.

    .venv/bin/python bench/realtime.py --fast FAST.ckpt --best BEST.ckpt --frames DIR [--rendered DIR]
        [--real DIR] [--out DIR] [--repeat N] [--section-file F] [--write-benchmarks]

- ``--fast`` / ``--best``: training checkpoints (the best model: the most accurate of the same training). Left
  out, both are trained briefly here on rendered frames (``freespace synth`` + ``freespace train``: Fast-SCNN
  and a Lite0 U-Net at 192×640, 8 epochs; tens of minutes on a busy 2-core machine) — placeholders until
  the real models exist, and said so in the output.
- ``--frames``: real KITTI-size (1242×375) frames, a folder; the end-to-end runs read them (and a video
  made of them), and int8 is calibrated on them.
- ``--real``: labelled real frames, ``image_2/*.png`` and ``road_mask/*.png`` (KITTI stereo 2015's two in the
  shared data); skipped when absent. ``--rendered``: a rendered KITTI-road tree (``data_road/training``) whose
  frames listed in ``--split-file`` (default: all) are scored.

Each model is exported to ONNX (float32, and int8 calibrated on ``--frames``) and run through ONNX Runtime
(every graph optimisation, one intra-op thread per allowed core). End to end = ``freespace predict``'s path:
first frame read to last mask written, masks only (``--no-overlays``), through the pipeline; the same without
the pipeline, with overlays, and on a video, for comparison. The profile times each step of one frame alone
(wall and CPU milliseconds, medians over the frames). Writes ``realtime.json`` and ``realtime.md`` to ``--out``
(default ``bench/out/``), and the markdown as BENCHMARKS.md's section with ``--write-benchmarks`` (or to
``--section-file``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, section_text, write_section  # noqa: E402

SECTION = "Real time on the CPU (bench/realtime.py)"
KITTI_RAW = Path("/work/shared/data/kitti_raw/2011_09_26/2011_09_26_drive_0001_sync/image_02/data")
REAL = Path("/work/shared/data/kitti_stereo_2015")


def versions() -> dict[str, str]:
    """The versions of what the figures depend on."""
    import cv2
    import onnxruntime
    import torch

    return {"onnxruntime": onnxruntime.__version__, "torch": torch.__version__, "opencv": cv2.__version__,
            "numpy": np.__version__, "python": sys.version.split()[0]}


def train_placeholders(work: Path) -> dict[str, Path]:
    """Render 120 frames at 1242×375 and train Fast-SCNN (light) and a Lite0 U-Net (ImageNet encoder) on them,
    8 epochs at 192×640 each: the same training for both. Returns the best checkpoints."""
    cli = [sys.executable, "-m", "freespace.cli"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    data = work / "synth"
    if not (data / "synth.json").exists():
        subprocess.run([*cli, "synth", "--out", str(data), "--num", "120", "--width", "1242", "--height", "375"],
                       check=True, env=env)
    specs = {"fast": ["--model", "fastscnn", "--preset", "light"],
             "best": ["--model", "unet", "--encoder-name", "efficientnet-lite0", "--encoder-weights", "imagenet"]}
    out = {}
    for key, spec in specs.items():
        run = work / f"run-{key}"
        ckpt = run / "checkpoints" / "best.ckpt"
        if not ckpt.exists():
            subprocess.run([*cli, "train", "--dataset", "synth", "--root", str(data), "--out", str(run), *spec,
                            "--image-size", "192x640", "--epochs", "8", "--patience", "8", "--batch-size", "4",
                            "--lr", "0.01", "--no-progress"], check=True, env=env)
        out[key] = ckpt
    return out


def network_ms(predictor: Any, image: np.ndarray, repeat: int) -> float:
    """Median wall milliseconds of the network alone on one prepared frame (batch of 1)."""
    x = [predictor.prepare(image)]
    for _ in range(3):
        predictor.infer(x)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        predictor.infer(x)
        times.append(time.perf_counter() - t0)
    return 1000 * statistics.median(times)


def profile(predictor: Any, paths: list[Path], out: Path) -> dict[str, dict[str, float]]:
    """One frame at a time, each step alone: decode, preprocess, network, postprocess (upsample, 8-bit),
    write (PNG encode + atomic write). Median wall and CPU (this thread's) milliseconds over ``paths``."""
    from freespace.evaluation.metrics import to_confidence
    from freespace.io.codecs import read_image, write_image

    steps: dict[str, list[tuple[float, float]]] = {k: [] for k in
                                                  ("decode", "preprocess", "network", "postprocess", "write")}

    def timed(name: str, fn: Any) -> Any:
        w0, c0 = time.perf_counter(), time.thread_time()
        result = fn()
        steps[name].append((1000 * (time.perf_counter() - w0), 1000 * (time.thread_time() - c0)))
        return result

    for i, path in enumerate(paths):
        image = timed("decode", lambda: read_image(path))
        x = timed("preprocess", lambda: predictor.prepare(image))
        prob = timed("network", lambda: predictor.infer([x])[0])
        conf = timed("postprocess", lambda: to_confidence(predictor.restore(prob, image.shape[:2])))
        timed("write", lambda: write_image(out / f"{i}.png", conf))
    # the first frame warms caches and the session up: left out
    return {k: {"wall_ms": statistics.median(w for w, _ in v[1:]), "cpu_ms": statistics.median(c for _, c in v[1:])}
            for k, v in steps.items()}


def end_to_end(predictor: Any, frames: Path, video: Path, work: Path) -> dict[str, dict[str, float]]:
    """``freespace predict``'s frame rate on the folder (masks only; pipeline or not; with overlays) and on the
    video (overlaid MP4 out)."""
    from freespace.inference.predict import predict_folder, predict_video

    runs = {}

    def record(name: str, s: dict[str, Any], cpu: float) -> None:
        # CPU milliseconds per frame (the whole process): what the frame rate would be bounded by on an idle
        # machine with every core busy, a figure a loaded machine distorts less than the wall time
        runs[name] = {"fps": s["frames_per_second"], "network_share": s["network_share"], "frames": s["frames"],
                      "cpu_ms_per_frame": 1000 * cpu / s["frames"]}

    for name, kw in (("folder, masks, pipeline", {"overlays": False}),
                     ("folder, masks, sequential", {"overlays": False, "pipeline": False}),
                     ("folder, masks + overlays, pipeline", {})):
        out = work / "e2e"
        c0 = time.process_time()
        s = predict_folder(predictor, frames, out, batch_size=1, progress=False, **kw)
        record(name, s, time.process_time() - c0)
        shutil.rmtree(out)
    c0 = time.process_time()
    s = predict_video(predictor, video, work / "e2e.mp4", batch_size=1, progress=False)
    record("video → video, pipeline", s, time.process_time() - c0)
    return runs


def f_scores(predictor: Any, pairs: list[tuple[Path, Path]]) -> dict[str, float] | None:
    """F (threshold 0.5) and the KITTI MaxF of ``predictor`` over labelled ``(image, label)`` pairs, from summed
    counts at the images' own size."""
    from freespace.evaluation.metrics import RoadEvaluator
    from freespace.io.codecs import read_image, read_road_label

    if not pairs:
        return None
    ev = RoadEvaluator()
    for image, label in pairs:
        lab = read_road_label(label)
        ev.process(predictor.predict([read_image(image)])[0], lab.road, lab.valid)
    r = ev.evaluate()
    return {"f": r["f_score"], "max_f": r["max_f"], "images": r["images"]}


def real_pairs(root: Path) -> list[tuple[Path, Path]]:
    if not (root / "road_mask").is_dir():
        return []
    return [(p, root / "road_mask" / p.name) for p in sorted((root / "image_2").glob("*.png"))
            if (root / "road_mask" / p.name).exists()]


def rendered_pairs(root: Path, split_file: Path | None) -> list[tuple[Path, Path]]:
    training = root / "data_road" / "training"
    if not training.is_dir():
        return []
    names = (split_file.read_text().split() if split_file
             else [p.stem for p in sorted((training / "image_2").glob("*.png"))])
    pairs = []
    for name in names:
        cat, idx = name.rsplit("_", 1)
        pairs.append((training / "image_2" / f"{name}.png", training / "gt_image_2" / f"{cat}_road_{idx}.png"))
    return pairs


def bench_model(key: str, ckpt: Path, frames: Path, video: Path, work: Path, repeat: int,
                real: list, rendered: list) -> dict[str, Any]:
    from freespace.inference.export import export_model
    from freespace.inference.predictor import Predictor
    from freespace.io.codecs import read_image

    paths = sorted(frames.glob("*.png"))
    image = read_image(paths[0])
    result: dict[str, Any] = {"checkpoint": str(ckpt)}
    for dtype in ("float32", "int8"):
        onnx = work / f"{key}-{dtype}.onnx"
        r = export_model(ckpt, "onnx", onnx, calibration=frames if dtype == "int8" else None)
        predictor = Predictor(onnx=onnx)
        row: dict[str, Any] = {"model": predictor.name, "internal_size": list(predictor.resize_to or image.shape[:2]),
                               "onnx_bytes": onnx.stat().st_size}
        if dtype == "int8":
            row["against_float32_on_calibration_frames"] = r["int8"]
        row["network_ms"] = network_ms(predictor, image, repeat)
        row["end_to_end"] = end_to_end(predictor, frames, video, work)
        (work / "profile").mkdir(exist_ok=True)
        row["profile"] = profile(predictor, paths[: min(len(paths), 21)], work / "profile")
        row["f_real"] = f_scores(predictor, real)
        row["f_rendered"] = f_scores(predictor, rendered)
        result[dtype] = row
        print(f"{key} {dtype}: network {row['network_ms']:.1f} ms, end to end "
              f"{row['end_to_end']['folder, masks, pipeline']['fps']:.1f} frames/s", flush=True)
    return result


def markdown(report: dict[str, Any]) -> str:
    def pct(x: float | None) -> str:
        return "–" if x is None else f"{100 * x:.2f}"

    lines = [f"Machine: {report['machine']}; ONNX Runtime {report['versions']['onnxruntime']}, PyTorch "
             f"{report['versions']['torch']}, {report['threads']} intra-op threads. Frames: {report['frames']} "
             f"({report['frame_count']} real 1242×375). {report['note']}", "",
             "| model | weights | internal size | network ms | end to end frames/s (masks, pipeline) | sequential | "
             "with overlays | video → video | network share | CPU ms per frame | F real | MaxF real | F rendered | "
             "MaxF rendered |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for key in ("fast", "best"):
        for dtype in ("float32", "int8"):
            r = report["models"][key][dtype]
            e = r["end_to_end"]
            fr, fs = r["f_real"] or {}, r["f_rendered"] or {}
            lines.append(f"| {key}: {r['model']} | {dtype} | {'×'.join(map(str, r['internal_size']))} | "
                         f"{r['network_ms']:.1f} | **{e['folder, masks, pipeline']['fps']:.1f}** | "
                         f"{e['folder, masks, sequential']['fps']:.1f} | "
                         f"{e['folder, masks + overlays, pipeline']['fps']:.1f} | "
                         f"{e['video → video, pipeline']['fps']:.1f} | "
                         f"{100 * e['folder, masks, pipeline']['network_share']:.0f} % | "
                         f"{e['folder, masks, pipeline']['cpu_ms_per_frame']:.1f} | {pct(fr.get('f'))} | "
                         f"{pct(fr.get('max_f'))} | {pct(fs.get('f'))} | {pct(fs.get('max_f'))} |")
    lines += ["", "int8 against float32 (masks at 0.5 on the calibration frames, float32's as the reference):", ""]
    for key in ("fast", "best"):
        q = report["models"][key]["int8"]["against_float32_on_calibration_frames"]
        lines.append(f"- {key}: masks agree on {pct(q['mask_agreement'])} % of the pixels, F {pct(q['f_vs_float'])}, "
                     f"largest probability difference {q['max_prob_diff']:.3f} ({q['frames']} frames)")
    lines += ["", "Profile of one frame (each step alone, medians; wall ms / CPU ms):", "",
              "| model | weights | decode | preprocess | network | postprocess | write | sum (wall) |",
              "|---|---|---|---|---|---|---|---|"]
    for key in ("fast", "best"):
        for dtype in ("float32", "int8"):
            p = report["models"][key][dtype]["profile"]
            cells = " | ".join(f"{p[s]['wall_ms']:.1f} / {p[s]['cpu_ms']:.1f}" for s in
                               ("decode", "preprocess", "network", "postprocess", "write"))
            lines.append(f"| {key} | {dtype} | {cells} | {sum(v['wall_ms'] for v in p.values()):.1f} |")
    return "\n".join(lines)


def _repeat(text: str) -> int:
    """``--repeat``: a count of timings in 1…10000 (argparse's one-line refusal otherwise)."""
    from freespace.errors import InvalidOptionError
    from freespace.limits import bounded_int

    try:
        return int(bounded_int(1, 10_000)(text))
    except InvalidOptionError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def check_inputs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[Path]:
    """The frames of ``--frames``, once every input is known to be there and the frames share one size (the video
    made of them and the per-frame figures need it); else ``parser.error``'s one line (exit 2), before any work."""
    from freespace.io.codecs import image_header_size

    for flag, path, kind in (("--fast", args.fast, "file"), ("--best", args.best, "file"),
                             ("--split-file", args.split_file, "file"), ("--frames", args.frames, "dir"),
                             ("--rendered", args.rendered, "dir")):
        if path is not None and not (path.is_file() if kind == "file" else path.is_dir()):
            parser.error(f"{flag} {path}: no such {'file' if kind == 'file' else 'folder'}")
    frames = sorted(args.frames.glob("*.png"))
    if not frames:
        parser.error(f"--frames {args.frames}: no PNG frames")
    first = None
    for path in frames:
        with path.open("rb") as f:
            size = image_header_size(f.read(1 << 16))
        if size is None:
            parser.error(f"--frames: {path} is no readable PNG")
        first = first or (path, size)
        if size != first[1]:
            parser.error(f"--frames: {path} is {size[0]}×{size[1]} but {first[0]} is {first[1][0]}×{first[1][1]}; "
                         f"give frames of one size (one camera)")
    return frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fast", type=Path, help="the fast model's checkpoint (default: train a placeholder)")
    parser.add_argument("--best", type=Path, help="the best model's checkpoint (default: train a placeholder)")
    parser.add_argument("--frames", type=Path, default=KITTI_RAW, help="real 1242×375 frames (a folder)")
    parser.add_argument("--real", type=Path, default=REAL, help="image_2/ + road_mask/ labelled real frames")
    parser.add_argument("--rendered", type=Path, help="a rendered KITTI road tree to score (default: the "
                                                      "placeholders' test split, when trained here)")
    parser.add_argument("--split-file", type=Path, help="frame names of --rendered to score (default: all)")
    parser.add_argument("--work", type=Path, help="where placeholders are trained (default: a temporary folder "
                                                  "that is kept)")
    parser.add_argument("--repeat", type=_repeat, default=30, help="network-alone timings per model (median), "
                                                                  "1…10000")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out")
    parser.add_argument("--section-file", type=Path)
    parser.add_argument("--write-benchmarks", action="store_true")
    args = parser.parse_args()
    frames = check_inputs(parser, args)

    from freespace.inference.predictor import machine_threads
    from freespace.io.codecs import read_image
    from freespace.io.video import VideoWriter

    desc = machine()  # the load average at the start
    load = os.getloadavg()
    note = "Models: the given checkpoints."
    rendered, split = args.rendered, args.split_file
    if args.fast is None or args.best is None:
        work = args.work or Path(tempfile.mkdtemp(prefix="realtime-"))
        trained = train_placeholders(work)
        args.fast, args.best = args.fast or trained["fast"], args.best or trained["best"]
        note = ("Models: placeholders trained here on 70 of 120 rendered frames (Fast-SCNN light from scratch, "
                "U-Net with an ImageNet Lite0 encoder; 192×640, 8 epochs, the same training), not the real models.")
        if rendered is None:
            rendered, split = work / "synth", work / "run-fast" / "splits" / "test.txt"
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        video = tmp_path / "drive.mp4"
        with VideoWriter(video, fps=10) as writer:
            for p in frames:
                writer.write(read_image(p))
        real, rend = real_pairs(args.real), rendered_pairs(rendered, split) if rendered else []
        models = {key: bench_model(key, ckpt, args.frames, video, tmp_path, args.repeat, real, rend)
                  for key, ckpt in (("fast", args.fast), ("best", args.best))}
    report = {"machine": desc, "load_average_at_start": load, "versions": versions(), "threads": machine_threads(),
              "frames": str(args.frames), "frame_count": len(frames), "real": str(args.real) if real else None,
              "rendered": str(rendered) if rend else None, "note": note, "models": models,
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "realtime.json").write_text(json.dumps(report, indent=2) + "\n")
    body = markdown(report)
    (args.out / "realtime.md").write_text(section_text(SECTION, body))
    print(body)
    if args.section_file:
        args.section_file.write_text(section_text(SECTION, body))
    if args.write_benchmarks:
        write_section(SECTION, body)


if __name__ == "__main__":
    main()
