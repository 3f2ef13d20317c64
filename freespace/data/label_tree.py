"""The label tree, in one place: the road labels that ``freespace autolabel`` writes and that ``generate`` of a
dataset, ``train`` and ``reproduce`` read (their ``labels`` parameter).

A label tree is a folder of ``<frame>.png`` (KITTI colours; a frame name may hold folders, KITTI raw's
``<drive>/<frame>``), ``confidence/<frame>.png`` (8-bit, ``round(255·c)``), ``reports/<frame>.json``, and a
``settings.json`` that names the dataset it labels. This module does every job on it:

* **write** a label's files (:func:`write_label_files`, :func:`confidence_path`);
* **describe** it: its label files (:func:`label_files`), a record of it in words (:func:`tree_text`);
* **hash** it and the other files a run reads (:func:`label_tree_sha256`, :func:`file_sha256`,
  :func:`tree_record`, :func:`file_record`, :func:`changed_inputs`);
* **check** that it labels the frames it is given to (:func:`check_label_tree`, :func:`label_tree_pixels`);
* **record** which tree the frames of ``generate`` were fitted to (:func:`hold_labels_record`, ``labels.json``);
* **apply** it to a dataset (:func:`tree_labels`, :func:`apply_label_tree`, :func:`labelled_from_tree`).

Torch- and pydantic-free: ``freespace generate`` and ``freespace autolabel`` (the base install) use it too.
"""

from __future__ import annotations

import copy
import functools
import json
import logging
import os
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.errors import DatasetError, InputFileError, InvalidOptionError, param
from freespace.io.codecs import encode_image, road_label_to_kitti
from freespace.io.files import PathLike, check_outputs, check_writable, encode_json, write_files_together, write_json
from freespace.io.outdir import claim_folder
from freespace.labels import RoadLabel

log = logging.getLogger(__name__)

__all__ = ["resolved_path", "file_signature", "file_sha256", "CONFIDENCE", "LABELS_RECORD", "confidence_path",
           "write_label_files", "label_files", "label_tree_sha256", "tree_record", "files_record", "file_record",
           "changed_inputs", "tree_text", "label_tree_pixels", "check_label_tree", "tree_labels", "apply_label_tree",
           "labelled_from_tree", "hold_labels_record"]

#: the folder of a label tree that holds each label's confidence (``confidence/<frame>.png``)
CONFIDENCE = "confidence"
#: the folders of an autolabel tree that hold no labels
_NOT_LABELS = (CONFIDENCE, "reports", ".freespace")
#: generate's record of the label tree its frames were fitted to (``labels``), beside its settings.json
LABELS_RECORD = "labels.json"


# --- paths and file hashes -----------------------------------------------------------------------------------


def resolved_path(value: str) -> str:
    """``value`` absolute, ``~`` expanded and symbolic links followed (two spellings of one file compare
    equal; the text works from any folder)."""
    return os.path.realpath(os.path.expanduser(value))


def file_signature(path: Path) -> tuple[int, int, int]:
    """What tells a file changed without reading it: its modification time (ns), size (bytes) and inode."""
    st = path.stat()
    return st.st_mtime_ns, st.st_size, st.st_ino



def file_sha256(path: PathLike) -> str:
    """The SHA-256 (hex) of the file ``path``'s bytes; computed once per process for a file unchanged since
    (its modification time, size and inode key the cache)."""
    real = Path(resolved_path(os.fspath(path)))
    return _file_sha256(real, file_signature(real))


@functools.lru_cache(maxsize=64)
def _file_sha256(path: Path, signature: tuple[int, int, int]) -> str:
    import hashlib

    digest = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


# --- the tree's files: written, listed ---------------------------------------------------------------------


def confidence_path(tree: PathLike, frame: str) -> Path:
    """Where the label tree ``tree`` holds the confidence of frame ``frame``: ``tree/confidence/<frame>.png``."""
    return Path(tree) / CONFIDENCE / f"{frame}.png"


