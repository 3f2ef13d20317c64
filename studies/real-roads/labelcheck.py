"""How good are a teacher's labels? Issue 61's label checks, against human road masks that are only measured:

- ``kitti2015``: the drive teacher's fill (``student.py --drive-teacher``) of single-frame autolabels, on the
  two KITTI stereo 2015 frames: the autolabel alone, filled where it leaves don't care, and with the teacher's
  confident labels first (``--drive-teacher-first``). ``--autolabels`` holds ``<frame>.png`` KITTI-colour
  labels of ``000000_10`` and ``000001_10`` (``freespace autolabel`` on those pairs).
- ``look``: the road-look veto (``freespace autolabel --look-from``, :mod:`freespace.datagen.road_look`) of
  single-frame autolabels of the two KITTI stereo 2015 frames from SGBM, LiDAR (``disp_occ_0``) and both fused;
  the classifier learns from the two frames' own autolabels (a drive gives it a hundred).
- ``camvid``: the CamVid labellers of ``student.py`` on CamVid ``val`` (101 frames, ``valannot``) and the dusk
  frames (62 of ``train``, ``duskannot``): the ``--teacher`` models (light normalised, as ``freespace adapt``'s
  teachers), the ``--raw-teacher`` models (frames as they are, e.g. a teacher trained on the drives), and the
  mean over all of them.

A label is road where the models' mean probability is above 0.9 and not road below 0.1 (``student.py``'s
threshold), don't care between. Reported, pooled over each set's pixels (CamVid's void, class 11, left out):
the labelled share, the human road labelled road and labelled not road, and the precision of the road label.

    python studies/real-roads/labelcheck.py kitti2015 --teacher MODEL --autolabels DIR [--kitti2015 DIR]
    python studies/real-roads/labelcheck.py look [--kitti2015 DIR]
    python studies/real-roads/labelcheck.py camvid --camvid DIR --teacher MODEL ... [--raw-teacher MODEL ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from freespace.datagen.completion import balanced_label, complete_by_appearance, confident_label
from freespace.datagen.temporal import CarryOptions, carry_along
from freespace.evaluation.real_frames import FULL_MASK_FRAMES as KITTI2015_FRAMES
from freespace.evaluation.real_frames import SHARED

sys.path.insert(0, str(Path(__file__).resolve().parent))
import student  # noqa: E402  (the study's own script: the teachers' labels)

CAMVID_ROAD, CAMVID_VOID = 3, 11
#: the road's colour in the KITTI semantics frames of other streets (Cityscapes palette)
KITTI_DEV_ROAD = (128, 64, 128)


def count(label: np.ndarray, human_road: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Pixel counts of a KITTI-colour ``label`` (``H×W×3`` BGR) against ``human_road`` (``H×W bool``) over
    ``valid`` (``H×W bool``): valid, labelled, road labelled road, road labelled not road, labelled road, road."""
    road = (label == student.ROAD_BGR).all(2) & valid
    non = (label == student.NON_ROAD_BGR).all(2) & valid
    human = human_road & valid
    return np.array([valid.sum(), (road | non).sum(), (road & human).sum(), (non & human).sum(), road.sum(),
                     human.sum()], np.float64)


def summary(counts: np.ndarray) -> dict[str, float]:
    """Shares in % from :func:`count`'s sums: ``labelled``, ``road_as_road``, ``road_as_not``, ``precision``."""
    valid, labelled, hit, lost, road, human = counts
    return {"labelled": _percent(labelled, valid), "road_as_road": _percent(hit, human),
            "road_as_not": _percent(lost, human), "precision": _percent(hit, road)}


def _percent(part: float, whole: float) -> float:
    return round(100 * float(part) / max(float(whole), 1.0), 1)


def _rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"cannot read {path}: give the folders the module's docstring describes")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def check_kitti2015(teachers: list[Path], autolabels: Path, kitti2015: Path) -> dict[str, dict[str, float]]:
    """The fill of ``autolabels`` by ``teachers`` (frames as they are) on the two KITTI 2015 frames under
    ``kitti2015`` (``image_2/``, ``road_mask/``)."""
    sessions = student._sessions(teachers)
    sums: dict[str, np.ndarray] = {}
    for frame in KITTI2015_FRAMES:
        image = _rgb(kitti2015 / "image_2" / f"{frame}.png")
        human = cv2.imread(str(kitti2015 / "road_mask" / f"{frame}.png"), cv2.IMREAD_GRAYSCALE) > 0
        under = cv2.imread(str(autolabels / f"{frame}.png"), cv2.IMREAD_COLOR)
        if under is None or under.shape[:2] != human.shape:
            raise SystemExit(f"{autolabels / f'{frame}.png'}: missing or not at the frame's size")
        prob = student.teacher_probability(image, sessions, normalise=False)
        labels = {"autolabel": under, "filled": student.label_from(prob, under=under),
                  "teacher first": student.label_from(prob, under=under, teacher_first=True)}
        for name, label in labels.items():
            sums[name] = sums.get(name, 0) + count(label, human, np.ones_like(human))
    return {name: summary(s) for name, s in sums.items()}


