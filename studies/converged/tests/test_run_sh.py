"""The converged run's ``run.sh`` asks ``freespace reproduce`` for each cell in a way the package accepts: run
with stand-ins for ``freespace`` (which records its arguments) and for Python (datacheck and sync), its
``reproduce --only`` lines are parsed by the real CLI and pass the checks that ``reproduce`` makes before any
work (an X cell given ``--autolabels`` failed at its start in session 27)."""

from __future__ import annotations

import os
import shlex
import subprocess
from pathlib import Path

import pytest

from freespace.cli import build_parser
from freespace.experiments.cells import check_autolabels_used

RUN_SH = Path(__file__).resolve().parents[1] / "run.sh"

FAKE_FREESPACE = """#!/usr/bin/env bash
echo "$@" >> "$CALLS"
out=""; prev=""
for a in "$@"; do [ "$prev" = "--out" ] && out=$a; prev=$a; done
case " $* " in
  *" --only "*) echo "INFO done: runs/cell: trained" ;;
  *" --tables "*) mkdir -p "$out" && touch "$out"/results.md "$out"/results.csv "$out"/gains.csv "$out"/index.json ;;
esac
"""


@pytest.fixture
def calls(tmp_path: Path) -> list[list[str]]:
    """The arguments of every ``freespace`` call that ``run.sh`` made for two cells, X and X-auto of U-Net."""
    work, bin_dir = tmp_path / "work", tmp_path / "bin"
    bin_dir.mkdir()
    (tmp_path / "keep" / "res-final").mkdir(parents=True)  # the finished cells' copy (sync.py save makes it)
    for name in ("syn", "same-rigs", "shifted", "matched", "autolabels"):  # made already: nothing rendered
        (work / name).mkdir(parents=True)
    for name, text in (("freespace", FAKE_FREESPACE), ("python", "#!/usr/bin/env bash\nexit 0\n")):
        (bin_dir / name).write_text(text)
        (bin_dir / name).chmod(0o755)
    env = dict(os.environ, FREESPACE=str(bin_dir / "freespace"), PYTHON=str(bin_dir / "python"),
               CALLS=str(tmp_path / "calls.txt"), KEEP=str(tmp_path / "keep"), JOBS="1",
               CELLS="unet,X,0 unet,X-auto,0")
    done = subprocess.run(["bash", str(RUN_SH), str(work)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "FAILED" not in done.stdout, done.stdout
    return [shlex.split(line) for line in (tmp_path / "calls.txt").read_text().splitlines()]


def test_each_cell_is_a_reproduce_call_the_package_accepts(calls: list[list[str]]) -> None:
    cells = [argv for argv in calls if argv[0] == "reproduce" and "--only" in argv]
    assert [argv[argv.index("--only") + 1] for argv in cells] == ["unet,X,0", "unet,X-auto,0"]
    for argv in cells:
        args = build_parser(["reproduce"]).parse_args(argv)
        variant = args.only.split(",")[1]
        check_autolabels_used(args.autolabels, [variant])  # raises for a label tree that no cell reads
        assert (args.autolabels is not None) == (variant == "X-auto")
    assert any(argv[0] == "reproduce" and "--tables" in argv for argv in calls)
