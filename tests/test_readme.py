"""What a newcomer types first: the README's quickstart, run verbatim, and the README's counts against the code.

The quickstart's shell blocks run as written, in an empty folder that holds only a link to the repository's
``models/`` (the README is read from the repository root), with the ``freespace`` of this interpreter's
environment; then its Python blocks run there too, on what the shell blocks made.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from freespace.models import list_models, model_options

ROOT = Path(__file__).resolve().parents[1]


def _section(path: Path, title: str) -> str:
    """The text of the ``## title`` section of the Markdown file ``path``."""
    text = path.read_text()
    assert f"\n## {title}\n" in text, f"{path} has no section {title!r}"
    return text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]


def _blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", text, re.S)


@pytest.mark.slow  # trains a U-Net for one epoch: about 30 s on an idle 2-core machine
def test_quickstart_runs_verbatim(tmp_path: Path) -> None:
    quickstart = _section(ROOT / "README.md", "Quickstart")
    shell, python = _blocks(quickstart, "bash"), _blocks(quickstart, "python")
    assert len(shell) >= 2 and len(python) >= 2, "the quickstart lost its blocks"
    (tmp_path / "models").symlink_to(ROOT / "models")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    for block in shell:
        res = subprocess.run(["bash", "-euc", block], cwd=tmp_path, env=env, capture_output=True, text=True,
                             timeout=900)
        assert res.returncode == 0, f"{block}\n{res.stderr[-3000:]}"
    for out in re.findall(r"--out (\S+)", "".join(shell)):
        made = tmp_path / out
        assert made.is_dir() and any(made.iterdir()), f"--out {out} wrote nothing"
    masks = sorted(p.name for p in (tmp_path / "masks").glob("*.png"))
    assert masks == sorted(p.name for p in (ROOT / "models/real-road-fast/examples").glob("*.png"))
    assert (tmp_path / "runs/unet-ha/checkpoints/best.ckpt").is_file()
    assert (tmp_path / "runs/unet-ha/eval/metrics.json").is_file()
    for block in python:
        res = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True,
                             timeout=300)
        assert res.returncode == 0, f"{block}\n{res.stderr[-3000:]}"


_NUMBERS = {"six": 6, "seven": 7, "eight": 8, "nine": 9, "ten": 10}


@pytest.mark.parametrize("path, marker", [("README.md", "| `freespace train`"), ("README.md", "| [Networks"),
                                          ("README.md", "(geometry, datasets,"), ("docs/networks.md", "The ")])
def test_network_counts_match_the_registry(path: str, marker: str) -> None:
    line = next(line for line in (ROOT / path).read_text().splitlines() if line.startswith(marker))
    said = re.search(r"\b(six|seven|eight|nine|ten) networks", line)
    assert said is not None, line
    assert _NUMBERS[said.group(1)] == len(list_models()), f"{path} says {said.group(0)}: {line}"


def test_encoder_name_help_names_every_network_that_takes_one() -> None:
    from freespace.engine.options import options

    help_text = next(o for o in options() if o.name == "encoder_name").help
    takes = {m for m in list_models() if "encoder_name" in model_options(m)}
    named = {m for m in list_models() if re.search(rf"\b{m}\b", help_text)}
    assert named == takes, help_text
