"""The S+R-auto dataset of the real-roads study: one generic ``freespace`` dataset of links to the rendered
frames (their own labels) and the real KITTI raw frames (their autolabels), with its subset lists.

Training: every rendered frame and the real drives' training block; validation and test: the real drives'
val and test blocks (autolabels: no human label before the real test frames). Frame names: ``syn-<frame>``
and ``<drive>-<frame>``. Labels are KITTI colours in both sources (road magenta, non-road red, don't care
black).

    python studies/real-roads/mix.py --syn SYN --raw RAW --autolabels AL --splits SPLITS --out MIX
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def _link(target: Path, link: Path) -> None:
    link.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(target.resolve(), link)


def link_drives(raw: Path, autolabels: Path, splits: Path, out: Path, lists: dict[str, list[str]],
                copies: int = 1) -> None:
    """Link the KITTI raw frames of the subset lists ``splits/{train,val,test}.txt`` that ``autolabels`` labels, with
    their labels, as ``out/left/<drive>-<frame>.png`` and ``out/label/...``, appending their names to ``lists``;
    ``copies``: each training frame is listed this many times (``<name>-c1``, ...)."""
    drives = {p.name: p for p in raw.rglob("*_drive_*_sync") if p.is_dir()}
    for part in lists:
        for frame in (splits / f"{part}.txt").read_text().split():
            drive, number = frame.split("/")
            label = autolabels / drive / f"{number}.png"
            if not label.is_file():
                continue
            for copy in range(copies if part == "train" else 1):
                name = f"{drive}-{number}" + (f"-c{copy}" if copy else "")
                _link(drives[drive] / "image_02" / "data" / f"{number}.png", out / "left" / f"{name}.png")
                _link(label, out / "label" / f"{name}.png")
                lists[part].append(name)


def build(syn: Path, raw: Path, autolabels: Path, splits: Path, out: Path) -> dict[str, list[str]]:
    """Write the links, ``freespace.yaml`` and ``splits/{train,val,test}.txt`` under ``out`` (a new folder);
    return the subset lists (frame names)."""
    if out.exists():
        raise SystemExit(f"{out} exists; give a new folder")
    lists: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    images = syn / "data_road" / "training" / "image_2"
    for image in sorted(images.glob("*.png")):
        category, number = image.stem.split("_")
        name = f"syn-{image.stem}"
        _link(image, out / "left" / f"{name}.png")
        _link(syn / "data_road" / "training" / "gt_image_2" / f"{category}_road_{number}.png",
              out / "label" / f"{name}.png")
        lists["train"].append(name)
    link_drives(raw, autolabels, splits, out, lists)
    (out / "freespace.yaml").write_text("left: left\nlabel: label\nlabel_encoding: kitti\n")
    (out / "splits").mkdir()
    for part, names in lists.items():
        (out / "splits" / f"{part}.txt").write_text("".join(f"{n}\n" for n in names))
    return lists


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("syn", "raw", "autolabels", "splits", "out"):
        ap.add_argument(f"--{name}", type=Path, required=True)
    a = ap.parse_args()
    lists = build(a.syn, a.raw, a.autolabels, a.splits, a.out)
    print(", ".join(f"{k} {len(v)}" for k, v in lists.items()))


if __name__ == "__main__":
    main()
