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
  by :func:`check_writable` and :func:`freespace.io.outdir.claim_folder`, as the package itself writes there);
* an existing regular file that the running command did not write is never replaced. Every file the writers
  here (and :class:`freespace.io.video.VideoWriter`) put in place carries a mark, the extended attribute
  :data:`MARK` naming the command that wrote it (:func:`writing_as`); a file output checked by
  :func:`check_writable` is replaced only when it carries the running command's mark (a symbolic link is
  replaced as a link: the file it leads to is never written). Files in output folders follow their
  manifest instead (:mod:`freespace.io.outdir`);
* its suffix fits what is written: a file output ends in one of the suffixes its command writes (``.onnx``,
  ``.mp4``, …), never in ``/``; an output folder's name does not end in a file's suffix
  (:data:`FILE_SUFFIXES`: ``out.png`` or ``out.mp4`` is no folder).
"""

from __future__ import annotations

import csv
import errno
import io as _io
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, OutputError, param
from freespace.runtime.signals import signals_held

PathLike = str | os.PathLike[str]

__all__ = ["PathLike", "atomic_write_bytes", "write_files_together", "atomic_write_text", "encode_json", "write_json",
           "write_csv", "check_outputs", "check_writable", "check_output_kind", "check_writable_files", "missing_input",
           "read_bytes", "replaceable", "keep_mode", "special_kind", "inside_meta", "on_pseudo_fs", "unfollowable_link",
           "META", "MARK", "FILE_SUFFIXES", "writing_as", "mark_written", "check_suffix", "shown_path", "unicode_name"]

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
#: the extended attribute that marks a file freespace wrote: the name of the command that wrote it
MARK = "user.freespace"
#: the mark of a file written through the Python API, outside a command
_API = "api"
#: the running command (:func:`writing_as`), for every thread of the process
_COMMAND = [_API]
#: the file outputs checked by :func:`check_writable` (absolute paths): replaced only when the command wrote them
_FILE_OUTPUTS: set[str] = set()
#: suffixes of files (images, videos, models, tables, archives): no output folder is named with one
FILE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".pfm", ".webp",
                           ".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".json", ".csv", ".txt", ".yaml", ".yml",
                           ".onnx", ".pt", ".pth", ".ckpt", ".zip", ".npy", ".npz", ".pdf", ".svg"})


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
            that cannot be followed (a loop), a file its mode makes read-only, a file output
            (:func:`check_writable`) that the running command did not write, or lies where no output
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
    if st is not None and os.path.abspath(path) in _FILE_OUTPUTS:
        _refuse_foreign(path, what)
    return st


@contextmanager
def writing_as(command: str) -> Iterator[None]:
    """Mark the files written in the block (by any thread) as written by ``command`` (e.g. ``"export"``;
    :data:`MARK`), and replace a file output only when ``command`` wrote it."""
    _COMMAND.append(command)
    try:
        yield
    finally:
        _COMMAND.pop()


def mark_written(tmp: PathLike) -> None:
    """Mark the new file ``tmp`` (before it is renamed into place) as written by the running command
    (:data:`MARK`). A file system that keeps no extended attributes keeps no mark: the file is then not
    known as freespace's, and a later run refuses to replace it (:func:`replaceable`)."""
    try:
        os.setxattr(tmp, MARK, _COMMAND[-1].encode("utf-8"))
    except (OSError, AttributeError):  # (AttributeError: a platform without extended attributes)
        pass


def _who(command: str) -> str:
    return "freespace's Python API" if command == _API else f"freespace {command}"


def _refuse_foreign(path: Path, what: str) -> None:
    """Refuse the existing regular file ``path`` (a file output) unless the running command wrote it (its
    :data:`MARK`); a symbolic link is replaced as a link, so it passes."""
    if path.is_symlink() or not path.is_file():
        return
    command = _COMMAND[-1]
    try:
        mark: str | None = os.getxattr(path, MARK).decode("utf-8", "replace")
        why = f"it is the output of {_who(mark)}"
    except (OSError, AttributeError) as exc:  # ENODATA: no mark
        mark = None
        why = ("this file system keeps no extended attributes, where freespace marks its files"
               if getattr(exc, "errno", errno.ENOTSUP) in (errno.ENOTSUP, errno.EOPNOTSUPP)
               else "it carries no mark of a freespace output")
    if mark != command:
        raise OutputError(f"{what} {path} is a file that {_who(command)} did not write ({why}); freespace never "
                          f"replaces such a file: move it away or choose another path")


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
    file that replaces one keeps its mode. The renames run with SIGINT, SIGTERM and SIGHUP held back
    (:func:`freespace.runtime.signals.signals_held`), so a signal never leaves some targets new and others old.
    Returns the paths written.
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
                mark_written(tmp)
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
        with signals_held():  # every target or none: SIGINT/SIGTERM/SIGHUP wait for the renames
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
    return atomic_write_bytes(path, shown_path(text).encode("utf-8"))  # file names of any bytes: valid UTF-8