def write_label_files(label: RoadLabel, out: PathLike, confidence: np.ndarray | None = None,
                      confidence_out: PathLike | None = None, report: Mapping[str, Any] | None = None,
                      report_out: PathLike | None = None) -> list[Path]:
    """Write a road label as a label tree holds it, all or nothing (when one file cannot be written, the files
    there before stay as they were): ``label`` to ``out`` (KITTI colours PNG: road magenta, non-road red, don't
    care black), ``confidence`` (``uint8 H×W``, ``round(255·c)`` of a confidence ``c`` in [0, 1]) to
    ``confidence_out`` (8-bit grey PNG) and ``report`` to ``report_out`` (JSON), each when given. Returns the
    paths written."""
    files: dict[PathLike, bytes] = {out: encode_image(road_label_to_kitti(label), ".png")}
    if confidence is not None and confidence_out is not None:
        files[confidence_out] = encode_image(confidence, ".png")
    if report is not None and report_out is not None:
        files[report_out] = encode_json(dict(report))
    return write_files_together(files)


def label_files(folder: PathLike) -> dict[str, Path]:
    """The label files of the label tree ``folder`` that training reads, by frame name: ``<frame>.png``, where
    a frame name may hold folders (KITTI raw's ``<drive>/<frame>``; a link is followed; ``confidence/``,
    ``reports/`` and ``.freespace/`` hold no labels)."""
    folder = Path(folder)
    found = {}
    for entry in sorted(folder.rglob("*.png")):
        rel = entry.relative_to(folder)
        if rel.parts[0] not in _NOT_LABELS and entry.is_file():
            found[rel.with_suffix("").as_posix()] = entry
    return found


# --- hashes and records ------------------------------------------------------------------------------------


def label_tree_sha256(folder: PathLike) -> tuple[str, int]:
    """A content hash of the label tree ``folder`` (SHA-256, hex: over its label files' names, sorted, and
    their bytes; the same files give the same hash wherever the tree lies) and how many label files it has.
    Computed once per process for a tree whose files are unchanged."""
    files = label_files(resolved_path(os.fspath(folder)))
    return _tree_sha256(tuple((name, path, file_signature(path)) for name, path in files.items())), len(files)


@functools.lru_cache(maxsize=16)
def _tree_sha256(files: tuple[tuple[str, Path, tuple[int, int, int]], ...]) -> str:
    import hashlib

    digest = hashlib.sha256()
    for name, path, _ in files:
        data = path.read_bytes()
        digest.update(f"{name}.png\0{len(data)}\0".encode())
        digest.update(data)
    return digest.hexdigest()


def tree_record(folder: PathLike) -> dict[str, Any]:
    """What a run or ``generate`` records of the label tree ``folder``: ``{"path": resolved, "sha256":
    content hash, "files": label files}`` (:func:`label_tree_sha256`)."""
    digest, count = label_tree_sha256(folder)
    return {"path": resolved_path(os.fspath(folder)), "sha256": digest, "files": count}


def files_record(folder: PathLike, paths: list[Path]) -> dict[str, Any]:
    """What a run records of the files ``paths`` it read from ``folder`` (a labelled folder's images or labels):
    ``{"path": resolved folder, "sha256": content hash over the files' names and bytes, "files": count}``."""
    files = tuple((p.name, Path(resolved_path(os.fspath(p))), file_signature(p)) for p in sorted(paths))
    return {"path": resolved_path(os.fspath(folder)), "sha256": _tree_sha256(files), "files": len(files)}


def file_record(path: PathLike) -> dict[str, Any]:
    """What a run records of an input file ``path`` (e.g. encoder weights): ``{"path": resolved, "sha256"}``."""
    return {"path": resolved_path(os.fspath(path)), "sha256": file_sha256(path)}


