"""Where a road model's errors lie on the labelled development frames (issue 70's two diagnoses, measured).

The false road by the human class it falls on (pavement, parking, terrain, ...), and the missed road by place:
**beside a vehicle** (within ``--near`` × the frame's height of a car, truck, bus or cyclist of the human labels),
**far** (in the top third of the rows the frame's human road spans), or **elsewhere**; each place's share of the
missed road and the recall of the road there. The sets and their road are read as ``bench/real_bench.py`` reads
them (KITTI's other streets, Cityscapes colours; CamVid ``val`` and dusk, class ids); a pixel's class is the nearest
listed colour (the KITTI frames were scaled, blending colours at class edges) or its id. Labels are for measuring
only.

    .venv/bin/python studies/real-roads/errors.py --real-dev DEV --model NAME=PATH [--model ...] \\
        [--threshold 0.5] [--near 0.03] [--threads N] --out errors.json
    .venv/bin/python studies/real-roads/errors.py --real-dev DEV --model NAME=PATH ... --sweep --out sweep.json

``--sweep`` gives instead each model's pooled precision, recall and F at thresholds 0.05–0.95 (:func:`sweep`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from freespace.evaluation.labelled import pair_labelled_frames, parse_label_format, read_label_image
from freespace.evaluation.metrics import Counts
from freespace.limits import MAX_CROP_TOP

#: the labelled development sets as ``bench/real_bench.py`` reads them: name, images, labels (under real_dev/make.sh's
#: DEST), the label format
SETS = (("kitti_dev", "kitti_dev/images", "kitti_dev/masks", parse_label_format("palette", "128,64,128")),
        ("camvid_val", "camvid/val", "camvid/valannot", parse_label_format("class-id", "3", "11")),
        ("camvid_dusk", "camvid/train", "camvid/duskannot", parse_label_format("class-id", "3", "11")))

#: Cityscapes' colours (RGB) of the classes KITTI's semantics frames use
CITYSCAPES = {"road": (128, 64, 128), "sidewalk": (244, 35, 232), "parking": (250, 170, 160),
              "rail track": (230, 150, 140), "building": (70, 70, 70), "wall": (102, 102, 156),
              "fence": (190, 153, 153), "bridge": (150, 100, 100), "pole": (153, 153, 153),
              "traffic light": (250, 170, 30), "traffic sign": (220, 220, 0), "vegetation": (107, 142, 35),
              "terrain": (152, 251, 152), "sky": (70, 130, 180), "person": (220, 20, 60), "rider": (255, 0, 0),
              "car": (0, 0, 142), "truck": (0, 0, 70), "bus": (0, 60, 100), "train": (0, 80, 100),
              "motorcycle": (0, 0, 230), "bicycle": (119, 11, 32), "void": (0, 0, 0)}
#: CamVid's class ids (SegNet's 11 classes, 11 void)
CAMVID = ("sky", "building", "pole", "road", "pavement", "tree", "sign", "fence", "car", "pedestrian", "bicyclist",
          "void")
VEHICLES = {"car", "truck", "bus", "train", "motorcycle", "bicycle", "rider", "bicyclist"}
PLACES = ("beside a vehicle", "far", "elsewhere")


def class_names(raw: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """A label image's classes: ``(H×W int index, names)``. ``H×W×3`` RGB: the nearest Cityscapes colour;
    ``H×W``: CamVid's ids (an id past the list: void)."""
    if raw.ndim == 2:
        return np.minimum(raw.astype(np.int64), len(CAMVID) - 1), CAMVID
    rgb = raw.astype(np.int32)
    best, index = np.full(raw.shape[:2], np.iinfo(np.int32).max), np.zeros(raw.shape[:2], np.int64)
    for i, colour in enumerate(CITYSCAPES.values()):
        distance = np.abs(rgb - np.array(colour, np.int32)).sum(2)
        index[distance < best], best = i, np.minimum(best, distance)
    return index, tuple(CITYSCAPES)


