"""Output folders: one rule for every command that writes a folder.

A command owns an output folder through a **manifest**, ``OUT/.freespace/manifest.json``: the command's
name and every entry it wrote (``"name"`` a file, ``"name/"`` a whole subtree, e.g. a training run's
``checkpoints/``). The rule:

* a command writes into a new or empty folder, or into a folder whose manifest names that command;
* it refuses a folder that holds any file its manifest does not list (the message names one);
* it replaces or deletes only entries of its manifest, ``overwrite`` included, so a file it did not
  write is never touched;
* a lock (``OUT/.freespace/lock``, ``flock``) keeps two runs out of one folder: a whole run takes it
  alone, the shards of one run (:mod:`freespace.runtime.shard`) and the cells of one ``reproduce`` share it;
* staged output (:meth:`OwnedFolder.staged`) is written under ``OUT/.freespace/stage-<pid>-…`` and moved
  into place file by file (one atomic rename each) when the block ends, SIGINT, SIGTERM and SIGHUP held back
  until the last file is in place (all or nothing); an interrupted stage (a signal before the move, or
  SIGKILL, which cannot be held back) is removed by the next run that claims the folder.

Entries are confined to the folder. A manifest entry must be a relative POSIX path of plain names (no
``..``, ``.``, empty or absolute path, nor one inside ``.freespace``); a manifest that lists another is
refused in one line (it was edited by hand or crafted), never followed. A file entry (``"name"``) covers a
file (or link) only, never a folder of that name; entries are deleted or written only where their parent
folder lies inside the output folder (a symbolic link inside it that leads out is refused), and a link is
deleted as a link, never followed. ``.freespace`` must be a real folder, not a link. An output folder that
lies inside a ``"dir/"`` entry of another command's output folder (which that command may replace) is
refused, unless the command writing that enclosing folder is this very run (``demo`` writes its
``dataset/`` with ``synth``, ``reproduce`` its ``runs/`` with ``train``). Temporary files that a killed
atomic write leaves beside an entry (``.NAME.XXXXXXXX.tmp``) count as the command's and are removed by the
next run that holds the folder alone.

Nested output folders: a folder inside the output folder that holds its own manifest is another command's
output folder (``freespace evaluate --out RUN/eval`` in a training run). It does not block the command, which never
replaces or deletes anything in it; one that stands where the command is about to write (at an entry it
has not written yet, on the way to a file entry, or where a staged file would land) is refused. No output
folder may lie inside a ``.freespace`` folder. A device, pipe, socket or other special file (or a link to
one) anywhere in the folder is refused, as is a manifest that cannot be read (never opened when it is a
pipe): the message says so and how to fix it. Files follow :func:`freespace.io.files.replaceable` (no
special file, no read-only file; a replaced file keeps its mode).

The folder itself is never renamed or replaced, so an output folder that is a symbolic link stays one, and
``.`` works. Files are listed in the manifest **before** they are written (in place or by a
stage), so a run killed half-way leaves only files that its next run knows.

Also here: :func:`freespace.io.files.write_files_together` (several output files written all or nothing, earlier
files kept when it fails). Only the standard library is imported (and :mod:`freespace.runtime.signals`).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from freespace.errors import CorruptFileError, InvalidOptionError, OutputError, param
from freespace.io.files import (
    META,
    check_output_kind,
    inside_meta,
    keep_mode,
    on_pseudo_fs,
    replaceable,
    special_kind,
    write_files_together,
)
from freespace.runtime.signals import signals_held

PathLike = str | os.PathLike[str]

#: the parameters an output folder's messages name
OUT, OVERWRITE = param("out"), param("overwrite")
MANIFEST = "manifest.json"
_LOCK = "lock"
_STAGE = "stage-"
#: what a killed atomic write (:func:`freespace.io.files.write_files_together`: a :func:`tempfile.mkstemp` file)
#: leaves beside its target NAME
_TEMP = re.compile(r"\.(.+)\.[a-z0-9_]{8}\.tmp")
#: folders (resolved) that this process holds now: a folder claimed inside one of them is its own nesting
_HELD: dict[Path, int] = {}

__all__ = ["OwnedFolder", "claim_folder", "check_settings", "META"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _valid_entry(entry: str) -> bool:
    """Whether ``entry`` is a manifest entry: plain names joined by ``/`` (``"dir/"`` a subtree), no ``..``,
    ``.``, empty or absolute path, and not inside :data:`META`."""
    parts = (entry[:-1] if entry.endswith("/") else entry).split("/")
    return "\0" not in entry and parts[0] != META and all(p not in ("", ".", "..") for p in parts)


def _written_by_a_killed_write(rel: str) -> str | None:
    """The path whose atomic write left ``rel`` (a POSIX path relative to the folder) when it was killed,
    or None when ``rel`` is no such temporary file."""
    head, _, name = rel.rpartition("/")
    temp = _TEMP.fullmatch(name)
    return None if temp is None else (head + "/" if head else "") + temp.group(1)


def _known(rel: str, entries: set[str]) -> bool:
    """Whether ``rel`` (a POSIX path relative to the folder) is an entry or lies in a ``"dir/"`` entry;
    a ``"dir/"`` path (a folder) is covered by ``"dir/"`` entries only, and so is a temporary file that a
    killed atomic write left beside an entry."""
    if rel in entries:
        return True
    if _written_by_a_killed_write(rel) in entries:
        return True
    parts = rel.split("/")
    return any("/".join(parts[:i]) + "/" in entries for i in range(1, len(parts)))


class OwnedFolder:
    """An output folder claimed by one command (see the module docstring); made by :func:`claim_folder`.

    Attributes:
        path: the folder (as given; a symbolic link stays one).
        command: the command that owns it (e.g. ``"predict"``).
    """

    def __init__(self, path: Path, command: str, name: str) -> None:
        self.path, self.command, self.flag = path, command, param(name)
        self._meta = path / META

    # -- the manifest -----------------------------------------------------------------------------

    def entries(self) -> set[str]:
        """The entries of the manifest (``"name"`` files, ``"name/"`` subtrees), empty when there is none."""
        return set(_read_manifest(self._meta / MANIFEST)[1])

    def record(self, entries: Iterable[str]) -> None:
        """Add ``entries`` (POSIX paths relative to the folder; ``"dir/"`` for a whole subtree) to the
        manifest, before they are written."""
        added = {str(e) for e in entries}
        bad = next((e for e in sorted(added) if not _valid_entry(e)), None)
        if bad is not None:
            raise ValueError(f"{bad!r} is no entry of an output folder (a relative path of plain names)")
        with _exclusive(self._meta / "manifest.lock"):
            old = self.entries()
            new = old | added
            if new != old:
                _write_manifest(self._meta / MANIFEST, self.command, new)

    def forget(self, entries: Iterable[str]) -> None:
        """Delete ``entries`` (each must be in the manifest: a file or a ``"dir/"`` subtree) and drop them
        from the manifest."""
        with _exclusive(self._meta / "manifest.lock"):
            known = self.entries()
            gone = {str(e) for e in entries}
            for entry in sorted(gone):
                if entry not in known:
                    raise ValueError(f"{entry!r} is not in the manifest of {self.path}")
                target = self._inside(entry.rstrip("/"))
                if target.is_dir() and not target.is_symlink():
                    if not entry.endswith("/"):
                        raise self._clash(entry)
                    shutil.rmtree(target)
                else:
                    target.unlink(missing_ok=True)  # a link is removed as a link, never followed
            _write_manifest(self._meta / MANIFEST, self.command, known - gone)

    @contextmanager
    def alone(self) -> Iterator[None]:
        """Keep the other runs that share the folder (the shards of one run) out of the block: e.g. to check a
        record of what made the folder and write it when there is none, as one step."""
        with _exclusive(self._meta / "record.lock"):
            yield

    def _inside(self, rel: str) -> Path:
        """``self.path / rel``, after checking that its parent folder lies inside the folder (no symbolic
        link on the way leads out of it)."""
        target = self.path / rel
        if not target.parent.resolve().is_relative_to(self.path.resolve()):
            raise OutputError(f"{self.flag} {self.path}: {rel} lies outside it through a symbolic link; remove that "
                              f"link or choose another {self.flag}")
        return target

    def _not_in_a_nested_folder(self, rel: str) -> None:
        """Refuse ``rel`` when a folder on its way inside the folder is the output folder of a command (it
        holds a :data:`META` folder): that command's files are never written over."""
        parts = rel.split("/")[:-1]
        for i in range(1, len(parts) + 1):
            sub = "/".join(parts[:i])
            if (self.path / sub / META).is_dir():
                raise OutputError(f"{self.flag} {self.path}: freespace {self.command} would write {rel} inside {sub}/, "
                                  f"the output folder of another freespace command; move {sub}/ away or choose "
                                  f"another {self.flag}")

    def _clash(self, rel: str) -> OutputError:
        return OutputError(f"{self.flag} {self.path} has a folder {rel} where freespace {self.command} writes a "
                           f"file; move it away or choose another {self.flag}")

    # -- staged output --------------------------------------------------------------------------------

    @contextmanager
    def staged(self, *, replace: bool = True) -> Iterator[Path]:
        """A temporary folder to write the command's output into, moved into place when the block ends.

        Args:
            replace: True: the output replaces this command's earlier output (entries of the manifest
                that the stage did not write are deleted); False: it is added beside it (shards).

        When the block raises (or is interrupted), the stage is removed and the folder is left as it
        was. Files are moved one atomic rename each, ``.json`` files last (a summary appears once the
        files it describes are in place), with ``SIGINT``, ``SIGTERM`` and ``SIGHUP`` held back until the last
        is in place (:func:`freespace.runtime.signals.signals_held`; the signal then ends the command): every
        file of the stage or none, never some. ``SIGKILL`` cannot be held back: a run killed during the move
        leaves files its manifest lists (the next run replaces them) and its stage (the next run removes it).
        """
        try:
            stage = Path(tempfile.mkdtemp(dir=self._meta, prefix=f"{_STAGE}{os.getpid()}-"))
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror}; choose a writable output folder") from None
        try:
            yield stage
            files = sorted((p for p in stage.rglob("*") if p.is_file() or p.is_symlink()),
                           key=lambda p: (p.suffix == ".json", str(p)))
            written = {p.relative_to(stage).as_posix() for p in files}
            stale = self.entries() - written if replace else set()
            stale = {e for e in stale if not any(w.startswith(e) for w in written if e.endswith("/"))}
            targets = {w: self._inside(w) for w in sorted(written)}
            clash = next((w for w, t in targets.items() if t.is_dir() and not t.is_symlink()), None)
            if clash is not None:
                raise self._clash(clash)
            for w in targets:
                self._not_in_a_nested_folder(w)
            old = {w: replaceable(t, f"{self.flag} {self.path}: the output file") for w, t in targets.items()}
            with signals_held():  # all the files, or (a signal before) none: SIGINT/SIGTERM/SIGHUP wait for the move
                self.record(written)
                for path in files:
                    rel = path.relative_to(stage).as_posix()
                    _move(path, targets[rel], old[rel])
                if stale:
                    self.forget(stale)
        finally:
            shutil.rmtree(stage, ignore_errors=True)


