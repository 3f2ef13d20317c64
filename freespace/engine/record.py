"""What a training run records about where it ran (the package's commit, the data root and the torch version) and
what it read, by content (:func:`content_hashes`).

These go to the run's ``metrics.json`` (``"record"``), never to ``config.yaml``: they are not training options,
so a resumed or extended run, or a ``reproduce`` cell, is never refused because the commit or the machine
changed; the record of a run says which code and data finished it.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path
from typing import Any

__all__ = ["package_commit", "run_record", "content_hashes"]

#: the commit when the package's source is not a file of a git work tree (an installed wheel, no git)
UNKNOWN = "unknown"


def _git(src: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}  # a caller's GIT_DIR names another repo
    return subprocess.run(["git", "-C", str(src), *args], capture_output=True, text=True, timeout=20, env=env,
                          check=False)


def package_commit(src: Path | None = None) -> str:
    """The git commit (40 hex digits) of the package source ``src`` (default: this ``freespace`` package's
    folder), with ``-dirty`` when the package's files differ from that commit; :data:`UNKNOWN` when ``src``
    is not tracked in a git work tree (e.g. installed into a virtual environment that lies inside one) or git
    cannot be run. Local only: it runs ``git`` on the source folder, never the network."""
    src = Path(src) if src is not None else Path(__file__).resolve().parents[1]
    try:
        tracked = _git(src, "ls-files", "--", "__init__.py")  # git's short options: no freespace flag here
        if tracked.returncode != 0 or not tracked.stdout.strip():
            return UNKNOWN
        head = _git(src, "rev-parse", "HEAD")
        if head.returncode != 0 or not re.fullmatch(r"[0-9a-f]{40}", head.stdout.strip()):
            return UNKNOWN
        dirty = _git(src, "status", "-s", "-uno", "--", ".")  # tracked files that differ from HEAD
        return head.stdout.strip() + ("-dirty" if dirty.returncode != 0 or dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return UNKNOWN


def run_record(root: str | os.PathLike) -> dict[str, Any]:
    """``{"commit": package_commit(), "data_root": root resolved to an absolute path, "torch": torch's
    version}``: what a run's ``metrics.json`` records about the code and data that produced it."""
    import torch

    return {"commit": package_commit(), "data_root": str(Path(root).expanduser().resolve()),
            "torch": torch.__version__}


def content_hashes(config: Any) -> dict[str, Any]:
    """What a run of ``config`` (a :class:`~freespace.engine.config.TrainConfig`) read, by content:
    ``{"encoder_weights": {"path", "sha256"}}`` when its weights are a file
    (:func:`~freespace.data.label_tree.file_record`); ``{"labels": {"path", "sha256", "files"}}`` with a label tree
    (:func:`~freespace.data.label_tree.tree_record`); a labelled folder's ``images`` and ``labels`` (and
    ``val_images``, ``val_labels``) as the files it pairs; an ``init`` checkpoint and a ``teacher``'s. A run records it
    (``RUN/inputs.json``); a resumed run and the cells of one ``reproduce`` are refused when the files changed in
    between (:func:`~freespace.data.label_tree.changed_inputs`)."""
    from freespace.data.label_tree import file_record, files_record, tree_record
    from freespace.engine.option_values import weights_path

    found: dict[str, Any] = {}
    if weights_path(config.encoder_weights) and Path(config.encoder_weights).is_file():  # type: ignore[arg-type]
        found["encoder_weights"] = file_record(config.encoder_weights)  # type: ignore[arg-type]
    if config.images is not None:  # a labelled folder: the images and labels it pairs, by content
        from freespace.engine.labelled import labelled_frames

        for key, paths in labelled_frames(config).files().items():
            found[key] = files_record(getattr(config, key), paths)
    elif config.labels is not None and Path(config.labels).is_dir():
        found["labels"] = tree_record(config.labels)
    from freespace.engine.init import init_checkpoint

    for key in ("init", "teacher"):  # checkpoints: a model folder's model.ckpt, or the file
        if getattr(config, key) is not None:
            found[key] = file_record(init_checkpoint(getattr(config, key), key))
    return found