def encode_json(obj: Any) -> bytes:
    """``obj`` as the bytes of an indented UTF-8 JSON file (NaN/inf are rejected: use None); its strings as
    :func:`shown_path` shows them (a file name of bytes that are not UTF-8 holds no lone surrogate, which strict
    JSON readers refuse)."""
    return (json.dumps(_shown_strings(obj), indent=2, allow_nan=False) + "\n").encode("utf-8")


def _shown_strings(obj: Any) -> Any:
    """``obj`` with every string in it (keys too, at any depth of dicts, lists and tuples) as :func:`shown_path`
    shows it."""
    if isinstance(obj, str):
        return shown_path(obj)
    if isinstance(obj, dict):
        return {shown_path(k) if isinstance(k, str) else k: _shown_strings(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_shown_strings(v) for v in obj]
    return obj


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


def check_suffix(path: PathLike, suffixes: Sequence[str], name: str = "out") -> None:
    """Refuse a file output ``path`` that does not end in one of ``suffixes`` (lower case, with the dot: the
    kinds of file the command writes there), before any work: :class:`InvalidOptionError`."""
    if Path(path).suffix.lower() not in suffixes:
        raise InvalidOptionError(f"{param(name)} {path} must end in {' or '.join(suffixes)}, the kind of file written "
                                 f"there; rename it")


def _check_name(text: str, path: Path, flag: str, folder: bool) -> None:
    """Refuse an output whose name does not fit a file or a folder: a file named ``…/``, a folder ending in a
    file's suffix (:data:`FILE_SUFFIXES`)."""
    suffix = path.suffix.lower()
    if folder and suffix in FILE_SUFFIXES:
        raise InvalidOptionError(f"{flag} {path} is an output folder but ends in {suffix}, the suffix of a file; "
                                 f"name the folder without it")
    if not folder and text.endswith(("/", os.sep)):
        raise InvalidOptionError(f"{flag} {text} ends in /, which names a folder, but this output is a file; leave "
                                 f"out the /")


def check_writable(path: PathLike, name: str = "out", *, folder: bool = False) -> Path:
    """Refuse, before any work, an output that cannot be written where it is named.

    Args:
        path: the output file (``folder=False``) or folder (``folder=True``); it need not exist.
        name: the parameter that named it, for the message (:func:`freespace.errors.param`).

    Raises :class:`InvalidOptionError` when ``path`` is a folder where a file is wanted or a file where a
    folder is, is (or leads by a link to) a device, pipe, socket or other special file, lies inside a
    ``.freespace`` folder, or is a file named ``…/`` or a folder named like a file (``x.png``:
    :data:`FILE_SUFFIXES`; a file's own suffix is :func:`check_suffix`'s); :class:`OutputError` when a file
    output may not be replaced (:func:`replaceable`: read-only, on ``/proc``, …), a folder on the way to it
    is a file, or the nearest existing folder is not writable (folders on the way are created by the
    writers). Nothing is created. A file output is remembered, so that its writer refuses it when it exists
    and the running command did not write it (:func:`check_outputs` refuses that before any work, after the
    check that it is no input).
    """
    text = os.path.expanduser(os.fspath(path))
    path, flag = Path(text), param(name)
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
        _FILE_OUTPUTS.add(os.path.abspath(path))  # who wrote it: checked by check_outputs and by its writer
    elif (where := on_pseudo_fs(path, folder=True)) is not None:
        raise OutputError(f"{flag} {path} {where}")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {flag} {path}: no permission to write in {existing}; choose a writable "
                          f"folder")
    _check_name(text, path, flag, folder)
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
    folder that holds an input, when an input folder holds a symbolic link (a file or a folder, at any depth)
    that leads to an existing output or into it (the command would read the file, then replace it), or when
    two outputs are the same path. Symbolic links are resolved first, so a link to an input counts as the
    input. Then :class:`OutputError` for an output that is an existing regular file that the running command
    did not write.
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
    existing = {name: out for name, out in outs.items() if out.exists()}  # a new output holds no input yet
    for in_name, src in ins.items() if existing else ():
        found = _link_into(src, existing) if src.is_dir() else None
        if found is not None:
            out_name, link, target = found
            raise InvalidOptionError(f"the input {in_name} {src} holds {link.relative_to(src)}, a symbolic link to "
                                     f"{target} in {out_name} {existing[out_name]}, which the command would read, then "
                                     f"replace; choose another output path, or put a copy of the file in its place")
    seen: dict[Path, str] = {}
    for out_name, out in outs.items():
        if out in seen:
            raise InvalidOptionError(f"{out_name} and {seen[out]} are the same path {out}; give two paths")
        seen[out] = out_name
    for key, path in outputs.items():  # a regular file there is a file output (a folder output is no file)
        if path is not None:
            _refuse_foreign(Path(os.path.expanduser(os.fspath(path))), named(key))