def _move(path: Path, target: Path, old: os.stat_result | None) -> None:
    """Move the staged file ``path`` onto ``target`` in one rename, with the mode of ``old``, the file it replaces
    (a link keeps its own)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_symlink():
        keep_mode(path, old)
    os.replace(path, target)


def _read_manifest(path: Path) -> tuple[str | None, list[str]]:
    """``(command, entries)`` of a manifest file, ``(None, [])`` when there is none.

    Raises:
        CorruptFileError: it is unreadable (not a regular file, not JSON, not the manifest freespace writes),
            or lists an entry that is no path inside the folder (see :func:`_valid_entry`).
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None, []
    except OSError as exc:
        raise _unreadable(path, exc.strerror) from None
    kind = "a folder" if stat.S_ISDIR(st.st_mode) else special_kind(st.st_mode)
    if kind is not None:  # never opened: a named pipe would block the reader
        raise _unreadable(path, f"it is {kind}")
    try:
        data = json.loads(path.read_text())
        command, entries = data["command"], data["entries"]
    except OSError as exc:
        raise _unreadable(path, exc.strerror) from None
    except (ValueError, KeyError, TypeError):
        raise _unreadable(path, "not the JSON manifest freespace writes") from None
    if not (isinstance(command, str) and isinstance(entries, list) and all(isinstance(e, str) for e in entries)):
        raise _unreadable(path, "not the JSON manifest freespace writes")
    bad = next((e for e in entries if not _valid_entry(e)), None)
    if bad is not None:
        raise CorruptFileError(f"{path} lists {bad!r}, which is no path inside its folder (edited by hand?); "
                               f"freespace follows no such entry: remove it from the manifest")
    return command, entries


