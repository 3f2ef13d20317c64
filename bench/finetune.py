"""The few-shot benchmark of issue 69: fine-tune the published model on N labelled CamVid frames, and the same
network from ImageNet weights alone beside it, then score frames it never saw.

    .venv/bin/python bench/finetune.py --camvid DIR [--frames 5,20,50] [--start published,imagenet]
        [--out bench/out/finetune] [--train-args "..."] [--write-benchmarks]

``--camvid``: the CamVid development set laid out by ``shared/data/real_dev/make.sh`` (``val``, ``valannot``,
``train``, ``duskannot``). The training frames are **the first N of ``camvid/val`` by name** (N in 5, 20, 50): the
only human labels that may be trained on, for this benchmark only; no model trained on them is published.

Each run is ``freespace train --images FIRST_N --labels THEIR_LABELS --labels-like camvid`` with the defaults
(validation: the last fifth of the N frames by name) and

- ``published``: ``--init models/real-road-fast`` (its network at its size, weights; batch norms frozen);
- ``imagenet``: ``--model contextnet --encoder-name efficientnet-lite0 --encoder-weights imagenet --image-size
  HxW`` (the published model's size): the same network, its context branch from ImageNet, the rest random;

then ``freespace evaluate`` of its best checkpoint on

- ``other``: the other ``val`` frames (N + 1 … 101; drive 0016E5, the training frames' drive);
- ``unseen``: ``val`` frames 51 … 101 (the same 51 for every N: no run trained on them, no setting was chosen on
  them);
- ``dusk``: the 62 labelled frames of the dusk drive 0001TP (another drive, at dusk).

Figures: pooled F, precision and recall (p ≥ 0.5) with the 95 % frame-level bootstrap interval of F, and the
training's wall time (the command end to end: label checks, training, the test of its best checkpoint).
Each cell's figures go to ``OUT/START-N/cell.json`` (a cell found there is not run again); then
``OUT/results.json`` and ``OUT/results.md``, and BENCHMARKS.md's section *Few-shot fine-tuning* with
``--write-benchmarks``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_section

PUBLISHED = ROOT / "models" / "real-road-fast"


def start_options() -> dict[str, list[str]]:
    """``freespace train``'s options of each start: the published model, and its network (at its size) from
    ImageNet weights."""
    from freespace.inference.predictor import load_checkpoint

    h, w = load_checkpoint(PUBLISHED / "model.ckpt")[1]["image_size"]
    return {"published": ["--init", str(PUBLISHED)],
            "imagenet": ["--model", "contextnet", "--encoder-name", "efficientnet-lite0", "--encoder-weights",
                         "imagenet", "--image-size", f"{h}x{w}"]}


def _link_folder(folder: Path, images: list[Path], labels: Path) -> tuple[Path, Path]:
    """``folder/images`` and ``folder/labels`` holding links to ``images`` and their labels in ``labels``."""
    pair = folder / "images", folder / "labels"
    for p in pair:
        p.mkdir(parents=True, exist_ok=True)
    for img in images:
        for dst, src in ((pair[0], img), (pair[1], labels / img.name)):
            link = dst / img.name
            if not link.exists():
                link.symlink_to(src.resolve())
    return pair


def _run(args: list[str], log: Path) -> float:
    """Run ``freespace ARGS`` (this interpreter's), its output into ``log``; the wall time in seconds."""
    t0 = time.perf_counter()
    with log.open("w") as f:
        done = subprocess.run([sys.executable, "-m", "freespace.cli", *args], stdout=f, stderr=subprocess.STDOUT,
                              check=False)
    if done.returncode != 0:
        raise SystemExit(f"freespace {' '.join(args[:1])} failed (exit {done.returncode}); see {log}")
    return time.perf_counter() - t0


def _scores(metrics: dict) -> dict:
    ci = metrics.get("intervals") or {}
    return {"f": metrics["f_score"], "precision": metrics["precision"], "recall": metrics["recall"],
            "f_interval": ci.get("f_score"), "frames": metrics["frames"]}


def run_cell(camvid: Path, out: Path, n: int, start: str, train_args: list[str]) -> dict:
    """Train one cell (``n`` frames, ``start``) and score it on the three sets; a cell finished before (its
    ``cell.json``) is read, not run again."""
    done = out / f"{start}-{n}" / "cell.json"
    if done.is_file():
        return json.loads(done.read_text())
    val = sorted((camvid / "val").glob("*.png"))
    sets = {"other": val[n:], "unseen": val[50:]}
    train_imgs, train_labels = _link_folder(out / "data" / f"first-{n}", val[:n], camvid / "valannot")
    cell = out / f"{start}-{n}"
    cell.mkdir(parents=True, exist_ok=True)
    seconds = _run(["train", "--images", str(train_imgs), "--labels", str(train_labels), "--labels-like", "camvid",
                    "--out", str(cell / "run"), "--no-progress", *start_options()[start], *train_args],
                   cell / "train.log")
    result = {"frames": n, "start": start, "train_seconds": round(seconds, 1),
              "best_epoch": json.loads((cell / "run" / "metrics.json").read_text()).get("best_epoch")}
    ckpt = cell / "run" / "checkpoints" / "best.ckpt"
    for name, frames in sets.items():
        images, labels = _link_folder(out / "data" / f"{name}-{n}", frames, camvid / "valannot")
        _run(["evaluate", "--checkpoint", str(ckpt), "--images", str(images), "--labels", str(labels),
              "--labels-like", "camvid", "--out", str(cell / name), "--no-overlays", "--no-progress"],
             cell / f"{name}.log")
        result[name] = _scores(json.loads((cell / name / "metrics.json").read_text()))
    _run(["evaluate", "--checkpoint", str(ckpt), "--images", str(camvid / "train"), "--labels",
          str(camvid / "duskannot"), "--labels-like", "camvid", "--out", str(cell / "dusk"), "--no-overlays",
          "--no-progress"], cell / "dusk.log")
    result["dusk"] = _scores(json.loads((cell / "dusk" / "metrics.json").read_text()))
    done.write_text(json.dumps(result, indent=2))
    return result


def _cell_text(s: dict) -> str:
    ci = s["f_interval"]
    interval = f" [{ci[0] * 100:.1f}, {ci[1] * 100:.1f}]" if ci else ""
    return f"{s['f'] * 100:.1f}{interval} ({s['precision'] * 100:.1f} / {s['recall'] * 100:.1f})"


def table(results: list[dict]) -> str:
    """The markdown table of the cells: F [95 %] (precision / recall) per set, minutes of training."""
    rows = ["| start | frames | other `val` frames | `val` 51–101 (unseen) | dusk drive | training (min) "
            "| best epoch |", "|---|---:|---|---|---|---:|---:|"]
    for r in sorted(results, key=lambda r: (r["start"], r["frames"])):
        rows.append(f"| {r['start']} | {r['frames']} | {_cell_text(r['other'])} | {_cell_text(r['unseen'])} | "
                    f"{_cell_text(r['dusk'])} | {r['train_seconds'] / 60:.1f} | {r['best_epoch']} |")
    return "\n".join(rows)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--camvid", required=True, type=Path, help="real_dev's camvid folder")
    p.add_argument("--frames", default="5,20,50", help="training frame counts (the first N of val by name)")
    p.add_argument("--start", default="published,imagenet", help="published, imagenet or both")
    p.add_argument("--train-args", default="", help="more options for freespace train, quoted")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "finetune")
    p.add_argument("--write-benchmarks", action="store_true")
    a = p.parse_args()
    counts = [int(v) for v in a.frames.split(",")]
    if any(not 1 <= n <= 50 for n in counts):
        raise SystemExit("--frames: at most the first 50 val frames may be trained on (the dev README's rule)")
    starts = a.start.split(",")
    head = machine()
    results = []
    for start in starts:
        for n in counts:
            results.append(run_cell(a.camvid, a.out, n, start, shlex.split(a.train_args)))
            print(f"{start} {n}: other F {results[-1]['other']['f']:.4f}, dusk {results[-1]['dusk']['f']:.4f}, "
                  f"{results[-1]['train_seconds'] / 60:.1f} min", flush=True)
    (a.out / "results.json").write_text(json.dumps({"machine": head, "train_args": a.train_args,
                                                    "results": results}, indent=2))
    text = table(results)
    (a.out / "results.md").write_text(text + "\n")
    print(text)
    if a.write_benchmarks:
        write_section("Few-shot fine-tuning", f"`bench/finetune.py --camvid DIR` on {head}.\n\n{text}")


if __name__ == "__main__":
    main()
