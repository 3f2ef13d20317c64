"""freespace.io.outdir: the one rule for output folders (manifest, lock, stages) and all-or-nothing files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from freespace.errors import CorruptFileError, InvalidOptionError, OutputError
from freespace.io.files import write_files_together
from freespace.io.outdir import META, claim_folder


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


# ------------------------------------------------------------- issue 20: second look at output folders
def _owned(tmp_path: Path, command: str = "predict", files: tuple[str, ...] = ("a.png",)) -> Path:
    """A folder that ``command`` wrote ``files`` into (in place, listed in its manifest)."""
    out = tmp_path / "out"
    with claim_folder(out, command, entries=files):
        for name in files:
            path = out / name / "x" if name.endswith("/") else out / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(b"mine")
    return out


def _add_entries(out: Path, *entries: str) -> None:
    data = _manifest(out)
    (out / META / "manifest.json").write_text(json.dumps({**data, "entries": data["entries"] + list(entries)}))


@pytest.mark.parametrize("entry", ["../victim.txt", "VICTIM", "", "/", ".", "./", "..", "x/../../victim.txt",
                                   "x//y", ".freespace/", ".freespace/lock"])
def test_a_manifest_entry_outside_the_folder_is_refused_and_never_followed(entry: str, tmp_path: Path) -> None:
    """A hand-edited or crafted manifest (an entry with ``..``, absolute, empty, the folder itself or its
    ``.freespace``) is refused in one line before anything is deleted, ``--overwrite`` (a stage's replace)
    included; the file it names outside and the folder's own files stay."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = _owned(tmp_path)
    _add_entries(out, entry.replace("VICTIM", str(victim)))
    with pytest.raises(CorruptFileError, match="manifest.json lists") as info:
        with claim_folder(out, "predict") as folder, folder.staged() as stage:
            (stage / "b.png").write_bytes(b"new")
    assert "\n" not in str(info.value)
    assert victim.read_text() == "precious" and (out / "a.png").read_bytes() == b"mine"
    assert not (out / "b.png").exists()


def test_a_linked_entry_is_removed_as_a_link_never_followed(tmp_path: Path) -> None:
    """Entries that are links to a file or a folder outside (a ``"dir/"`` entry included): replacing the
    output deletes the links, and the files they lead to stay."""
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "sub").mkdir(parents=True)
    (elsewhere / "keep.txt").write_text("keep")
    (elsewhere / "sub" / "keep2.txt").write_text("keep")
    out = _owned(tmp_path)
    (out / "link.png").symlink_to(elsewhere / "keep.txt")
    (out / "tree").symlink_to(elsewhere / "sub", target_is_directory=True)
    _add_entries(out, "link.png", "tree/")
    with claim_folder(out, "predict") as folder, folder.staged() as stage:
        (stage / "a.png").write_bytes(b"new")
    assert sorted(p.name for p in out.iterdir()) == [META, "a.png"]
    assert (elsewhere / "keep.txt").read_text() == "keep" and (elsewhere / "sub" / "keep2.txt").read_text() == "keep"