def check_look(kitti2015: Path) -> dict[str, dict[str, float]]:
    """Single-frame autolabels of the two KITTI 2015 frames under ``kitti2015`` (``image_2/``, ``image_3/``,
    ``disp_occ_0/``, ``road_mask/``) from each disparity source, before and after the road-look veto."""
    from freespace.data.disparity import fuse_disparities
    from freespace.datagen.autolabel import autolabel
    from freespace.datagen.road_look import look_encoder, look_veto_frames
    from freespace.geometry import compute_disparity
    from freespace.io.codecs import read_disparity

    encoder, result = look_encoder(), {}
    images = [_rgb(kitti2015 / "image_2" / f"{frame}.png") for frame in KITTI2015_FRAMES]
    humans = [cv2.imread(str(kitti2015 / "road_mask" / f"{f}.png"), cv2.IMREAD_GRAYSCALE) > 0 for f in KITTI2015_FRAMES]
    for source in ("sgbm", "lidar", "fused"):
        labels = []
        for frame, image in zip(KITTI2015_FRAMES, images):
            sgbm = compute_disparity(image, _rgb(kitti2015 / "image_3" / f"{frame}.png"))
            lidar = read_disparity(kitti2015 / "disp_occ_0" / f"{frame}.png")
            disparity = {"sgbm": sgbm, "lidar": lidar, "fused": fuse_disparities(lidar, sgbm)}[source]
            labels.append(autolabel(disparity, baseline=0.54).label)
        checked, _ = look_veto_frames(images, labels, encoder=encoder)
        sums = {"autolabel": 0, "look-checked": 0}
        for before, after, human in zip(labels, checked, humans):
            for name, x in (("autolabel", before), ("look-checked", after)):
                sums[name] = sums[name] + count(_kitti_colours(np.where(x.valid, x.road, 255).astype(np.uint8)),
                                                human, np.ones_like(human))
        result.update({f"{source} {name}": summary(s) for name, s in sums.items()})
    return result


#: the label sources of a teacher's probability (issue 70, item 1): one global confidence (student.py's), class-
#: balanced thresholds per band of rows, the confident label completed by appearance (a graph cut), the confident
#: label carried along time from the next frames (a sequence's road-plane homographies,
#: :mod:`freespace.datagen.temporal`), and that carried label completed by appearance
SOURCES = ("confident", "balanced", "appearance", "temporal", "temporal+appearance")


def _kitti_colours(classes: np.ndarray) -> np.ndarray:
    """A class map (1 road, 0 not road, 255 don't care) as a KITTI-colour label (``H×W×3`` BGR)."""
    label = np.zeros((*classes.shape, 3), np.uint8)
    label[classes == 1] = student.ROAD_BGR
    label[classes == 0] = student.NON_ROAD_BGR
    return label


def labels_of(source: str, images: list[np.ndarray], probs: list[np.ndarray],
              release: tuple[float, float] = (0.0, 1.0)) -> list[np.ndarray]:
    """The KITTI-colour labels (BGR) that ``source`` (:data:`SOURCES`) makes of the road probabilities ``probs`` of
    ``images`` (RGB frames of one camera, consecutive and in time order for the temporal sources); ``release``: the
    distance and far share of the confident not road the graph cut may relabel (the appearance sources;
    :func:`freespace.datagen.completion.released_seeds`)."""
    if source == "confident":
        return [student.label_from(prob) for prob in probs]
    if source == "balanced":
        return [_kitti_colours(balanced_label(prob)) for prob in probs]
    seeds = [confident_label(prob, student.THRESHOLD) for prob in probs]
    if source.startswith("temporal"):
        seeds = carry_along(images, seeds, [prob >= 0.5 for prob in probs], CarryOptions())[0]
    if source.endswith("appearance"):
        seeds = [complete_by_appearance(image, prob, student.THRESHOLD, seeds=seed, release=release[0], far=release[1])
                 for image, prob, seed in zip(images, probs, seeds)]
    return [_kitti_colours(seed) for seed in seeds]


