"""Keep a long `reproduce` run's finished cells in the repository, without checkpoints.

``python sync.py save RES RUN KEEP``: copy the small files of ``RES/runs/RUN`` (config, per-epoch CSV, metrics,
splits, test-set metrics, the run's manifest) to ``KEEP/runs/RUN``; never ``checkpoints/``, ``generated/`` or
the lock. ``python sync.py restore KEEP RES``: copy every kept cell that ``RES`` lacks back into it (a cell
finished on another machine is then skipped, not trained again), under RES's own manifest. A cell that ``RES``
holds in any state is left as it is: an extension in progress has no metrics.json, and the kept copy's
shorter metrics.csv must not replace its own.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from freespace.experiments.tables import OUT_ENTRIES
from freespace.io.outdir import claim_folder

SKIP = {"checkpoints", "generated", "tensorboard"}


def save(res: Path, run: str, keep: Path) -> None:
    src, dst = res / "runs" / run, keep / "runs" / run
    if not (src / "metrics.json").is_file():  # a wrong name would copy nothing, silently
        raise SystemExit(f"{src} is not a finished cell (no metrics.json): nothing saved")
    for path in sorted(src.rglob("*")):
        rel = path.relative_to(src)
        if path.is_file() and rel.parts[0] not in SKIP and not path.name.endswith((".tmp", "lock")):
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, dst / rel)


def restore(keep: Path, res: Path) -> None:
    with claim_folder(res, "reproduce", entries=OUT_ENTRIES, shared=True):
        for cell in sorted(p for p in (keep / "runs").glob("*") if p.is_dir()):
            if not (res / "runs" / cell.name).exists():
                shutil.copytree(cell, res / "runs" / cell.name)


if __name__ == "__main__":
    if sys.argv[1] == "save":
        save(Path(sys.argv[2]), sys.argv[3], Path(sys.argv[4]))
    else:
        restore(Path(sys.argv[2]), Path(sys.argv[3]))