def test_an_entry_behind_a_link_that_leads_out_is_never_touched(tmp_path: Path) -> None:
    """``link/x`` in the manifest where ``link`` leads out of the folder: neither deleting nor writing goes
    through the link."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "victim.png").write_text("precious")
    out = _owned(tmp_path)
    (out / "link").symlink_to(elsewhere, target_is_directory=True)
    _add_entries(out, "link/victim.png")
    with pytest.raises(OutputError, match="outside it through a symbolic link"):
        with claim_folder(out, "predict") as folder, folder.staged() as stage:  # replace: forget the stale entry
            (stage / "a.png").write_bytes(b"new")
    with pytest.raises(OutputError, match="outside it through a symbolic link"):
        with claim_folder(out, "predict") as folder, folder.staged(replace=False) as stage:
            (stage / "link").mkdir()
            (stage / "link" / "new.png").write_bytes(b"new")
    assert sorted(p.name for p in elsewhere.iterdir()) == ["victim.png"]
    assert (elsewhere / "victim.png").read_text() == "precious"


@pytest.mark.parametrize("what", ["meta-link", "meta-file", "lock-link"])
def test_a_planted_freespace_folder_or_lock_is_refused(what: str, tmp_path: Path) -> None:
    """``.freespace`` a link to another folder (e.g. another output's) or a file, or its lock a link:
    refused in one line, and nothing is written where the link leads."""
    other = tmp_path / "other"
    other.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    if what == "meta-link":
        (out / META).symlink_to(other, target_is_directory=True)
    elif what == "meta-file":
        (out / META).write_text("x")
    else:
        (out / META).mkdir()
        (out / META / "lock").symlink_to(other / "created-by-the-lock")
    with pytest.raises((InvalidOptionError, OutputError)) as info:
        with claim_folder(out, "predict") as folder, folder.staged() as stage:
            (stage / "a.png").write_bytes(b"x")
    assert "\n" not in str(info.value) and ".freespace" in str(info.value)
    assert list(other.iterdir()) == [] and not (out / "a.png").exists()


def test_a_stale_stage_that_is_a_link_is_unlinked_not_followed(tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.txt").write_text("keep")
    out = _owned(tmp_path)
    (out / META / "stage-999999999-x").symlink_to(elsewhere, target_is_directory=True)
    with claim_folder(out, "predict"):
        pass
    assert not (out / META / "stage-999999999-x").is_symlink() and (elsewhere / "keep.txt").read_text() == "keep"


def test_a_file_entry_does_not_cover_a_folder_of_that_name(tmp_path: Path) -> None:
    """The manifest lists ``a.png`` (a file) and the user's folder ``a.png/`` stands there: it is the user's
    (refused, named), and forgetting the entry never deletes the folder."""
    out = _owned(tmp_path)
    (out / "a.png").unlink()
    (out / "a.png").mkdir()
    (out / "a.png" / "thesis.tex").write_text("mine")
    with pytest.raises(InvalidOptionError, match="a.png/"):
        with claim_folder(out, "predict"):
            pass
    with pytest.raises(OutputError, match="has a folder a.png"):
        with claim_folder(tmp_path / "out2", "predict", entries=["a.png"]) as folder:
            (tmp_path / "out2" / "a.png").mkdir()
            (tmp_path / "out2" / "a.png" / "thesis.tex").write_text("mine")
            folder.forget(["a.png"])
    assert (out / "a.png" / "thesis.tex").is_file() and (tmp_path / "out2" / "a.png" / "thesis.tex").is_file()


def test_a_killed_atomic_write_does_not_block_the_next_run(tmp_path: Path) -> None:
    """What SIGKILL leaves beside an entry (``.NAME.XXXXXXXX.tmp`` of an atomic write) is the command's: a
    shard accepts it, a whole run removes it; a temporary-looking file beside no entry is the user's."""
    out = _owned(tmp_path, "generate", ("settings.json", "reports/000001.json"))
    left = [out / ".settings.json.k1_2abcd.tmp", out / "reports" / ".000001.json.zz9xy0ab.tmp"]
    for path in left:
        path.write_bytes(b"half")
    with claim_folder(out, "generate", shared=True):
        assert all(p.exists() for p in left)
    with claim_folder(out, "generate"):
        pass
    assert not any(p.exists() for p in left) and (out / "settings.json").read_bytes() == b"mine"
    (out / ".notes.txt.abcdefgh.tmp").write_text("mine")
    with pytest.raises(InvalidOptionError, match=r"\.notes\.txt\.abcdefgh\.tmp"):
        with claim_folder(out, "generate"):
            pass


def test_a_folder_inside_another_commands_subtree_is_refused(tmp_path: Path) -> None:
    """``predict --out RUN/checkpoints/preds`` (inside a subtree that ``train`` replaces on a restart) is
    refused; a folder beside the subtree is fine, and so is the command's own nesting (``demo`` writing
    ``dataset/`` with ``synth``) while it holds the enclosing folder."""
    run = _owned(tmp_path, "train", ("checkpoints/", "config.yaml"))
    with pytest.raises(InvalidOptionError, match="inside checkpoints/ of .* freespace train"):
        with claim_folder(run / "checkpoints" / "preds", "predict"):
            pass
    assert not (run / "checkpoints" / "preds").exists()
    with claim_folder(tmp_path / "demo", "demo", entries=["dataset/"]):
        with claim_folder(tmp_path / "demo" / "dataset", "synth", entries=["synth.json"]):
            (tmp_path / "demo" / "dataset" / "synth.json").write_text("{}")
    with pytest.raises(InvalidOptionError, match="output of freespace demo"):
        with claim_folder(tmp_path / "demo" / "dataset", "synth"):  # by hand, later: the demo's own
            pass

