"""Files the package writes, and the rules for them: atomic writes (one file, or several all or nothing),
JSON and CSV, checks of output paths before any work, and the one-line errors for missing inputs.

Every writer writes to a temporary file beside the target and renames it, so a crash or a user mistake
never leaves a partial output file. Output folders follow :mod:`freespace.io.outdir`.

What an output path may be (:func:`check_writable` before any work, :func:`replaceable` again when the file
is written, so every writer follows it):

* a new path, or an existing **regular file** that may be written (its permission bits allow it); the new
  file keeps the replaced file's mode (and owner, where the process may set it); a new file gets
  ``0o666 & ~umask``;
* never a character or block device (``/dev/null``), a named pipe, a socket or another special file, nor a
  symbolic link to one: the rename would replace it with a regular file (as root, ``/dev/null`` itself);
* a symbolic link to a regular file is replaced by the new file (the file it leads to is not written);
* never a name in ``/proc``, ``/sys`` or ``/dev`` (``/dev/shm`` aside) or on another kernel's pseudo file
  system, wherever it leads (``/dev/stdout`` may lead to a regular file), nor a link that cannot be followed;
* never inside a ``.freespace`` folder (where an output folder keeps its manifest, lock and stages; checked
  by :func:`check_writable` and :func:`freespace.io.outdir.claim_folder`, as the package itself writes there).
"""

from __future__ import annotations

import csv
import io as _io
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from freespace.errors import InputFileError, InvalidOptionError, OutputError, param

PathLike = str | os.PathLike[str]

__all__ = ["PathLike", "atomic_write_bytes", "write_files_together", "atomic_write_text", "encode_json", "write_json",
           "write_csv", "check_outputs", "check_writable", "check_output_kind", "check_writable_files", "missing_input",
           "read_bytes", "replaceable", "keep_mode", "special_kind", "inside_meta", "on_pseudo_fs", "unfollowable_link",
           "META"]

# ---------------------------------------------------------------------------------------------------
# atomic writes

_UMASK = os.umask(0)
os.umask(_UMASK)

#: the hidden folder of an output folder (:mod:`freespace.io.outdir`): its manifest, lock and stages
META = ".freespace"
#: file systems a kernel makes up (no output file belongs there)
_PSEUDO_FS = frozenset({"proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "debugfs", "tracefs",
                        "securityfs", "pstore", "bpf", "configfs", "fusectl", "mqueue", "efivarfs", "binfmt_misc",
                        "selinuxfs", "hugetlbfs", "rpc_pipefs", "nsfs", "autofs"})
_FS_TYPES: dict[int, str] | None = None


