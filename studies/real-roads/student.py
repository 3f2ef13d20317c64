"""The student's dataset of issue 61 (item 3): the real drives' autolabels plus a teacher's confident road on
unlabelled frames of another city and camera, as one generic ``freespace`` dataset with its subset lists.

- Real drives: links to the KITTI raw frames and their label tree (``freespace autolabel``), split by the
  study's ``splits-raw`` lists (training block; validation and test blocks as they are: autolabels, no human
  label).
- Unlabelled frames (e.g. CamVid's 367 ``train`` frames, none of them opened with a label): the teacher is one
  or more published-format model folders (``model.onnx``), each run on the frame and its mirror image as
  ``freespace adapt``'s teacher sees them (light normalised: :func:`freespace.data.photometry.normalise_light`),
  the probabilities averaged over models and mirrors, brought to the frame's size; road where p > THRESHOLD,
  not road where p < 1 - THRESHOLD, don't care between. They join the training list only.
- Optionally (``--drive-teacher``), models trained on the drives fill the don't care of the drives' training
  frames with their confident labels in the same way (the far road and the road beyond cars that the
  autolabels leave open); the autolabel stays wherever it labels. With ``--drive-teacher-first`` the teacher's
  confident labels win over the autolabel instead (its labels on the whole frame; the autolabel only where the
  teacher is unsure).

Labels are KITTI colours everywhere (road magenta, non-road red, don't care black). Frame names:
``<drive>-<frame>`` and ``<prefix>-<stem>``. ``report.json`` gives each teacher, the threshold and the labels'
confident and road shares.

    python studies/real-roads/student.py --raw RAW --autolabels AL --splits SPLITS \\
        --frames CAMVID/train --teacher MODEL [--teacher MODEL ...] [--drive-copies N] \\
        [--drive-teacher MODEL ... [--drive-teacher-first]] --out MIX
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np

from freespace.cli.shared import number_pair
from freespace.engine.adapt import road_probabilities

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mix import _link, link_drives  # noqa: E402  (the study's own script: the drives' links)

#: road where the teacher's mean probability is above this, not road below 1 - this (adapt's default)
THRESHOLD = 0.9
ROAD_BGR, NON_ROAD_BGR = (255, 0, 255), (0, 0, 255)


def _sessions(teachers: list[Path]) -> list[tuple[object, tuple[int, int]]]:
    """ONNX Runtime sessions of the teachers' ``model.onnx`` files with their input size (h, w)."""
    import onnxruntime as ort

    out = []
    for folder in teachers:
        session = ort.InferenceSession(str(folder / "model.onnx"), providers=["CPUExecutionProvider"])
        h, w = json.loads(session.get_modelmeta().custom_metadata_map["image_size"])  # freespace export's record
        out.append((session, (int(h), int(w))))
    return out


def teacher_probability(image: np.ndarray, sessions: list[tuple[object, tuple[int, int]]],
                        normalise: bool = True) -> np.ndarray:
    """The teachers' mean road probability (``H×W float32``) of an ``H×W×3 uint8`` RGB frame, each teacher on the
    frame and its mirror (light normalised with ``normalise``), brought to the frame's size."""
    h0, w0 = image.shape[:2]
    prob = np.zeros((h0, w0), np.float32)
    for session, (h, w) in sessions:
        small = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)[None]
        p = road_probabilities(session, small, normalise=normalise)[0].astype(np.float32)
        prob += cv2.resize(p, (w0, h0), interpolation=cv2.INTER_LINEAR)
    return prob / len(sessions)


