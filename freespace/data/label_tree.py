"""The label tree: the road labels that ``freespace autolabel`` writes (``<frame>.png`` in KITTI colours, a
``settings.json`` that names the dataset) and that ``generate`` of a dataset, ``train`` and ``reproduce`` read
(their ``labels`` parameter): its files, its content hash, and the checks that it labels the frames it is given to.

Torch- and pydantic-free: ``freespace generate`` (the base install) reads label trees too.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from freespace.errors import DatasetError, InputFileError, param
from freespace.io.files import PathLike

__all__ = ["resolved_path", "file_signature", "file_sha256", "label_files", "label_tree_sha256", "label_tree_pixels",
           "check_label_tree"]


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


#: the folders of an autolabel tree that hold no labels
_NOT_LABELS = ("confidence", "reports", ".freespace")


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
    import json

    from freespace.data.registry import get_dataset_class
    folder = Path(folder)
    if not folder.is_dir():
        raise InputFileError(f"{param(option)} {folder} not found; give the folder that `freespace autolabel` wrote "
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
