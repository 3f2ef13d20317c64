"""docs/architecture.md stays true: its module tree names every module of the package, and names none that is gone.

A module is named by its file in the tree (``    kitti_raw.py    ...`` under ``  data/``; a package by its folder,
``  runtime/``; a folder's line may list its modules, as ``synthetic/`` does) or by its dotted name in backticks
(```freespace.labels```). The command line (``freespace/cli.py`` or the package ``freespace/cli/``) is left out:
its lines are kept with the command line.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "architecture.md"
PACKAGE = ROOT / "freespace"
_ENTRY = re.compile(r"^( *)([A-Za-z_][\w.]*/|[A-Za-z_]\w*\.py)(?:\s+(.*))?$")
_INLINE = re.compile(r"(?<![\w./])([A-Za-z_]\w*\.py)\b")


def _tree_lines() -> list[str]:
    """The lines of the page's module tree (the code block that starts with ``freespace/``)."""
    text = PAGE.read_text(encoding="utf-8")
    for block in re.findall(r"^```[^\n]*\n(.*?)^```", text, re.S | re.M):
        if block.startswith("freespace/"):
            return block.splitlines()
    raise AssertionError("docs/architecture.md has no module tree (a code block starting with `freespace/`)")


def _tree_paths() -> set[str]:
    """The paths the tree names, relative to the repository root (``freespace/data/kitti_raw.py``,
    ``freespace/data/synthetic/`` for a folder)."""
    named: set[str] = set()
    stack: list[str] = []  # the folders enclosing the current line, by depth
    for line in _tree_lines():
        m = _ENTRY.match(line)
        if not m or len(m.group(1)) % 2 or len(m.group(1)) > 2 * len(stack):
            continue  # a description's continuation line
        depth = len(m.group(1)) // 2
        if depth == 0 and m.group(2) != "freespace/":
            break  # tests/, bench/, ...: beside the package, not in it
        stack = stack[:depth]
        path = "".join(stack) + m.group(2)
        named.add(path)
        if m.group(2).endswith("/"):
            stack.append(m.group(2))
            for child in _INLINE.findall(m.group(3) or ""):  # a folder's line listing its modules
                named.add(path + child)
    return named


def _is_cli(rel: str) -> bool:
    return rel == "freespace/cli.py" or rel.startswith("freespace/cli/")


def _modules() -> dict[str, str]:
    """``{path as the tree names it: dotted name}`` of every module of the package but the command line's."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if _is_cli(rel):
            continue
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
            rel = rel[: -len("__init__.py")]
        found[rel] = ".".join(parts)
    return found


def test_every_module_is_on_the_page():
    text = PAGE.read_text(encoding="utf-8")
    named = _tree_paths()
    missing = [rel for rel, dotted in _modules().items() if rel not in named and f"`{dotted}`" not in text]
    assert not missing, (f"docs/architecture.md does not name {missing}: add each to the module tree under its "
                         "package, with what it does in one line")


def test_the_page_names_no_module_that_is_gone():
    gone = [rel for rel in _tree_paths() if not _is_cli(rel) and not (ROOT / rel).exists()]
    assert not gone, f"docs/architecture.md's module tree names {gone}, which the package no longer has"


def test_the_tree_is_read():
    """The reading itself: the tree's entries at every depth, and a folder's inline list."""
    named = _tree_paths()
    for rel in ("freespace/", "freespace/errors.py", "freespace/data/", "freespace/data/kitti_raw.py",
                "freespace/data/synthetic/", "freespace/data/synthetic/render.py", "freespace/engine/config.py"):
        assert rel in named, rel
    assert not any(rel.startswith(("tests", "bench", "docs", "studies")) for rel in named)
    assert "freespace/runtime/files.py" not in named  # io's files.py is io's, not the folder above it