def teacher_labels(image: np.ndarray, sessions: list[tuple[object, tuple[int, int]]],
                   threshold: float = THRESHOLD, under: np.ndarray | None = None, normalise: bool = True,
                   teacher_first: bool = False) -> np.ndarray:
    """A KITTI-colour label (``H×W×3 uint8`` BGR) of an ``H×W×3 uint8`` RGB frame from the teachers' mean road
    probability: road above ``threshold``, not road below ``1 - threshold``, don't care between. ``under``: a
    KITTI-colour label of the frame whose labelled pixels stay as they are (the teacher fills its don't care), or,
    with ``teacher_first``, stay only where the teacher is unsure. ``normalise``: the teachers see the frames light
    normalised, as ``freespace adapt``'s teachers were trained."""
    return label_from(teacher_probability(image, sessions, normalise), threshold, under, teacher_first)


def label_from(prob: np.ndarray, threshold: float = THRESHOLD, under: np.ndarray | None = None,
               teacher_first: bool = False) -> np.ndarray:
    """A KITTI-colour label (``H×W×3 uint8`` BGR) from a road probability (``H×W`` in [0, 1]): road above
    ``threshold``, not road below ``1 - threshold``, don't care between; ``under`` and ``teacher_first`` as
    :func:`teacher_labels`'s."""
    label = np.zeros((*prob.shape, 3), np.uint8) if under is None else under.copy()
    free = np.ones(prob.shape, bool) if teacher_first else ~label.any(2)
    label[free & (prob > threshold)] = ROAD_BGR
    label[free & (prob < 1 - threshold)] = NON_ROAD_BGR
    return label