def places(road: np.ndarray, classes: np.ndarray, names: tuple[str, ...], near: float) -> np.ndarray:
    """Each pixel's place (``H×W int``, an index of :data:`PLACES`): beside a vehicle (within ``near`` × the height
    of one, a square neighbourhood), else far (the top third of the rows ``road`` spans), else elsewhere."""
    h = road.shape[0]
    out = np.full(road.shape, 2, np.int64)
    rows = np.flatnonzero(road.any(1))
    if rows.size:
        out[: rows[0] + (rows[-1] - rows[0] + 1) // 3] = 1
    vehicle = np.isin(classes, [i for i, n in enumerate(names) if n in VEHICLES]).astype(np.uint8)
    r = max(1, round(near * h))
    out[cv2.dilate(vehicle, np.ones((2 * r + 1, 2 * r + 1), np.uint8)) > 0] = 0
    return out


def tally(pred: np.ndarray, road: np.ndarray, valid: np.ndarray, classes: np.ndarray, names: tuple[str, ...],
          near: float, into: dict[str, dict[str, int]]) -> None:
    """Add one frame's counts to ``into``: ``fp`` (false road pixels by class name), ``road`` and ``missed`` (road
    pixels and missed ones by place), ``tp``. ``pred``, ``road``, ``valid``: ``H×W bool``."""
    fp = pred & ~road & valid
    for i, n in enumerate(np.bincount(classes[fp], minlength=len(names))):
        if n:
            into["fp"][names[i]] = into["fp"].get(names[i], 0) + int(n)
    where = places(road & valid, classes, names, near)
    truth = road & valid
    for i, place in enumerate(PLACES):
        into["road"][place] = into["road"].get(place, 0) + int((truth & (where == i)).sum())
        into["missed"][place] = into["missed"].get(place, 0) + int((truth & ~pred & (where == i)).sum())
    into["tp"]["all"] = into["tp"].get("all", 0) + int((truth & pred).sum())


def summary(counts: dict[str, dict[str, int]]) -> dict[str, object]:
    """Precision, recall, F (pooled); each class's share of the false road (largest first); each place's share of
    the missed road and the recall there. Shares and figures in [0, 1]."""
    tp, fp = counts["tp"].get("all", 0), sum(counts["fp"].values())
    fn, total = sum(counts["missed"].values()), sum(counts["road"].values())
    scores = Counts(tp=tp, fp=fp, fn=fn).metrics()
    return {**{k: scores[k] for k in ("precision", "recall", "f_score")}, "false_road_pixels": fp,
            "missed_road_pixels": fn,
            "false_road_by_class": {k: v / max(fp, 1) for k, v in sorted(counts["fp"].items(), key=lambda x: -x[1])},
            "missed_road_by_place": {k: {"share": counts["missed"][k] / max(fn, 1),
                                         "road_share": counts["road"][k] / max(total, 1),
                                         "recall": 1 - counts["missed"][k] / max(counts["road"][k], 1)}
                                     for k in PLACES}}


def _predictor(path: Path, threads: int | None, tta: bool = False, crop_top: float = 0.0):
    """A model file's predictor: an ONNX file on ``threads`` threads, or a training checkpoint; with ``tta``, as
    ``predict --tta`` sees frames (light normalised, mirror averaged); ``crop_top``: as ``predict --crop-top``."""
    from freespace.inference.predictor import Predictor

    if path.suffix == ".onnx":
        return Predictor(onnx=path, threads=threads, tta=tta, crop_top=crop_top)
    return Predictor(checkpoint=path, tta=tta, crop_top=crop_top)


def run(models: dict[str, Path], real_dev: Path, threshold: float, near: float, threads: int | None
        ) -> dict[str, dict[str, object]]:
    """Every model on KITTI's other streets, CamVid ``val`` and dusk (those here) → ``{set: {model: summary}}``."""
    out: dict[str, dict[str, object]] = {}
    predictors = {name: _predictor(path, threads) for name, path in models.items()}
    for set_name, images, labels, label_format in SETS:
        if not (real_dev / labels).is_dir():
            continue
        frames = pair_labelled_frames(real_dev / images, real_dev / labels, label_format)
        out[set_name] = {}
        for name, predictor in predictors.items():
            counts: dict[str, dict[str, int]] = {"fp": {}, "road": {}, "missed": {}, "tp": {}}
            for frame in frames:
                image, label = frame.read(label_format)
                if not label.valid.any():
                    continue
                classes, names = class_names(read_label_image(frame.label))
                pred = predictor.predict([image])[0] >= threshold
                tally(pred, label.road, label.valid, classes, names, near, counts)
            out[set_name][name] = summary(counts)
            print(f"{set_name} {name}: F {100 * out[set_name][name]['f_score']:.2f}", flush=True)
    return out


#: the thresholds of ``--sweep``
SWEEP = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95)