def check_camvid(teachers: list[Path], raw_teachers: list[Path], camvid: Path,
                 sources: tuple[str, ...] = ("confident",),
                 release: tuple[float, float] = (0.0, 1.0),
                 look: tuple[float, float] | None = None,
                 opening: tuple[float, float] | None = None) -> dict[str, dict[str, float]]:
    """The CamVid labels of ``teachers`` (light normalised), ``raw_teachers`` (as they are) and the mean of all
    models, on ``val`` and the dusk frames under ``camvid`` (``make.sh``'s layout; each set one sequence in time
    order: ``val`` 15 frames a second, dusk one), each made by every label ``sources`` (:data:`SOURCES`; other than
    ``confident``, named ``name / source``; ``release``: :func:`labels_of`'s; ``look``: each also after the
    road-look veto with the lane ahead in that band of columns, named ``... + look``; ``opening``: each of those
    also with the teachers' confident not road near their road left don't care, ``student.py --open``, named
    ``... + open``)."""
    normalised, raw = student._sessions(teachers), student._sessions(raw_teachers)
    sums: dict[str, np.ndarray] = {}
    for part, folder, masks in (("val", "val", "valannot"), ("dusk", "train", "duskannot")):
        paths = sorted((camvid / masks).glob("*.png"))
        classes = [cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) for path in paths]
        images = [_rgb(camvid / folder / path.name) for path in paths]
        named: dict[str, list[np.ndarray]] = {}
        if teachers:
            named["teachers"] = [student.teacher_probability(im, normalised, normalise=True) for im in images]
        if raw_teachers:
            named["raw teachers"] = [student.teacher_probability(im, raw, normalise=False) for im in images]
        if teachers and raw_teachers:  # the mean over every model
            named["all"] = [(len(normalised) * a + len(raw) * b) / (len(normalised) + len(raw))
                            for a, b in zip(named["teachers"], named["raw teachers"])]
        for name, probs in named.items():
            for source in sources:
                key = f"{part}, {name}" + ("" if source == "confident" else f" / {source}")
                made = {key: labels_of(source, images, probs, release)}
                if look is not None:
                    made[f"{key} + look"] = looked(images, made[key], look)
                if opening is not None:
                    made.update({f"{k} + open": [_kitti_colours(student.opened(_classes(x), p, student.THRESHOLD,
                                                                                opening)) for x, p in zip(v, probs)]
                                 for k, v in list(made.items())})
                for k, labels in made.items():
                    for label, human in zip(labels, classes):
                        sums[k] = sums.get(k, 0) + count(label, human == CAMVID_ROAD, human != CAMVID_VOID)
    return {name: summary(s) for name, s in sums.items()}


def looked(images: list[np.ndarray], labels: list[np.ndarray], band: tuple[float, float]) -> list[np.ndarray]:
    """KITTI-colour ``labels`` (BGR) of one sequence's ``images`` after the road-look veto (``student.py --look``,
    the lane ahead in ``band``): its road of another look made don't care."""
    return [_kitti_colours(c) for c in student.looked(images, [_classes(x) for x in labels], band)]


def _classes(label: np.ndarray) -> np.ndarray:
    """A KITTI-colour label (``H×W×3`` BGR) as a class map (1 road, 0 not road, 255 don't care)."""
    return np.where((label == student.ROAD_BGR).all(2), 1, np.where((label == student.NON_ROAD_BGR).all(2), 0, 255)
                    ).astype(np.uint8)


