"""Files the package writes, and the rules for them: atomic writes (one file, or several all or nothing),
JSON and CSV, checks of output paths before any work, and the one-line errors for missing inputs.

Every writer writes to a temporary file beside the target and renames it, so a crash or a user mistake
never leaves a partial output file. Output folders follow :mod:`freespace.io.outdir`.
"""

from __future__ import annotations

import csv
import io as _io
import json
import os
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from freespace.errors import InputFileError, InvalidOptionError, OutputError, param

PathLike = str | os.PathLike[str]

__all__ = ["PathLike", "atomic_write_bytes", "write_files_together", "atomic_write_text", "encode_json", "write_json",
           "write_csv", "check_outputs", "check_writable", "check_writable_files", "missing_input", "read_bytes"]

# ---------------------------------------------------------------------------------------------------
# atomic writes

_UMASK = os.umask(0)
os.umask(_UMASK)


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then ``os.replace``).

    Parent folders are created. Returns the path written.
    """
    return write_files_together({path: data})[0]


def write_files_together(files: Mapping[PathLike, bytes]) -> list[Path]:
    """Write several output files all or nothing: each goes to a temporary file beside its target, and
    only when every one is written are they renamed into place. When any write fails, the temporary
    files are removed and every earlier file at the targets is left as it was.

    Returns the paths written.
    """
    staged: list[tuple[str, Path]] = []
    try:
        for target, data in files.items():
            target = Path(target)
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
            staged.append((tmp, target))
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(data)
                os.chmod(tmp, 0o666 & ~_UMASK)
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
        for tmp, target in staged:
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    return [target for _, target in staged]


def atomic_write_text(path: PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically. Returns the path written."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def encode_json(obj: Any) -> bytes:
    """``obj`` as the bytes of an indented UTF-8 JSON file (NaN/inf are rejected: use None)."""
    return (json.dumps(obj, indent=2, allow_nan=False) + "\n").encode("utf-8")


def check_writable(path: PathLike, name: str = "out", *, folder: bool = False) -> Path:
    """Refuse, before any work, an output that cannot be written where it is named.

    Args:
        path: the output file (``folder=False``) or folder (``folder=True``); it need not exist.
        name: the parameter that named it, for the message (:func:`freespace.errors.param`).

    Raises :class:`InvalidOptionError` when ``path`` is a folder where a file is wanted or a file where a
    folder is, and :class:`OutputError` when a folder on the way to it is a file, or the nearest existing
    folder is not writable (folders on the way are created by the writers). Nothing is created.
    """
    path, flag = Path(os.path.expanduser(os.fspath(path))), param(name)
    if folder and path.exists() and not path.is_dir():
        raise InvalidOptionError(f"{flag} {path} is a file; give a folder")
    if not folder and path.is_dir():
        raise InvalidOptionError(f"{flag} {path} is a folder; give a file name")
    existing = path.absolute().parent
    while not existing.exists() and not existing.is_symlink() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"cannot write {flag} {path}: {existing} is a file, not a folder; choose another path")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {flag} {path}: no permission to write in {existing}; choose a writable "
                          f"folder")
    return path


def check_writable_files(outputs: Mapping[str, PathLike | None]) -> None:
    """:func:`check_writable` for every output file given (parameter name → path; None = not given), before
    any input is read."""
    for name, path in outputs.items():
        if path is not None:
            check_writable(path, name)


def write_json(path: PathLike, obj: Any) -> Path:
    """Write ``obj`` as indented JSON (NaN/inf are rejected: use None) atomically."""
    return atomic_write_bytes(path, encode_json(obj))


def check_outputs(outputs: dict[str, PathLike | None], inputs: dict[str, PathLike | None]) -> None:
    """Refuse outputs that would overwrite or land among a command's inputs, before any work.

    Args:
        outputs: parameter name → output path (file or folder; None = not given).
        inputs: parameter name → input path (file or folder; None = not given).

    Raises :class:`InvalidOptionError` when an output is an input, lies inside an input folder, or is a
    folder that holds an input, or when two outputs are the same path. Symbolic links are resolved
    first, so a link to an input counts as the input.
    """
    def real(p: PathLike) -> Path:
        return Path(os.path.realpath(os.path.expanduser(os.fspath(p))))

    def named(key: str) -> str:  # "input[1]": the second of the paths of the parameter input
        name, bracket, rest = key.partition("[")
        return param(name) + bracket + rest

    outs = {named(k): real(v) for k, v in outputs.items() if v is not None}
    ins = {named(k): real(v) for k, v in inputs.items() if v is not None}
    for out_name, out in outs.items():
        for in_name, src in ins.items():
            if out == src:
                raise InvalidOptionError(f"{out_name} {out} is the input {in_name}; the command would overwrite "
                                         f"it: choose another output path")
            if out.is_relative_to(src):
                raise InvalidOptionError(f"{out_name} {out} lies inside the input {in_name} {src}; choose an "
                                         f"output outside the input folder")
            if src.is_relative_to(out):
                raise InvalidOptionError(f"the input {in_name} {src} lies inside {out_name} {out}; choose an "
                                         f"output folder that holds no input")
    seen: dict[Path, str] = {}
    for out_name, out in outs.items():
        if out in seen:
            raise InvalidOptionError(f"{out_name} and {seen[out]} are the same path {out}; give two paths")
        seen[out] = out_name


def write_csv(path: PathLike, fields: Sequence[str], rows: Iterable[Mapping[str, Any]],
              extra: Literal["raise", "ignore"] = "raise") -> Path:
    """Write ``rows`` (dicts) as a CSV file with the header ``fields``, atomically.

    Values are written with ``str`` (missing keys as empty cells), lines end with ``\n``. ``extra``: what a
    key outside ``fields`` does — ``"raise"`` (ValueError, a programming error) or ``"ignore"``.
    """
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(fields), extrasaction=extra, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return atomic_write_text(path, buf.getvalue())



def missing_input(path: PathLike, what: str, kind: Literal["file", "folder"] = "file") -> InputFileError:
    """The one-line error for an input ``path`` that is not the ``kind`` asked for: that it is a folder
    where a file is wanted (or the other way round), else that it is not found. ``what`` names it
    ("checkpoint", "ground-truth folder", ...)."""
    path = Path(path)
    if kind == "file" and path.is_dir():
        return InputFileError(f"{what} {path} is a folder; name a file")
    if kind == "folder" and path.exists():
        return InputFileError(f"{what} {path} is a file; give a folder")
    return InputFileError(f"{what} not found: {path}")


def read_bytes(path: PathLike, what: str) -> bytes:
    """The bytes of the input file ``path``; ``what`` names it in the one-line error (InputFileError) for a
    missing, folder or unreadable path."""
    path = Path(path)
    if not path.is_file():
        hint = "it is a folder, name a file" if path.is_dir() else "check the path"
        raise InputFileError(f"{what} not found: {path} ({hint})")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputFileError(f"cannot read {what} {path}: {exc.strerror}") from None