def _unreadable(path: Path, why: str) -> CorruptFileError:
    """The error for the unreadable manifest ``path`` (``OUT/.freespace/manifest.json``)."""
    folder = path.parent.parent
    return CorruptFileError(f"the output folder {folder} has an unreadable manifest {path} ({why}), so which of its "
                            f"files freespace wrote is unknown and none is touched; choose another output folder, or "
                            f"empty {folder} (its {META} included) to write it anew")


def _write_manifest(path: Path, command: str, entries: set[str]) -> None:
    text = json.dumps({"command": command, "entries": sorted(entries)}, indent=1) + "\n"
    write_files_together({path: text.encode("utf-8")})


@contextmanager
def _exclusive(path: Path) -> Iterator[None]:
    fd = _open_lock(path)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _open_lock(path: Path) -> int:
    """A file descriptor of the lock file ``path`` (created if missing; a symbolic link is refused, so a
    planted link never makes a file elsewhere)."""
    try:
        kind = special_kind(os.lstat(path).st_mode)
    except OSError:
        kind = None
    if kind is not None:  # never opened: a named pipe or a device is no lock
        raise OutputError(f"{path} is {kind}, not the lock file freespace writes; remove it or choose another "
                          f"output folder")
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o666 & ~_umask())
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror}; remove it or choose another output folder") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OutputError(f"{path} is no regular file, not the lock file freespace writes; remove it or choose "
                          f"another output folder")
    return fd


