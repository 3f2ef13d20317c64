"""freespace.outdir: the one rule for output folders (manifest, lock, stages) and all-or-nothing files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from freespace.errors import InvalidOptionError, OutputError
from freespace.outdir import META, claim_folder, write_files_together


def _manifest(folder: Path) -> dict:
    return json.loads((folder / META / "manifest.json").read_text())


def test_a_staged_output_replaces_only_the_commands_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with claim_folder(out, "predict") as folder, folder.staged() as stage:
        (stage / "a.png").write_bytes(b"1")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.png").write_bytes(b"2")
    assert _manifest(out) == {"command": "predict", "entries": ["a.png", "sub/b.png"]}
    with claim_folder(out, "predict") as folder, folder.staged() as stage:
        (stage / "c.png").write_bytes(b"3")
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if META not in p.parts) == ["c.png", "sub"]
    assert _manifest(out)["entries"] == ["c.png"]


def test_shards_add_beside_each_other(tmp_path: Path) -> None:
    out = tmp_path / "out"
    for name in ("a", "b"):
        with claim_folder(out, "predict", shared=True) as folder, folder.staged(replace=False) as stage:
            (stage / f"{name}.png").write_bytes(b"x")
    assert _manifest(out)["entries"] == ["a.png", "b.png"]


def test_a_failed_stage_leaves_the_folder_as_it_was(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with claim_folder(out, "predict") as folder, folder.staged() as stage:
        (stage / "a.png").write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with claim_folder(out, "predict") as folder, folder.staged() as stage:
            (stage / "a.png").write_bytes(b"new")
            raise RuntimeError("the work failed")
    assert (out / "a.png").read_bytes() == b"old"
    assert not list((out / META).glob("stage-*"))


def test_a_run_that_wrote_nothing_leaves_no_folder(tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper" / "out"
    with pytest.raises(RuntimeError):
        with claim_folder(out, "evaluate"):
            raise RuntimeError("failed before writing")
    assert not (tmp_path / "new").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    with claim_folder(empty, "evaluate"):
        pass
    assert empty.is_dir() and not any(empty.iterdir())  # a folder that was there stays, as it was


def test_unknown_files_are_refused_and_named(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "deep" / "er").mkdir(parents=True)
    (out / "deep" / "er" / "notes ü.txt").write_text("mine")
    with pytest.raises(InvalidOptionError, match="deep/"):
        with claim_folder(out, "predict"):
            pass
    (tmp_path / "only_empty" / "sub").mkdir(parents=True)  # empty folders hold nothing to lose
    with claim_folder(tmp_path / "only_empty", "predict", entries=["x.png"]):
        pass


def test_entries_cover_whole_subtrees_and_forget_deletes_only_them(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with claim_folder(out, "train", entries=["checkpoints/", "config.yaml"]) as folder:
        (out / "checkpoints").mkdir()
        (out / "checkpoints" / "epoch=3.ckpt").write_bytes(b"w")
        (out / "config.yaml").write_text("a: 1\n")
    with claim_folder(out, "train") as folder:  # every file is known: claimed again
        assert folder.entries() == {"checkpoints/", "config.yaml"}
        with pytest.raises(ValueError):
            folder.forget(["user.txt"])
        folder.forget(["checkpoints/"])
    assert not (out / "checkpoints").exists() and (out / "config.yaml").is_file()


def test_another_commands_folder_and_a_held_lock_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with claim_folder(out, "train", entries=["config.yaml"]):
        (out / "config.yaml").write_text("")
        with pytest.raises(InvalidOptionError, match="another freespace run"):
            with claim_folder(out, "train"):
                pass
    with pytest.raises(InvalidOptionError, match="output of freespace train"):
        with claim_folder(out, "evaluate"):
            pass
    with claim_folder(out, "train", shared=True):
        with claim_folder(out, "train", shared=True):  # shards share it
            pass
        with pytest.raises(InvalidOptionError, match="another freespace run"):
            with claim_folder(out, "train"):
                pass


def test_a_file_is_not_a_folder(tmp_path: Path) -> None:
    path = tmp_path / "f"
    path.write_text("x")
    with pytest.raises(InvalidOptionError, match="is a file"):
        with claim_folder(path, "predict"):
            pass


def test_write_files_together_keeps_earlier_files_when_one_fails(tmp_path: Path) -> None:
    a, b = tmp_path / "a.png", tmp_path / "b.json"
    write_files_together({a: b"A1", b: b"B1"})
    (tmp_path / "blocker").write_text("a file where a folder should be")
    with pytest.raises(OutputError):
        write_files_together({a: b"A2", tmp_path / "blocker" / "c.json": b"C"})
    assert a.read_bytes() == b"A1" and b.read_bytes() == b"B1"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.json", "blocker"]