def fill_drives(out: Path, names: list[str], sessions: list[tuple[object, tuple[int, int]]],
                threshold: float = THRESHOLD, teacher_first: bool = False) -> dict[str, float | bool]:
    """Replace the label links of the drives' training frames ``names`` (``out/label/<name>.png``, copies
    ``<name>-cN`` included) by files whose don't-care pixels (every pixel with ``teacher_first``) hold the
    teachers' confident labels; return the labelled share before and after, averaged over the frames, and the
    share of the pixels whose label the teacher changed (road to not road or back). The teachers see the frames
    as they are (models trained on the drives, not adapted); a frame's copies, links to the same autolabel, get
    a copy of its file."""
    written: dict[Path, Path] = {}  # autolabel → the filled file written for it
    before, after, changed = [], [], []
    for name in names:
        link = out / "label" / f"{name}.png"
        source = link.resolve()
        if source not in written:
            under = cv2.imread(str(link), cv2.IMREAD_COLOR)
            image = cv2.cvtColor(cv2.imread(str(out / "left" / f"{name}.png"), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
            label = teacher_labels(image, sessions, threshold, under=under, normalise=False,
                                   teacher_first=teacher_first)
            before.append(float(under.any(2).mean()))
            changed.append(float((under.any(2) & (label != under).any(2)).mean()))
            after.append(float(label.any(2).mean()))
            link.unlink()
            cv2.imwrite(str(link), label)
            written[source] = link
        else:
            link.unlink()
            shutil.copyfile(written[source], link)
    return {"frames": len(before), "labelled_before": float(np.mean(before)) if before else 0.0,
            "labelled_after": float(np.mean(after)) if after else 0.0,
            "changed": float(np.mean(changed)) if changed else 0.0, "teacher_first": teacher_first}


def frame_classes(paths: list[Path], sessions: list[tuple[object, tuple[int, int]]], threshold: float = THRESHOLD,
                  complete: bool = False, carry: bool = False,
                  release: tuple[float, float] = (0.0, 1.0), look: tuple[float, float] | None = None,
                  opening: tuple[float, float] | None = None) -> tuple[list[np.ndarray], dict[str, object] | None]:
    """The teachers' class maps (``uint8 H×W``: 1 road, 0 not road, 255 don't care) of the frames at ``paths``:
    the confident label, carried along time with ``carry`` (frames grouped into sequences by the name before its
    last ``_``, CamVid's ``0016E5_07959``, in name order; :func:`freespace.datagen.temporal.carry_along` with
    labelcheck's settings), then completed by appearance with ``complete`` (``release``: the distance and far
    share of :func:`freespace.datagen.completion.released_seeds`, the confident not road near the road the graph cut
    may relabel), then with ``look`` the road of another look made don't care (each sequence's road look learnt from
    its own labels, the lane ahead in that band of columns: :func:`freespace.datagen.road_look.look_veto_frames`),
    last with ``opening`` the teachers' confident not road near their road left open (:func:`opened`).
    Also the carrying's record per sequence (``None`` without ``carry``)."""
    from freespace.datagen.completion import complete_by_appearance, confident_label
    from freespace.datagen.temporal import CarryOptions, carry_along

    images = [cv2.cvtColor(cv2.imread(str(p), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB) for p in paths]
    probs = [teacher_probability(image, sessions) for image in images]
    classes = [confident_label(prob, threshold) for prob in probs]
    record: dict[str, object] | None = None
    groups: dict[str, list[int]] = {}
    for i, path in enumerate(paths):
        groups.setdefault(path.stem.rpartition("_")[0], []).append(i)
    if carry:
        record = {}
        for key, idx in groups.items():
            carried, record[key] = carry_along([images[i] for i in idx], [classes[i] for i in idx],
                                               [probs[i] >= 0.5 for i in idx], CarryOptions())
            for i, label in zip(idx, carried):
                classes[i] = label
    if complete:
        classes = [complete_by_appearance(im, prob, threshold, seeds=c, release=release[0], far=release[1])
                   for im, prob, c in zip(images, probs, classes)]
    if look is not None:
        for idx in groups.values():
            for i, c in zip(idx, looked([images[i] for i in idx], [classes[i] for i in idx], look)):
                classes[i] = c
    if opening is not None:
        classes = [opened(c, prob, threshold, opening) for c, prob in zip(classes, probs)]
    return classes, record


def opened(classes: np.ndarray, prob: np.ndarray, threshold: float, opening: tuple[float, float]) -> np.ndarray:
    """A class map (``uint8 H×W``: 1 road, 0 not road, 255 don't care) whose not road is made don't care where the
    teachers' mean road probability ``prob`` (``H×W``) was confidently not road within ``opening[0]`` × the image
    height of their road, in the top ``opening[1]`` share of its rows
    (:func:`freespace.datagen.completion.released_seeds`): the lanes beside the cars and the road's far end, which
    the teachers call not road confidently and wrongly a third of the time, left to the student instead of taught as
    not road (issue 70)."""
    from freespace.datagen.completion import confident_label, released_seeds

    near = released_seeds(confident_label(prob, threshold), prob, *opening)
    return np.where(near & (classes == 0), 255, classes).astype(np.uint8)


def looked(images: list[np.ndarray], classes: list[np.ndarray], band: tuple[float, float]) -> list[np.ndarray]:
    """Class maps (1 road, 0 not road, 255 don't care) of one sequence after the road-look veto, the lane ahead in
    ``band``."""
    from freespace.datagen.options import LookOptions
    from freespace.datagen.road_look import look_veto_frames
    from freespace.labels import RoadLabel

    labels = [RoadLabel(c == 1, c != 255) for c in classes]
    vetoed, _ = look_veto_frames(images, labels, LookOptions(band=band))
    return [np.where(x.valid, x.road, 255).astype(np.uint8) for x in vetoed]


#: ``"LO,HI"`` → ``(LO, HI)``: the columns of the lane ahead, fractions of the width (argparse type)
parse_band = number_pair("LO,HI", "two fractions of the width")


def labels_sha256(label: Path) -> str:
    """The content hash of a dataset's label folder (``out/label``): SHA-256 over each file's name and bytes in name
    order (links read through), so a rebuilt dataset can be checked against the published recipe's."""
    import hashlib

    digest = hashlib.sha256()
    for path in sorted(label.iterdir()):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


Band = tuple[float, float]


def build(raw: Path, autolabels: Path, splits: Path, frames: Path | list[Path], teachers: list[Path], out: Path,
          prefix: str | list[str] = "camvid", threshold: float = THRESHOLD, drive_copies: int = 1,
          drive_teachers: list[Path] | None = None, drive_teacher_first: bool = False,
          complete: bool = False, carry: bool = False, release: tuple[float, float] = (0.0, 1.0),
          look: Band | list[Band | None] | None = None, opening: Band | None = None) -> dict[str, object]:
    """Write the links, the teacher's labels, ``freespace.yaml``, ``splits/`` and ``report.json`` under ``out``
    (a new folder); return the report. ``drive_copies``: each training frame of the drives is listed this many
    times (``<name>-c1``, ...: each copy draws its own augmentation), to weigh the drives against the other
    frames. ``drive_teachers``: model folders whose confident labels fill the don't care of the drives' training
    frames (:func:`fill_drives`; ``drive_teacher_first``: their confident labels win over the autolabels); the
    validation and test frames keep their autolabels. ``complete``: the frames' confident labels are completed by
    appearance (:func:`freespace.datagen.completion.complete_by_appearance`: a graph cut on the frame's colours
    labels the pixels the teacher is unsure of; issue 70, item 1; ``release``: also the confident not road near
    the road, :func:`frame_classes`). ``carry``: the confident labels are first carried
    along time within each sequence (:func:`frame_classes`). ``look``: the teachers' road of another look made
    don't care last (:func:`frame_classes`; the drives' labels are look-checked by ``freespace autolabel
    --look-from`` before they come here). Several folders of unlabelled frames may be given (``frames`` a list),
    each with its own ``prefix`` and ``look`` band (a list, one per folder; one band alone applies to all): each
    folder is labelled on its own (its sequences carried and look-checked within it) and the report gives each
    folder's shares. ``opening``: the teachers' confident not road near their road left don't care (:func:`opened`;
    the distance and far share)."""
    folders = frames if isinstance(frames, list) else [frames]
    prefixes = prefix if isinstance(prefix, list) else [prefix]
    bands = look if isinstance(look, list) else [look] * len(folders)
    if not len(folders) == len(prefixes) == len(bands):
        raise SystemExit("give one --prefix (and one --look, or a single one for all) per --frames folder")
    if out.exists():
        raise SystemExit(f"{out} exists; give a new folder")
    lists: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    link_drives(raw, autolabels, splits, out, lists, drive_copies)
    filled = fill_drives(out, list(lists["train"]), _sessions(drive_teachers), threshold,
                         drive_teacher_first) if drive_teachers else None
    sessions, confident, road, sets, carried = _sessions(teachers), [], [], [], {}
    for folder, name_prefix, band in zip(folders, prefixes, bands):
        paths = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".png")
        classes, record = frame_classes(paths, sessions, threshold, complete, carry, release, band, opening)
        carried.update(record or {})
        shares = []
        for path, frame in zip(paths, classes):
            label = np.zeros((*frame.shape, 3), np.uint8)
            label[frame == 1], label[frame == 0] = ROAD_BGR, NON_ROAD_BGR
            name = f"{name_prefix}-{path.stem}"
            _link(path, out / "left" / f"{name}.png")
            cv2.imwrite(str(out / "label" / f"{name}.png"), label)
            shares.append((float(label.any(2).mean()), float((label[..., 0] == 255).mean())))
            lists["train"].append(name)
        confident += [c for c, _ in shares]
        road += [r for _, r in shares]
        sets.append({"frames": str(folder), "prefix": name_prefix, "count": len(shares),
                     "look_band": list(band) if band else None,
                     "confident_share": float(np.mean([c for c, _ in shares])) if shares else 0.0,
                     "road_share": float(np.mean([r for _, r in shares])) if shares else 0.0})
    (out / "freespace.yaml").write_text("left: left\nlabel: label\nlabel_encoding: kitti\n")
    (out / "splits").mkdir()
    for part, names in lists.items():
        (out / "splits" / f"{part}.txt").write_text("".join(f"{n}\n" for n in names))
    report = {"teachers": [str(t) for t in teachers], "threshold": threshold,
              "frames": str(frames) if not isinstance(frames, list) else [str(f) for f in frames],
              "counts": {k: len(v) for k, v in lists.items()}, "teacher_frames": len(road),
              "drive_copies": drive_copies, "drive_teachers": [str(t) for t in drive_teachers or []],
              "drives_filled": filled, "completed_by_appearance": complete,
              "released": list(release) if complete else None, "carried_along_time": carried if carry else None,
              "look_band": [list(b) if b else None for b in look] if isinstance(look, list)
              else (list(look) if look else None), "opened": list(opening) if opening else None, "sets": sets,
              "confident_share": float(np.mean(confident)), "road_share": float(np.mean(road)),
              "labels_sha256": labels_sha256(out / "label")}
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("raw", "autolabels", "splits", "out"):
        ap.add_argument(f"--{name}", type=Path, required=True)
    ap.add_argument("--frames", type=Path, action="append", required=True,
                    help="a folder of unlabelled frames (.png); repeat for several, each with its --prefix")
    ap.add_argument("--teacher", type=Path, action="append", required=True, help="a model folder (model.onnx)")
    ap.add_argument("--prefix", action="append", help="the frames' name prefix, one per --frames (camvid)")
    ap.add_argument("--threshold", type=float, default=THRESHOLD)
    ap.add_argument("--drive-copies", type=int, default=1, help="list each training frame of the drives N times")
    ap.add_argument("--drive-teacher", type=Path, action="append", default=[],
                    help="a model folder whose confident labels fill the drives' training frames' don't care")
    ap.add_argument("--drive-teacher-first", action="store_true",
                    help="the drive teachers' confident labels win over the autolabels (the whole frame)")
    ap.add_argument("--complete", action="store_true",
                    help="complete the teachers' confident labels of --frames by appearance (a graph cut)")
    ap.add_argument("--carry", action="store_true",
                    help="carry the teachers' confident labels of --frames along time within each sequence first")
    ap.add_argument("--release", type=float, default=0.0, metavar="R",
                    help="with --complete, the graph cut may relabel the confident not road within R × the image "
                         "height of the teacher's road (0: none)")
    ap.add_argument("--release-far", type=float, default=1.0, metavar="F",
                    help="... only in the top F share of the road's rows (1: all)")
    ap.add_argument("--look", type=parse_band, metavar="LO,HI", action="append",
                    help="the teachers' road of another look made don't care, each sequence's road look learnt from "
                         "its labels with the lane ahead in columns LO–HI (CamVid drives on the left: 0.45,0.70)")
    ap.add_argument("--open", type=float, default=0.0, metavar="R",
                    help="leave don't care the teachers' confident not road within R × the image height of their "
                         "road (0: none), last")
    ap.add_argument("--open-far", type=float, default=1.0, metavar="F",
                    help="... only in the top F share of the road's rows (1: all)")
    a = ap.parse_args()
    if a.release and not a.complete:
        ap.error("--release needs --complete")
    if a.drive_teacher_first and not a.drive_teacher:
        ap.error("--drive-teacher-first needs --drive-teacher MODEL")
    if not 0 <= a.open <= 1 or not 0 < a.open_far <= 1:
        ap.error("--open takes a share of the image height in [0, 1], --open-far a share of rows in (0, 1]")
    frames = a.frames[0] if len(a.frames) == 1 else a.frames
    prefix = a.prefix or ["camvid"] * len(a.frames)
    look = a.look[0] if a.look and len(a.look) == 1 else a.look
    print(json.dumps(build(a.raw, a.autolabels, a.splits, frames, a.teacher, a.out,
                           prefix[0] if len(prefix) == 1 else prefix, a.threshold,
                           a.drive_copies, a.drive_teacher, a.drive_teacher_first, a.complete, a.carry,
                           (a.release, a.release_far), look, (a.open, a.open_far) if a.open else None)))


if __name__ == "__main__":
    main()