def _enclosing(out: Path) -> tuple[Path, str, str] | None:
    """The nearest folder above ``out`` whose manifest has ``out`` inside one of its entries and that this
    process does not hold: ``(folder, its command, the entry)``, or None."""
    real = out.resolve()
    for folder in real.parents:
        try:
            owner, entries = _read_manifest(folder / META / MANIFEST)
        except CorruptFileError:
            continue
        rel = real.relative_to(folder).as_posix()
        entry = next((e for e in sorted(entries) if rel == e.rstrip("/") or rel.startswith(e) and e.endswith("/")),
                     None)
        if owner is not None and entry is not None:
            return None if folder in _HELD else (folder, owner, entry)
    return None


def _check_contents(out: Path, entries: set[str], writes: set[str], command: str, flag: str) -> None:
    """Refuse ``out`` when it holds something ``command`` may not replace (sorted, depth first): a file
    that ``entries`` (its manifest) does not cover (named; empty folders hold nothing), a device, pipe,
    socket or other special file anywhere (inside ``"dir/"`` entries too; a link to one counts), or a nested
    output folder (a folder with a :data:`META` manifest) where the command is about to write: at one of
    ``writes`` that it has not written yet, or on the way to a file entry. A nested output folder at or in
    one of its ``"dir/"`` entries is its own (``demo`` writes ``dataset/`` with ``synth``, ``reproduce``
    ``runs/*`` with ``train``); any other is another command's, never touched, and left out of the check."""
    def nested(rel: str) -> str | None:  # the command that owns out/rel, or None
        meta = out / rel / META
        if meta.is_symlink() or not meta.is_dir():
            return None
        try:
            owner, _ = _read_manifest(meta / MANIFEST)
        except CorruptFileError:
            raise InvalidOptionError(f"{flag} {out} holds {rel}/, an output folder of freespace with an unreadable "
                                     f"manifest, so what it holds is unknown; move {rel}/ away, or empty it (its "
                                     f"{META} included)") from None
        return owner

    stack = [""]
    while stack:
        prefix = stack.pop()
        try:
            items = sorted(os.scandir(out / prefix) if prefix else os.scandir(out), key=lambda e: e.name)
        except OSError as exc:
            raise OutputError(f"cannot read {flag} {out / prefix}: {exc.strerror}; choose another {flag}") from None
        owned = bool(prefix) and _known(prefix, entries)  # inside a "dir/" entry: the command's
        below: list[str] = []
        for item in items:
            rel = prefix + item.name
            if not prefix and item.name == META:
                continue
            if item.is_dir(follow_symlinks=False):
                owner = nested(rel)
                if owner is None:
                    below.append(rel + "/")
                    continue
                if owned or _known(rel + "/", entries):
                    continue  # at or in a "dir/" entry it wrote: its own, made by another command (demo's dataset/)
                if any(rel == e.rstrip("/") or e.startswith(rel + "/") for e in entries | writes):
                    raise InvalidOptionError(f"{flag} {out} holds {rel}/, the output folder of freespace {owner}, "
                                             f"where freespace {command} writes its own files; move it away or choose "
                                             f"another {flag}")
                continue  # another command's output folder: never touched
            mode = stat.S_IFREG  # from the folder listing: no stat for a regular file
            if not item.is_file(follow_symlinks=False):
                try:
                    mode = item.stat(follow_symlinks=item.is_symlink()).st_mode
                except OSError:
                    mode = stat.S_IFLNK  # a dangling link
            kind = special_kind(mode) if not stat.S_ISLNK(mode) else None
            if kind is not None:
                link = " through a symbolic link" if item.is_symlink() else ""
                raise InvalidOptionError(f"{flag} {out} holds {rel}, {kind}{link}, which freespace {command} did not "
                                         f"write and never replaces; move it away or choose another {flag}")
            if stat.S_ISDIR(mode):  # a link to a folder: covered as a file or a "dir/" entry, or empty
                if owned or _known(rel, entries) or _known(rel + "/", entries) or not any(os.scandir(item.path)) \
                        or any(e.startswith(rel + "/") for e in entries):  # entries behind it: see _inside
                    continue
                raise InvalidOptionError(f"{flag} {out} holds {rel}/ (a link to a folder), which freespace {command} "
                                         f"did not write; choose a new or empty folder, or move it away")
            if not owned and not _known(rel, entries):
                raise InvalidOptionError(f"{flag} {out} holds {rel}, which freespace {command} did not write; choose "
                                         f"a new or empty folder, or move that file away")
        stack.extend(reversed(below))  # depth first, in name order


