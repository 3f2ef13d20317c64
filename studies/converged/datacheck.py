"""Check that a machine made the converged run's data (the rendered sets and their SGBM autolabels) as the
finished cells had them, before any cell trains on them.

``python datacheck.py WORK REF``: compares the data in ``WORK`` with the references in the folder ``REF``:

- ``REF/data.sha256``: byte for byte, the files no CPU changes: labels, disparities, calibrations, rig tables
  (session 2's data);
- ``REF/data.fingerprints.json``: within a tolerance, the files a CPU's float rounding does change: the
  rendered images and the autolabels. OpenCV and NumPy pick their SIMD code by CPU (AVX-512 on the machine of
  sessions 2-5, AVX2 on session 6's), and a float32 result one ULP apart truncates to another grey level now
  and then: about 1.3 values per 416×320 image differ by one grey level between two dispatch targets, and
  SGBM on those images changes 0.004 % of the autolabels' pixels on average (0.38 % in the worst of 100
  frames). An image is kept as the sums of its quadrants per channel, an autolabel as its quadrants' road,
  non-road and don't-care counts; an image may move its sums by at most 64 grey levels in all, an autolabel
  at most 1 % of its pixels, and the file lists must be equal. A change to the renderer or to autolabel moves
  thousands.

A missing ``data.fingerprints.json`` is written from ``WORK`` (the first machine to make the data).
Exit status 1, with the files that differ, when the data are not the run's.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import cv2
import numpy as np

SETS = ("syn", "same-rigs", "shifted", "matched", "autolabels")
IMAGE_TOLERANCE = 64  # grey levels, summed over quadrants and channels
LABEL_TOLERANCE = 0.01  # share of the pixels that may change class
# KITTI colours of an autolabel: road magenta, non-road red, don't care black (BGR as OpenCV reads them)
LABEL_COLOURS = ((255, 0, 255), (0, 0, 255), (0, 0, 0))


def data_files(work: Path) -> list[str]:
    """The data files of the run (images, labels, disparities, calibrations, rig tables, autolabels; not the
    reports, which hold timings and paths, nor the autolabels' confidence maps, which training never reads),
    relative to ``work``, sorted."""
    files = []
    for name in SETS:
        for path in (work / name).rglob("*"):
            rel = path.relative_to(work)
            if (path.is_file() and path.suffix in (".png", ".txt", ".csv") and ".freespace" not in rel.parts
                    and "reports" not in rel.parts and "confidence" not in rel.parts
                    and not path.name.startswith("report")):
                files.append(rel.as_posix())
    return sorted(files)


def is_tolerant(rel: str) -> bool:
    """Whether a CPU's float rounding can change the file (a rendered image or an autolabel)."""
    parts = rel.split("/")
    return parts[0] == "autolabels" or any(p in ("image_2", "image_3") for p in parts)


def _quadrants(a: np.ndarray) -> list[np.ndarray]:
    h, w = a.shape[:2]
    return [a[:h // 2, :w // 2], a[:h // 2, w // 2:], a[h // 2:, :w // 2], a[h // 2:, w // 2:]]


def fingerprint(path: Path, rel: str) -> list[int]:
    """Quadrant sums per channel of an image, or quadrant counts per class of an autolabel."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SystemExit(f"{path} is not a readable image")
    if rel.startswith("autolabels/"):
        return [int(np.all(q == c, axis=2).sum()) for q in _quadrants(img) for c in LABEL_COLOURS]
    img = img.reshape(*img.shape[:2], -1).astype(np.int64)
    return [int(v) for q in _quadrants(img) for v in q.sum(axis=(0, 1))]


def differs(rel: str, now: list[int], ref: list[int], pixels: int) -> bool:
    """Whether a tolerant file moved more than its tolerance."""
    moved = int(np.abs(np.array(now) - np.array(ref)).sum())
    if rel.startswith("autolabels/"):
        return moved > 2 * LABEL_TOLERANCE * pixels  # a pixel that changes class moves two counts
    return moved > IMAGE_TOLERANCE


def main(work: Path, ref: Path) -> int:
    files = data_files(work)
    exact = [f for f in files if not is_tolerant(f)]
    tolerant = [f for f in files if is_tolerant(f)]
    wrong = []
    sums = {}
    for line in (ref / "data.sha256").read_text().splitlines():
        digest, rel = line.split(maxsplit=1)
        if not is_tolerant(rel) and "/confidence/" not in rel:
            sums[rel] = digest
    if sorted(sums) != exact:
        wrong.append(f"other files than the run's: {len(set(exact) ^ set(sums))} differ in name "
                     f"(e.g. {sorted(set(exact) ^ set(sums))[:3]})")
    for rel in exact:
        if rel in sums and hashlib.sha256((work / rel).read_bytes()).hexdigest() != sums[rel]:
            wrong.append(rel)
    prints = {rel: fingerprint(work / rel, rel) for rel in tolerant}
    ref_prints = ref / "data.fingerprints.json"
    if not ref_prints.exists():
        ref_prints.write_text(json.dumps(prints, separators=(",", ":")) + "\n")
        print(f"{ref_prints}: written from {work} ({len(prints)} images and autolabels)")
    known = json.loads(ref_prints.read_text())
    if sorted(known) != tolerant:
        wrong.append(f"other images or autolabels than the run's: {len(set(tolerant) ^ set(known))} differ in name")
    for rel in tolerant:
        if rel in known:
            shape = cv2.imread(str(work / rel), cv2.IMREAD_UNCHANGED).shape
            if differs(rel, prints[rel], known[rel], shape[0] * shape[1]):
                wrong.append(rel)
    if wrong:
        print(f"the data in {work} differ from the run's ({ref}): {len(wrong)} files, e.g. {wrong[:5]}; the "
              f"renderer or autolabel changed: make the data with a commit of plan.md's progress table")
        return 1
    print(f"data checked: {len(exact)} files byte for byte, {len(tolerant)} images and autolabels within "
          f"CPU rounding")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