def changed_inputs(recorded: Mapping[str, Any], now: Mapping[str, Any]) -> list[str]:
    """The inputs whose content hash in ``recorded`` (a run's inputs.json) differs from ``now`` (records of
    :func:`file_record` and :func:`tree_record` by parameter name, e.g. ``encoder_weights``, ``labels``), as
    ``"name path (sha256 abc… then, def… now)"``, in ``now``'s order; an input one of them lacks is not compared."""
    changed = []
    for key, new in now.items():
        old = recorded.get(key)
        if isinstance(old, dict) and isinstance(new, dict) and old.get("sha256") != new.get("sha256"):
            changed.append(f"{param(key)} {new.get('path')} (sha256 {str(old.get('sha256'))[:12]}… then, "
                           f"{str(new.get('sha256'))[:12]}… now)")
    return changed


def tree_text(record: Mapping[str, Any] | None) -> str:
    """A label tree's record (:func:`tree_record`; None: the dataset's own labels) in words, for messages."""
    return "the dataset's own labels" if record is None else \
        f"the label tree {record.get('path')} (sha256 {str(record.get('sha256'))[:12]}…)"


# --- checks: a tree that labels the frames it is given to --------------------------------------------------


@functools.lru_cache(maxsize=16)
def _inspect_labels(files: tuple[tuple[str, Path, tuple[int, int, int]], ...]) -> dict[str, tuple[str | None, int]]:
    """Each label file's problem (:func:`~freespace.io.codecs.label_image_problem`, None: a label) and its
    number of labelled (not don't care) pixels."""
    from freespace.io.codecs import label_image_problem, read_image, road_label_from_image

    found = {}
    for name, path, _ in files:
        img = read_image(path, what="road label")
        problem = label_image_problem(img)
        found[name] = (problem, 0 if problem else int(np.count_nonzero(road_label_from_image(img).valid)))
    return found


def label_tree_pixels(folder: PathLike) -> dict[str, int]:
    """The labelled (not don't care) pixels of each label file of the tree ``folder``, by frame name; read
    once per process for unchanged files. Raises as :func:`check_label_tree`."""
    files = label_files(folder)
    found = _inspect_labels(tuple((n, p, file_signature(p)) for n, p in files.items()))
    return {name: count for name, (_, count) in found.items()}