@contextmanager
def claim_folder(out: PathLike, command: str, *, entries: Iterable[str] = (), shared: bool = False,
                 name: str = "out") -> Iterator[OwnedFolder]:
    """Claim ``out`` for ``command`` for the length of the block (see the module docstring).

    Args:
        out: the output folder (created if missing, with its parents).
        command: the command's name (``"predict"``, ``"train"``, …): only the same command may write
            into a folder it wrote before.
        entries: entries the command writes in place (``"name"`` files, ``"name/"`` subtrees), recorded
            in the manifest at once (before they are written).
        shared: share the lock with other runs of ``command`` that pass ``shared`` (the shards of one
            run); otherwise the run holds the folder alone.
        name: the parameter that named the folder, for messages (:func:`freespace.errors.param`).

    Raises:
        InvalidOptionError: ``out`` is a file, holds a file that the command did not write (named), was
            written by another command, or another run holds it.
        OutputError: it cannot be created or written.
    """
    out, flag = Path(out), param(name)
    check_output_kind(out, flag, folder=True)
    meta_above = inside_meta(out)
    if meta_above is not None:
        raise InvalidOptionError(f"{flag} {out} lies inside {meta_above}, where freespace keeps an output folder's "
                                 f"manifest, lock and stages (replaced and deleted by its next run); choose a folder "
                                 f"outside it")
    pseudo = on_pseudo_fs(out, folder=True)
    if pseudo is not None:
        raise OutputError(f"{flag} {out} {pseudo}")
    meta = out / META
    if meta.is_symlink() or (meta.exists() and not meta.is_dir()):
        raise InvalidOptionError(f"{flag} {out} holds {META}, which is not a folder but a link or a file; "
                                 f"freespace keeps its manifest there: move it away or choose another {flag}")
    enclosing = _enclosing(out)
    if enclosing is not None:
        raise InvalidOptionError(f"{flag} {out} lies inside {enclosing[2]} of {enclosing[0]}, "
                                 f"the output of freespace {enclosing[1]}, which replaces it; choose a folder "
                                 f"outside it")
    owner, known = _read_manifest(meta / MANIFEST)
    if out.is_dir():
        if owner is not None and owner != command:
            raise InvalidOptionError(f"{flag} {out} holds the output of freespace {owner}; choose another {flag} for "
                                     f"freespace {command}")
        _check_contents(out, set(known), {str(e) for e in entries}, command, flag)
    existing = out
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent  # the folders below it are created here, and removed if left empty
    try:
        meta.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror}; choose a writable output folder") from None
    fd = _open_lock(meta / _LOCK)
    held = out.resolve()
    try:
        try:
            fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                raise
            raise InvalidOptionError(f"another freespace run is writing to {flag} {out}; wait for it to end or "
                                     f"choose another {flag}") from None
        owner, known = _read_manifest(meta / MANIFEST)  # as it is now that the lock is held
        if owner is not None and owner != command:
            raise InvalidOptionError(f"{flag} {out} holds the output of freespace {owner}; choose another {flag}")
        _remove_stale_stages(meta, alone=not shared)
        if not shared:
            _remove_killed_writes(out, set(known))
        folder = OwnedFolder(out, command, name)
        if owner is None:
            _write_manifest(meta / MANIFEST, command, set(known))
        folder.record(entries)
        _HELD[held] = _HELD.get(held, 0) + 1
        try:
            yield folder
        finally:
            _HELD[held] -= 1
            if not _HELD[held]:
                del _HELD[held]
    finally:
        _leave(out, existing, fd)