def special_kind(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is when it is neither a regular file nor a folder ("a character
    device", "a named pipe (FIFO)", …), else None."""
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return ("a character device" if stat.S_ISCHR(mode) else "a block device" if stat.S_ISBLK(mode) else
            "a named pipe (FIFO)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else
            "a special file")


def _pseudo_fs(folder: Path) -> str | None:
    """The type of the kernel's pseudo file system (``"proc"``, ``"sysfs"``, …) that holds the existing
    ``folder``, or None (a real file system, or unknown: no ``/proc/self/mountinfo``)."""
    global _FS_TYPES
    if _FS_TYPES is None:
        types: dict[int, str] = {}
        try:
            for line in Path("/proc/self/mountinfo").read_text().splitlines():
                fields, _, rest = line.partition(" - ")
                major, _, minor = fields.split()[2].partition(":")
                types.setdefault(os.makedev(int(major), int(minor)), rest.split()[0])
        except (OSError, ValueError, IndexError):
            pass
        _FS_TYPES = types
    try:
        fs = _FS_TYPES.get(os.stat(folder).st_dev)
    except OSError:
        return None
    return fs if fs in _PSEUDO_FS else None


def on_pseudo_fs(path: PathLike, folder: bool = False) -> str | None:
    """Why no output may be written at ``path`` because it lies on a kernel's pseudo file system (``/proc``,
    ``/sys``, ``devtmpfs``, …), or None. For a file, the folder that holds its name is checked (a new file
    is made there and renamed onto the name, a link included); for a ``folder``, the folder itself (links
    followed), or the nearest existing folder above it."""
    path = Path(os.path.abspath(os.path.expanduser(os.fspath(path))))
    existing = Path(os.path.realpath(path if folder else path.parent))
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    fs = _pseudo_fs(existing)
    system = any(existing.is_relative_to(d) for d in ("/proc", "/sys", "/dev")) \
        and not existing.is_relative_to("/dev/shm")  # (a container's /dev may be a tmpfs: /dev/stdout a link there)
    if fs is None and not system:
        return None
    return (f"lies on the kernel's {fs or 'system'} file system ({existing}), where no output belongs; choose a path "
            f"on a disk")


def unfollowable_link(path: PathLike, folder: bool = False) -> str | None:
    """Why the output ``path`` cannot be used when it is a symbolic link that cannot be followed (a loop, one
    that leads into a missing folder, or, for an output ``folder``, one to a missing name): ``"is a symbolic
    link … ; …"``, else None. A file output's link to a missing name in an existing folder is fine: the new
    file replaces the link."""
    path = Path(path)
    if not path.is_symlink():
        return None
    try:
        os.stat(path)
        return None
    except FileNotFoundError:
        target = Path(os.path.realpath(path))
        if folder:
            return f"is a symbolic link to {target}, which does not exist; create it, or choose another path"
        if target.parent.is_dir():
            return None
        return (f"is a symbolic link to {target}, whose folder does not exist; create it or remove the link, or "
                f"choose another path")
    except OSError as exc:
        return f"is a symbolic link that cannot be followed ({exc.strerror}); remove it or choose another path"


def inside_meta(path: PathLike) -> Path | None:
    """The :data:`META` folder (an output folder's manifest, lock and stages) that ``path`` lies in or is,
    links resolved, or None."""
    real = Path(os.path.realpath(os.path.expanduser(os.fspath(path))))
    return Path(*real.parts[:real.parts.index(META) + 1]) if META in real.parts else None


def replaceable(path: PathLike, what: str = "output") -> os.stat_result | None:
    """Check that an output file may be written at ``path`` (see the module docstring): the ``os.stat`` of
    the existing regular file (a symbolic link followed) that the new file replaces, or None when there is
    none.

    Args:
        path: the output file.
        what: how messages name it (e.g. ``"output"``, or a parameter's flag such as ``param("out")``).

    Raises:
        OutputError: ``path`` is (or is a link to) a device, pipe, socket or other special file, a link
            that cannot be followed (a loop), a file its mode makes read-only, or lies where no output
            belongs.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        st = None  # a new file (a dangling link is replaced by it)
    except NotADirectoryError:
        raise OutputError(f"cannot write {what} {path}: a folder on the way to it is a file; choose another "
                          f"path") from None
    except OSError as exc:
        raise OutputError(f"cannot write {what} {path}: {exc.strerror}; choose another path") from None
    if st is not None:
        kind = special_kind(st.st_mode)
        if kind is not None:
            link = " (through a symbolic link)" if path.is_symlink() else ""
            raise OutputError(f"{what} {path} is {kind}{link}, not a regular file; freespace writes outputs as "
                              f"new files renamed into place and would replace it: choose a file path")
        if not stat.S_ISDIR(st.st_mode) and (not os.access(path, os.W_OK) or not st.st_mode & 0o222):
            raise OutputError(f"{what} {path} is read-only (mode {stat.S_IMODE(st.st_mode):04o}); make it writable "
                              f"(chmod u+w) to replace it, or choose another path")
    where = on_pseudo_fs(path)
    if where is not None:
        raise OutputError(f"{what} {path} {where}")
    return st


def keep_mode(tmp: PathLike, old: os.stat_result | None) -> None:
    """Give the new file ``tmp`` the mode of the file ``old`` it replaces (and its owner and group, where the
    process may set them), or ``0o666 & ~umask`` when it replaces none."""
    if old is None:
        os.chmod(tmp, 0o666 & ~_UMASK)
        return
    os.chmod(tmp, stat.S_IMODE(old.st_mode))
    if (old.st_uid, old.st_gid) != (os.getuid(), os.getgid()):
        try:
            os.chown(tmp, old.st_uid, old.st_gid)
        except OSError:
            pass  # only root may give a file away: the new file is then the writer's


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then ``os.replace``).

    Parent folders are created. Returns the path written.
    """
    return write_files_together({path: data})[0]


def write_files_together(files: Mapping[PathLike, bytes]) -> list[Path]:
    """Write several output files all or nothing: each goes to a temporary file beside its target, and
    only when every one is written are they renamed into place. When any write fails, the temporary
    files are removed and every earlier file at the targets is left as it was.

    Every target is checked first (:func:`replaceable`: no device, pipe or socket, no read-only file); a
    file that replaces one keeps its mode. Returns the paths written.
    """
    staged: list[tuple[str, Path]] = []
    targets = [Path(t) for t in files]
    old = [replaceable(t) for t in targets]  # before anything is written
    try:
        for target, data, before in zip(targets, files.values(), old):
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
            staged.append((tmp, target))
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(data)
                keep_mode(tmp, before)
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
        for tmp, target in staged:
            try:
                os.replace(tmp, target)
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose another output path") from None
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


def check_output_kind(path: Path, flag: str, folder: bool) -> None:
    """Refuse an output ``path`` (a folder with ``folder``, else a file) that is a link which cannot be followed,
    a device, pipe, socket or other special file (or a link to one), a file where a folder is wanted or a folder
    where a file is: :class:`InvalidOptionError`, one line that starts with ``flag`` (the parameter that named it)."""
    unfollowable = unfollowable_link(path, folder)
    if unfollowable is not None:
        raise InvalidOptionError(f"{flag} {path} {unfollowable}")
    try:
        kind = special_kind(os.stat(path).st_mode)
    except OSError:
        kind = None
    if kind is not None:
        link = " (through a symbolic link)" if path.is_symlink() else ""
        raise InvalidOptionError(f"{flag} {path} is {kind}{link}, not a {'folder' if folder else 'regular file'}; "
                                 f"freespace writes only regular files and folders: give a "
                                 f"{'folder' if folder else 'file'} path")
    if folder and path.exists() and not path.is_dir():
        raise InvalidOptionError(f"{flag} {path} is a file; give a folder")
    if not folder and path.is_dir():
        raise InvalidOptionError(f"{flag} {path} is a folder; give a file name")


def check_writable(path: PathLike, name: str = "out", *, folder: bool = False) -> Path:
    """Refuse, before any work, an output that cannot be written where it is named.

    Args:
        path: the output file (``folder=False``) or folder (``folder=True``); it need not exist.
        name: the parameter that named it, for the message (:func:`freespace.errors.param`).

    Raises :class:`InvalidOptionError` when ``path`` is a folder where a file is wanted or a file where a
    folder is, is (or leads by a link to) a device, pipe, socket or other special file, or lies inside a
    ``.freespace`` folder; :class:`OutputError` when a file output may not be replaced
    (:func:`replaceable`: read-only, on ``/proc``, …), a folder on the way to it is a file, or the nearest
    existing folder is not writable (folders on the way are created by the writers). Nothing is created.
    """
    path, flag = Path(os.path.expanduser(os.fspath(path))), param(name)
    check_output_kind(path, flag, folder)
    meta = inside_meta(path)
    if meta is not None:
        raise InvalidOptionError(f"{flag} {path} lies inside {meta}, where freespace keeps an output folder's "
                                 f"manifest, lock and stages (replaced and deleted by its next run); choose a path "
                                 f"outside it")
    existing = path.absolute().parent
    while not existing.exists() and not existing.is_symlink() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        try:
            what = f"is {special_kind(os.stat(existing).st_mode) or 'a file'}, not a folder; choose another path"
        except OSError:
            what = unfollowable_link(existing, folder=True) or "is no folder; choose another path"
        raise OutputError(f"cannot write {flag} {path}: {existing} {what}")
    if not folder:
        replaceable(path, flag)
    elif (where := on_pseudo_fs(path, folder=True)) is not None:
        raise OutputError(f"{flag} {path} {where}")
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



def missing_input(path: PathLike, what: str, kind: Literal["file", "folder"] = "file",
                  hint: str = "") -> InputFileError:
    """The one-line error for an input ``path`` that is not the ``kind`` asked for, naming what it is: a
    folder where a file is wanted (or the other way round), something that is neither (a named pipe, a socket,
    a device: never opened, a pipe would block), else that it is not found (``hint``, when given, in brackets
    after it). ``what`` names it ("checkpoint", "ground-truth folder", ...)."""
    path = Path(path)
    want = "name a file" if kind == "file" else "give a folder"
    if kind == "file" and path.is_dir():
        return InputFileError(f"{what} {path} is a folder; {want}")
    if kind == "folder" and path.is_file():
        return InputFileError(f"{what} {path} is a file; {want}")
    if path.exists() and not path.is_dir():
        return InputFileError(f"{what} {path} is {special_kind(path.stat().st_mode)}, not a regular file or folder; "
                              f"{want}")
    return InputFileError(f"{what} not found: {path}" + (f" ({hint})" if hint else ""))


def read_bytes(path: PathLike, what: str) -> bytes:
    """The bytes of the input file ``path``; ``what`` names it in the one-line error (InputFileError) for a
    missing, folder, special (:func:`missing_input`) or unreadable path."""
    path = Path(path)
    if not path.is_file():
        raise missing_input(path, what, hint="check the path")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputFileError(f"cannot read {what} {path}: {exc.strerror}") from None