def _link_into(folder: Path, outputs: Mapping[str, Path]) -> tuple[str, Path, Path] | None:
    """The first symbolic link under ``folder`` (in name order, a folder's own links before its subfolders'; a link
    to a folder is not followed into) that leads to one of ``outputs`` (name → existing path, resolved) or into it:
    ``(name, link, where it leads)``, else None. Only links can: a file of the folder that is no link lies outside
    every output (checked before)."""
    stack = [folder]
    while stack:
        try:
            with os.scandir(stack.pop()) as items:
                entries = sorted(items, key=lambda e: e.name)
        except OSError:
            continue  # an unreadable folder: its files are not read either
        below = []
        for entry in entries:
            if entry.is_symlink():
                target = Path(os.path.realpath(entry.path))
                name = next((n for n, out in outputs.items() if target.is_relative_to(out)), None)
                if name is not None:
                    return name, Path(entry.path), target
            elif entry.is_dir(follow_symlinks=False):
                below.append(Path(entry.path))
        stack.extend(reversed(below))
    return None


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


def read_bytes(path: PathLike, what: str, max_bytes: int | None = None, limit: str = "") -> bytes:
    """The bytes of the input file ``path``; ``what`` names it in the one-line error (InputFileError) for a
    missing, folder, special (:func:`missing_input`) or unreadable path.

    Args:
        max_bytes: the most bytes the file may have, checked before it is read (None: no limit); a larger file
            is refused (CorruptFileError) with ``limit``, the text that names the limit
            (``"MAX_IMAGE_FILE_BYTES (…)"``).
    """
    path = Path(path)
    if not path.is_file():
        raise missing_input(path, what, hint="check the path")
    try:
        with path.open("rb") as f:
            size = os.fstat(f.fileno()).st_size
            if max_bytes is None:
                data = f.read()
            else:  # not read at all when too large; at most one byte more when it grew since
                data = f.read(max_bytes + 1) if size <= max_bytes else b""
    except OSError as exc:
        raise InputFileError(f"cannot read {what} {path}: {exc.strerror}") from None
    if max_bytes is not None and max(size, len(data)) > max_bytes:
        raise CorruptFileError(f"{what} {path} has {max(size, len(data)):,} bytes, more than the "
                               f"{limit or f'{max_bytes:,} bytes'} read here; give a smaller file (or check it: a "
                               f"wrong file, or a crafted one?)")
    return data




def unicode_name(name: str) -> bool:
    """Whether ``name`` is valid Unicode: not a file name of bytes that are not UTF-8 (which Python holds as lone
    surrogates, and which libraries taking UTF-8 text cannot open)."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def shown_path(path: PathLike | bytes) -> str:
    """``path`` (or any file name) as a message, a printed line or a record writes it: itself when it is valid
    Unicode; else (a name of bytes that are not UTF-8, which Python holds as lone surrogates that no UTF-8 output
    can take: ``UnicodeEncodeError``) with each such byte written ``\\xNN`` (``b"fr\\xe9me.png"`` is shown
    ``fr\\xe9me.png``). For showing only: a file is opened, and an output named, by the path itself."""
    text = os.fsdecode(path) if isinstance(path, bytes) else os.fspath(path)
    if unicode_name(text):
        return text
    try:
        return os.fsencode(text).decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # surrogates that no file name decoded to
        return text.encode("utf-8", "backslashreplace").decode("utf-8")
