"""House rules of the code's shape (issue 60, "one home for each job"): no function in ``freespace/`` longer than
80 lines, and ``freespace/cli.py`` (which parses options and dispatches; the work is the library's) at most 800
lines."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "freespace"

MAX_FUNCTION_LINES = 80
MAX_CLI_LINES = 800


def _long_functions(path: Path, limit: int) -> list[str]:
    """``file:line name (n lines)`` of every function or method of ``path`` longer than ``limit`` lines
    (``end_lineno - lineno + 1``: its decorators aside, its docstring included)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1  # type: ignore[operator]
            if n > limit:
                where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name
                found.append(f"{where}:{node.lineno} {node.name} ({n} lines)")
    return found


def test_no_function_is_longer_than_80_lines() -> None:
    found = [f for path in sorted(PACKAGE.rglob("*.py")) for f in _long_functions(path, MAX_FUNCTION_LINES)]
    assert not found, f"split these into named steps (at most {MAX_FUNCTION_LINES} lines each):\n" + "\n".join(found)


def test_the_checker_sees_a_long_function(tmp_path: Path) -> None:
    path = tmp_path / "probe.py"
    path.write_text("def short():\n    pass\n\n\nclass A:\n    def long(self):\n" + "        x = 1\n" * 80)
    assert _long_functions(path, MAX_FUNCTION_LINES) == ["probe.py:6 long (81 lines)"]


@pytest.mark.xfail(strict=True, reason="cli.py still holds every command's parser (about 550 lines of options and "
                                       "help) and the label-tree and config code another change moves")
def test_the_cli_is_thin() -> None:
    lines = len((PACKAGE / "cli.py").read_text().splitlines())
    assert lines <= MAX_CLI_LINES, f"freespace/cli.py has {lines} lines; move work into the library"