def check_label_tree(folder: PathLike, dataset: str, root: PathLike, split: str | None,
                     option: str = "labels") -> None:
    """Refuse, in one line naming ``option``, a label tree that does not belong to the frames it would label:

    * made for another dataset: its ``settings.json`` (written by ``freespace autolabel``) names another
      layout, root (compared resolved) or on-disk split than ``dataset``, ``root`` and ``split`` (None: the
      layout's first), whose frames may share the names;
    * no label tree: no ``<frame>.png``, or files that are not label images (confidence maps, predictions,
      overlays: :func:`~freespace.io.codecs.label_image_problem`);
    * nothing labelled: every pixel of every label is don't care (training would learn nothing, at loss 0).

    Raises:
        InputFileError: no folder ``folder``. DatasetError: one of the above.
    """
    from freespace.data.registry import get_dataset_class

    folder = Path(folder)
    if not folder.is_dir():
        what = "is a file" if folder.exists() else "not found"  # a file where a folder is wanted: said so
        raise InputFileError(f"{param(option)} {folder} {what}; give the folder that `freespace autolabel` wrote "
                             f"for the dataset")
    settings_path = folder / "settings.json"
    if settings_path.is_file():
        try:
            made = json.loads(settings_path.read_text())
        except (OSError, UnicodeDecodeError, ValueError):
            made = None
        if not isinstance(made, dict):
            raise DatasetError(f"{param(option)} {folder}: its settings.json is unreadable, so which dataset it "
                               f"labels is unknown; label the dataset again with `freespace autolabel`")
        ours = {"dataset": get_dataset_class(dataset).name, "root": resolved_path(os.fspath(root)),
                "split": split or get_dataset_class(dataset).splits[0]}
        theirs = {"dataset": made.get("dataset"), "split": made.get("split"),
                  "root": resolved_path(str(made["root"])) if isinstance(made.get("root"), str) else made.get("root")}
        other = [k for k in ("root", "dataset", "split") if theirs[k] is not None and theirs[k] != ours[k]]
        if other:
            k = other[0]
            raise DatasetError(f"{param(option)} {folder} labels another dataset: `freespace autolabel` made it for "
                               f"{k} {theirs[k]}, not {ours[k]} (frames of the same names are other images); label "
                               f"this one with `freespace autolabel` ({dataset} at {root}) and give that tree")
    dataset_root = resolved_path(os.fspath(folder)) == resolved_path(os.fspath(root)) or any(
        (folder / name).exists() for name in ("freespace.yaml", "training", "data_road"))
    files = {} if dataset_root else label_files(folder)  # a dataset root's images are no labels
    if not files:
        what = "a dataset root, not a label tree" if dataset_root else "no <frame>.png"
        raise DatasetError(f"{param(option)} {folder} holds {what}; give the folder that `freespace autolabel` "
                           f"wrote for the dataset (<frame>.png in KITTI colours)")
    found = _inspect_labels(tuple((n, p, file_signature(p)) for n, p in files.items()))
    bad = [(name, problem) for name, (problem, _) in found.items() if problem]
    if bad:
        subfolder = folder.parent if folder.name == "confidence" and (folder.parent / "settings.json").is_file() \
            else None
        fix = (f"give {subfolder}, the label tree above it" if subfolder is not None else
               "give the label tree that `freespace autolabel` wrote for the dataset (<frame>.png in KITTI colours)")
        raise DatasetError(f"{param(option)} {folder}: {len(bad)} of its {len(files)} files are no labels ({bad[0][0]}"
                           f".png is {bad[0][1]}); {fix}")
    if not any(count for _, count in found.values()):
        raise DatasetError(f"{param(option)} {folder}: every pixel of its {len(files)} labels is don't care, so "
                           f"there is nothing to learn from; label the frames again (`freespace autolabel`)")


# --- applying a tree to a dataset --------------------------------------------------------------------------


def tree_labels(folder: PathLike, names: Iterable[str]) -> list[str]:
    """The frames of ``names`` that the label tree ``folder`` labels (a ``folder/<name>.png`` file), in order."""
    return [name for name in names if (Path(folder) / f"{name}.png").is_file()]


def apply_label_tree(dataset: StereoRoadDataset, folder: PathLike, names: Iterable[str]) -> StereoRoadDataset:
    """``dataset`` with the road labels of the frames ``names`` read from the label tree ``folder``
    (``folder/<name>.png``, KITTI colours) instead of its own; other frames keep theirs. Every named frame must
    have its file there.

    Raises:
        DatasetError: a name is not a frame of ``dataset``, or has no ``<name>.png`` in ``folder``.
    """
    files = {}
    for name in names:
        dataset.index(name)
        path = Path(folder) / f"{name}.png"
        if not path.is_file():
            raise DatasetError(f"{path} not found: the label tree {folder} has no label of frame {name}")
        files[name] = path
    view = copy.copy(dataset)
    view.label_files = {**dataset.label_files, **files}
    return view


