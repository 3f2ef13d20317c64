"""The KITTI road benchmark's submission: the testing split predicted as bird's-eye-view maps, zipped."""

from __future__ import annotations

import io as _io
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import InputFileError
from freespace.evaluation.metrics import to_confidence
from freespace.inference.predictor import Predictor
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, atomic_write_bytes, check_outputs, check_writable
from freespace.io.kitti import read_kitti_calib
from freespace.io.outdir import claim_folder

__all__ = ["kitti_submit", "submit_report"]


def kitti_submit(checkpoint: PathLike, root: PathLike, out: PathLike, progress: bool = True) -> dict[str, Any]:
    """Predict the KITTI road testing split and write the benchmark's bird's-eye-view confidence maps
    (``OUT/<cat>_road_<id>.png``, 800×400) and ``OUT/submission.zip`` holding them.

    Every calibration file is read before any prediction; the folder is written all or nothing and
    replaces the files of an earlier submission there (:mod:`freespace.io.outdir`)."""
    from freespace.data.kitti_road import KittiRoad

    check_writable(out, folder=True)
    check_outputs({"out": out}, {"checkpoint": checkpoint, "root": root})
    ds = KittiRoad(root, "testing", disparity_source="none")
    missing = [f.name for f in ds.frames if f.calib is None]
    if missing:
        raise InputFileError(f"{len(missing)} testing frames have no calibration (first: {missing[0]}); the BEV "
                             f"transform needs data_road/testing/calib/<frame>.txt")
    calibs = [read_kitti_calib(f.calib) for f in ds.frames]  # type: ignore[arg-type]  # every file checked first
    predictor = Predictor(checkpoint=checkpoint)
    with claim_folder(out, "kitti-submit") as folder, folder.staged() as staging:
        names = _submit_into(predictor, ds, calibs, staging, progress)
    return {"frames": len(names), "zip": str(Path(out) / "submission.zip")}


def _submit_into(predictor: Predictor, ds: Any, calibs: list[dict[str, np.ndarray]], out: Path,
                 progress: bool) -> list[str]:
    from freespace.evaluation.bev import to_bev
    from freespace.runtime.log import progress_bar

    names = []
    for i, frame in enumerate(progress_bar(ds.frames, desc="kitti-submit", unit="frame", enabled=progress)):
        image = ds.load(i, right=False, label=False, disparity=False).left
        conf = to_confidence(predictor.predict([image])[0])
        bev = to_bev(conf, calibs[i])
        name = f"{frame.category}_road_{frame.name.split('_')[1]}.png"
        write_image(out / name, bev)
        names.append(name)
    buf = _io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in names:
            zf.write(out / name, arcname=name)
    atomic_write_bytes(out / "submission.zip", buf.getvalue())
    return names


def submit_report(result: dict[str, Any], out: PathLike) -> str:
    """One line on what :func:`kitti_submit` wrote into ``out`` (``result``: its return value)."""
    return f"{result['frames']} bird's-eye-view maps → {out}; upload {result['zip']}"