def _leave(out: Path, existing: Path, fd: int) -> None:
    """Release the lock of ``out``; a folder that holds nothing but the manifest (a run that wrote no
    file) is left as it was found: the manifest removed, and the folders created for it too."""
    try:
        if any(p.name != META for p in out.iterdir()):
            return
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # no other shard is in the folder
        shutil.rmtree(out / META, ignore_errors=True)  # under the lock: a run that claims it next starts anew
    except OSError:
        return
    finally:
        os.close(fd)
    folder = out
    while folder != existing and folder != folder.parent:
        try:
            folder.rmdir()
        except OSError:
            break
        folder = folder.parent


def _remove_stale_stages(meta: Path, alone: bool) -> None:
    """Remove the stages of interrupted runs: all of them when this run holds the folder alone, else
    those whose process is gone."""
    for stage in meta.glob(f"{_STAGE}*"):
        pid = stage.name[len(_STAGE):].partition("-")[0]
        if stage.is_symlink():
            stage.unlink()  # never one of ours: removed as a link, never followed
        elif alone or not (pid.isdigit() and _pid_alive(int(pid))):
            shutil.rmtree(stage, ignore_errors=True)


def _remove_killed_writes(out: Path, entries: set[str]) -> None:
    """Remove the temporary files that killed atomic writes left beside the entries (files directly in
    the folder or in folders the entries name; not inside ``"dir/"`` subtrees, whose writers clean up)."""
    folders = {""} | {e.rpartition("/")[0] for e in entries if not e.endswith("/") and "/" in e}
    for rel in sorted(folders):
        folder = out / rel
        if not folder.is_dir() or not folder.resolve().is_relative_to(out.resolve()):
            continue
        for path in folder.iterdir():
            if _written_by_a_killed_write(f"{rel}/{path.name}" if rel else path.name) in entries \
                    and not path.is_dir():
                path.unlink(missing_ok=True)


def check_settings(path: Path, settings: dict[str, Any], overwrite: bool, what: str,
                   recorded_as: Callable[[dict[str, Any]], dict[str, Any]] = lambda d: d) -> None:
    """Refuse an output whose recorded settings (the JSON file ``path``) differ from ``settings``, unless
    ``overwrite``; an output with no record yet passes. ``recorded_as`` turns the file's content into the
    keys of ``settings`` (e.g. filling keys an older version did not write); ``what`` says what the folder
    holds, for the message ("frames generated", "a dataset rendered").

    Raises:
        InvalidOptionError: the settings differ (each change named, old → new) or the record is unreadable.
    """
    try:
        recorded = json.loads(path.read_text())
    except FileNotFoundError:
        return
    except (OSError, ValueError):
        recorded = None
    if overwrite:
        return
    if not isinstance(recorded, dict):
        raise InvalidOptionError(f"{OUT} {path.parent} has an unreadable {path.name}, so the settings of what it "
                                 f"holds are unknown; add {OVERWRITE} to make it again, or choose another {OUT}")
    old = recorded_as(recorded)
    differ = [k for k in settings if old.get(k) != settings[k]]
    if differ:
        changes = ", ".join(f"{k} {old.get(k)!r} → {settings[k]!r}" for k in differ)
        raise InvalidOptionError(f"{OUT} {path.parent} holds {what} with other settings ({changes}); choose another "
                                 f"{OUT}, or add {OVERWRITE} to replace them")