def _curve(counts: np.ndarray) -> dict[str, list[float]]:
    """Pooled precision, recall and F (fractions, :meth:`Counts.metrics`) from ``T×3`` summed ``tp, fp, fn`` counts,
    one row a threshold of :data:`SWEEP`."""
    scores = [Counts(*(int(v) for v in row)).metrics() for row in counts]
    return {"th": list(SWEEP), **{k: [m[name] for m in scores] for k, name in
                                  (("P", "precision"), ("R", "recall"), ("F", "f_score"))}}


def sweep(models: dict[str, Path], real_dev: Path, threads: int | None, tta: bool = False, crop_top: float = 0.0
          ) -> dict[str, dict[str, object]]:
    """Each model's pooled precision, recall and F at every threshold of :data:`SWEEP` → ``{set: {model: curve}}``:
    the sets of :data:`SETS` here, ``kitti_wide9`` (the 9 KITTI frames of other streets with the most human road)
    and ``camvid_pool`` (``val`` and dusk together) — the cheapest control of a change that moves precision and
    recall together (does it beat the model's own threshold?)."""
    out: dict[str, dict[str, object]] = {}
    th = np.array(SWEEP)[:, None]
    for name, path in models.items():
        predictor = _predictor(path, threads, tta, crop_top)
        per_set = {}
        for set_name, images, labels, label_format in SETS:
            if not (real_dev / labels).is_dir():
                continue
            rows = []  # per frame: T×3 counts and its human road
            for frame in pair_labelled_frames(real_dev / images, real_dev / labels, label_format):
                image, label = frame.read(label_format)
                prob = predictor.predict([image])[0][label.valid]
                road = label.road[label.valid]
                hit = prob[None, :] >= th
                rows.append((np.stack([(hit & road).sum(1), (hit & ~road).sum(1), (~hit & road).sum(1)], 1),
                             int(road.sum())))
            per_set[set_name] = rows
            out.setdefault(set_name, {})[name] = _curve(sum(c for c, _ in rows))
        if "kitti_dev" in per_set:
            wide = sorted(per_set["kitti_dev"], key=lambda r: r[1], reverse=True)[:9]
            out.setdefault("kitti_wide9", {})[name] = _curve(sum(c for c, _ in wide))
        if {"camvid_val", "camvid_dusk"} <= set(per_set):
            pool = per_set["camvid_val"] + per_set["camvid_dusk"]
            out.setdefault("camvid_pool", {})[name] = _curve(sum(c for c, _ in pool))
        print(f"{name}: swept", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real-dev", type=Path, required=True, help="the development sets (real_dev/make.sh's DEST)")
    ap.add_argument("--model", action="append", required=True, metavar="NAME=PATH",
                    help="an ONNX model or a training checkpoint; repeatable")
    ap.add_argument("--threshold", type=float, default=0.5)
    ap.add_argument("--near", type=float, default=0.03, help="beside a vehicle: within this × the frame's height")
    ap.add_argument("--threads", type=int)
    ap.add_argument("--sweep", action="store_true",
                    help="instead: pooled precision, recall and F at thresholds 0.05–0.95 (no classes, no places)")
    ap.add_argument("--tta", action="store_true", help="with --sweep: the models as predict --tta runs them")
    ap.add_argument("--crop-top", type=float, default=0.0, metavar="F",
                    help="with --sweep: the models as predict --crop-top F runs them")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    if not a.real_dev.is_dir():
        ap.error(f"--real-dev {a.real_dev} is not a folder; lay the sets out with shared/data/real_dev/make.sh")
    if any("=" not in m for m in a.model):
        ap.error("--model takes NAME=PATH")
    models = {k: Path(v) for k, v in (m.split("=", 1) for m in a.model)}
    for name, path in models.items():
        if not path.is_file():
            ap.error(f"--model {name}={path}: no such file")
    if (a.tta or a.crop_top) and not a.sweep:
        ap.error("--tta and --crop-top go with --sweep")
    if not 0 <= a.crop_top < MAX_CROP_TOP:
        ap.error(f"--crop-top {a.crop_top} is not a fraction of the height in [0, {MAX_CROP_TOP})")
    if a.sweep:
        res = {"models": {k: str(v) for k, v in models.items()}, "tta": a.tta, "crop_top": a.crop_top,
               "sets": sweep(models, a.real_dev, a.threads, a.tta, a.crop_top)}
    else:
        res = {"threshold": a.threshold, "near": a.near, "models": {k: str(v) for k, v in models.items()},
               "sets": run(models, a.real_dev, a.threshold, a.near, a.threads)}
    tmp = a.out.with_name(a.out.name + ".part")
    tmp.write_text(json.dumps(res, indent=1) + "\n")
    tmp.replace(a.out)


if __name__ == "__main__":
    main()
