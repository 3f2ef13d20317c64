"""The real-roads study's protocol file gives the cells run.sh's cell() makes (``pytest studies/``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from freespace.experiments import Protocol

STUDY = Path(__file__).resolve().parents[1]


def test_the_real_roads_protocol_gives_run_sh_options(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """studies/real-roads/protocol.yaml: run.sh's cell() data, augment and run folder names, variant by variant
    (run.sh's tag: ``tr 'A-Z+' 'a-z_'``; its --cache-dir for HA-R-auto and R-auto-dup only; a -fp variant: its
    base's data with --flip --photometric)."""
    raw, work = tmp_path / "raw", tmp_path / "work"
    for folder in (raw, work / "autolabels", work / "sgbm-cache", work / "syn", work / "splits-raw",
                   work / "mix/splits"):
        folder.mkdir(parents=True)
    for part in ("train", "val", "test"):
        for lists in (work / "splits-raw", work / "mix/splits"):
            (lists / f"{part}.txt").write_text(f"{part}\n")
    monkeypatch.setenv("RAW", str(raw))
    monkeypatch.setenv("WORK", str(work))
    p = Protocol.load(STUDY / "protocol.yaml")
    real = {"dataset": "kitti-raw", "root": str(raw), "labels": str(work / "autolabels"),
            "splits_dir": str(work / "splits-raw")}
    run_sh = {  # studies/real-roads/run.sh, cell()
        "S": ({"dataset": "synth", "root": str(work / "syn")}, ()),
        "R-auto": (real, ()),
        "HA-R-auto": ({**real, "cache_dir": str(work / "sgbm-cache")}, ("homography",)),
        "R-auto-dup": ({**real, "cache_dir": str(work / "sgbm-cache")}, ("duplicate",)),
        "S+R-auto": ({"dataset": "generic", "root": str(work / "mix"), "splits_dir": str(work / "mix/splits")}, ()),
    }
    run_sh |= {f"{name}-fp": run_sh[name] for name in ("R-auto", "S+R-auto")}
    assert p.variants == tuple(run_sh)
    for name, (values, augment) in run_sh.items():
        spec = p.declared[name]
        given = {k: v for k, v in p.data[spec.data].training(spec.augment).items() if v is not None}
        assert (given, spec.augment) == (values, augment), name
        assert spec.samples == (("flip", "photometric") if name.endswith("-fp") else ()), name
        assert spec.tag == name.translate(str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ+", "abcdefghijklmnopqrstuvwxyz_"))
    assert ("HA-R-auto", "R-auto-dup") in p.gains and ("R-auto", "S") in p.gains