def labelled_from_tree(dataset: StereoRoadDataset, labels: PathLike, name: str, root: PathLike,
                       split: str | None) -> tuple[StereoRoadDataset, dict[str, Any]]:
    """The frames of ``dataset`` (layout ``name`` at ``root``, on-disk split ``split``, as the user gave them)
    that the label tree ``labels`` labels, labelled from it (:func:`apply_label_tree`; the others are left out,
    in one warning line), and the tree's record (:func:`tree_record`). What ``generate`` of a dataset fits its
    road models to.

    Raises:
        InputFileError, DatasetError: as :func:`check_label_tree`, or the tree labels none of the frames.
    """
    check_label_tree(labels, name, root, split)
    files = label_files(labels)
    names = [f.name for f in dataset.frames if f.name in files]
    if not names:
        raise DatasetError(f"{param('labels')} {labels} labels none of the {len(dataset.frames)} frames of "
                           f"{name} at {root} (e.g. {dataset.frames[0].name}); give the tree that "
                           f"`freespace autolabel` wrote for this dataset")
    skipped = [f.name for f in dataset.frames if f.name not in files]
    if skipped:
        log.warning("%d of %d frames have no label in %s and are skipped (%s%s)", len(skipped), len(dataset.frames),
                    labels, skipped[0], ", …" if len(skipped) > 1 else "")
    return apply_label_tree(dataset.subset(names), labels, names), tree_record(labels)


# --- generate's record of the tree its frames were fitted to -----------------------------------------------


def _recorded_tree(record: Path, started: bool, tree: dict[str, Any] | None) -> Any:
    """The label tree that ``OUT/labels.json`` (``record``) says the frames there were fitted to: its record,
    None (the dataset's own labels: frames made, ``started``, and no record), ``"unreadable"``, or ``tree``
    when nothing was made yet."""
    if not record.is_file():
        return None if started else tree
    try:
        return json.loads(record.read_text())["labels"]
    except (OSError, ValueError, KeyError, TypeError):
        return "unreadable"


@contextmanager
def hold_labels_record(out: PathLike, tree: dict[str, Any] | None, root: PathLike, labels: PathLike | None,
                       overwrite: bool) -> Iterator[None]:
    """Hold ``OUT/labels.json``, generate's record of the label tree (``tree``: :func:`tree_record`, None: the
    dataset's own labels) that the frames in ``out`` were fitted to, around the run. An ``out`` made with another
    tree, or with the dataset's own labels when a tree is given now (or the reverse), is refused in one line,
    unless ``overwrite``: then every file of the earlier run goes, and every frame is made again. The record is
    written before any frame, so that a run killed half-way resumes with the same tree, under a claim of the
    folder by generate (:mod:`freespace.io.outdir`: shared, as the shards of one run share it); it is
    removed again when the run fails before generating anything.

    Raises:
        InvalidOptionError: ``out`` holds frames fitted to other labels (and not ``overwrite``).
        OutputError: ``out`` cannot be written.
    """
    folder_path = Path(out)
    record, settings = folder_path / LABELS_RECORD, folder_path / "settings.json"
    if tree is None and not record.exists():
        yield  # the dataset's own labels, and no tree recorded: generate's own settings say it all
        return
    check_writable(out, folder=True)  # what generate checks first: nothing is written where it refuses to
    check_outputs({"out": out}, {"root": root, **({"labels": labels} if labels else {})})
    created = not folder_path.exists()
    with claim_folder(out, "generate", shared=True) as folder:
        started = settings.is_file()
        old = _recorded_tree(record, started, tree)
        if old != tree:
            if not overwrite:
                was = "an unreadable record of their labels" if old == "unreadable" else tree_text(old)
                raise InvalidOptionError(f"{param('out')} {out} holds frames fitted to {was}, not to "
                                         f"{tree_text(tree)}; choose another {param('out')}, or add "
                                         f"{param('overwrite')} to make them again")
            folder.forget(folder.entries())  # every frame of the other labels, whichever this run makes
        if tree is None:
            folder.forget({LABELS_RECORD} & folder.entries())
        else:
            folder.record({LABELS_RECORD})
            write_json(record, {"labels": tree})
    try:
        yield
    except BaseException:
        if tree is not None and not started and not settings.exists():  # refused before any frame: leave no record
            with claim_folder(out, "generate", shared=True) as folder:
                folder.forget({LABELS_RECORD} & folder.entries())
            if created:
                try:
                    folder_path.rmdir()  # empty again (its manifest went with the last entry)
                except OSError:
                    pass
        raise