def check_kitti_dev(teachers: list[Path], kitti_dev: Path, sources: tuple[str, ...] = ("confident",),
                    release: tuple[float, float] = (0.0, 1.0)) -> dict[str, dict[str, float]]:
    """The labels ``teachers`` (frames as they are) make on the 22 KITTI frames of other streets under
    ``kitti_dev`` (``images/``, ``masks/``: Cityscapes colours, road within 8 levels of (128, 64, 128)), by every
    label ``sources`` (``release``: :func:`labels_of`'s), pooled over all 22 and over the 9 with the most road (the
    wide streets)."""
    sessions = student._sessions(teachers)
    frames = []
    for path in sorted((kitti_dev / "masks").glob("*.png")):
        mask = _rgb(path).astype(np.int16)
        human = (np.abs(mask - np.array(KITTI_DEV_ROAD)).max(2) <= 8)
        frames.append((path.name, human))
    wide = {name for name, _ in sorted(frames, key=lambda f: -int(f[1].sum()))[:9]}
    sums: dict[str, np.ndarray] = {}
    for name, human in frames:
        image = _rgb(kitti_dev / "images" / name)
        prob = student.teacher_probability(image, sessions, normalise=False)
        for source in sources:
            counts = count(labels_of(source, [image], [prob], release)[0], human, np.ones_like(human))
            for group in ("all 22",) + (("9 wide",) if name in wide else ()):
                key = f"{group} / {source}"
                sums[key] = sums.get(key, 0) + counts
    return {name: summary(s) for name, s in sums.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="check", required=True)
    k = sub.add_parser("kitti2015", help="the drive teacher's fill of the KITTI 2015 frames' autolabels")
    k.add_argument("--teacher", type=Path, action="append", required=True, help="a model folder (model.onnx)")
    k.add_argument("--autolabels", type=Path, required=True)
    k.add_argument("--kitti2015", type=Path, default=SHARED / "kitti_stereo_2015")
    g = sub.add_parser("look", help="the road-look veto of the KITTI 2015 frames' autolabels")
    g.add_argument("--kitti2015", type=Path, default=SHARED / "kitti_stereo_2015")
    c = sub.add_parser("camvid", help="the CamVid labellers on val and the dusk frames")
    c.add_argument("--camvid", type=Path, required=True, help="make.sh's camvid folder")
    c.add_argument("--teacher", type=Path, action="append", default=[], help="a model folder, light normalised")
    c.add_argument("--raw-teacher", type=Path, action="append", default=[], help="a model folder, frames as they are")
    c.add_argument("--sources", default="confident", help=f"label sources, comma-separated: {', '.join(SOURCES)}")
    c.add_argument("--look", type=student.parse_band, metavar="LO,HI",
                   help="also each source after the road-look veto, the lane ahead in columns LO–HI (fractions of "
                        "the width; CamVid drives on the left: 0.45,0.70)")
    c.add_argument("--open", type=float, default=0.0, metavar="R",
                   help="also each label with the confident not road within R × the image height of the teachers' "
                        "road left don't care (student.py --open)")
    c.add_argument("--open-far", type=float, default=1.0, metavar="F", help="... only in the top F share of its rows")
    d = sub.add_parser("kittidev", help="a teacher's labels on the 22 KITTI frames of other streets")
    d.add_argument("--kitti-dev", type=Path, required=True, help="make.sh's kitti_dev folder")
    d.add_argument("--teacher", type=Path, action="append", required=True, help="a model folder, frames as they are")
    d.add_argument("--sources", default="confident", help=f"label sources, comma-separated: {', '.join(SOURCES)}")
    for parser in (c, d):
        parser.add_argument("--release", type=float, default=0.0, metavar="R",
                            help="the appearance sources may relabel the confident not road within R × the image "
                                 "height of the road (student.py --release)")
        parser.add_argument("--release-far", type=float, default=1.0, metavar="F",
                            help="... only in the top F share of the road's rows")
    a = ap.parse_args()
    if not 0 <= getattr(a, "open", 0.0) <= 1 or not 0 < getattr(a, "open_far", 1.0) <= 1:
        ap.error("--open takes a share of the image height in [0, 1], --open-far a share of rows in (0, 1]")
    if a.check == "kitti2015":
        result = check_kitti2015(a.teacher, a.autolabels, a.kitti2015)
    elif a.check == "look":
        result = check_look(a.kitti2015)
    elif a.check == "kittidev":
        sources = tuple(a.sources.split(","))
        if not set(sources) <= set(SOURCES[:3]):  # single frames: nothing to carry along time
            ap.error(f"kittidev's frames are not a sequence: --sources takes {', '.join(SOURCES[:3])}")
        result = check_kitti_dev(a.teacher, a.kitti_dev, sources, (a.release, a.release_far))
    else:
        if not a.teacher and not a.raw_teacher:
            ap.error("give --teacher MODEL or --raw-teacher MODEL")
        sources = tuple(a.sources.split(","))
        if not set(sources) <= set(SOURCES):
            ap.error(f"--sources takes {', '.join(SOURCES)}")
        result = check_camvid(a.teacher, a.raw_teacher, a.camvid, sources, (a.release, a.release_far), a.look,
                              (a.open, a.open_far) if a.open else None)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
