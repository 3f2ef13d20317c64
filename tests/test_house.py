"""House rules of the code's shape (issue 60, "one home for each job"): no function in ``freespace/`` longer than
80 lines, and the command line, the package ``freespace/cli/``, parses options and dispatches (the work is the
library's): no module of it over 800 lines, and its ``__init__.py`` holds the parser, the table of commands and
``main``, each command's options and handler living in a module of its job; the training configuration
(``engine/config.py``) does that one job in at most 400 lines, and the label tree is handled in one module that
imports neither torch nor pydantic."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "freespace"

MAX_FUNCTION_LINES = 80
MAX_CLI_LINES = 800
MAX_CONFIG_LINES = 400


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


def test_the_cli_is_thin() -> None:
    cli = PACKAGE / "cli"
    assert cli.is_dir() and not (PACKAGE / "cli.py").exists(), "the command line is the package freespace/cli/"
    long = [f"{p.relative_to(ROOT)} has {n} lines" for p in sorted(cli.glob("*.py"))
            if (n := len(p.read_text().splitlines())) > MAX_CLI_LINES]
    assert not long, f"split by job or move work into the library (at most {MAX_CLI_LINES} lines):\n" + "\n".join(long)


def test_the_cli_package_parses_and_dispatches() -> None:
    """``freespace/cli/__init__.py`` defines ``main``, ``build_parser`` and the table of commands, and no command:
    every ``cmd_<command>`` handler (and its parser) lives in a module of its job, which the table names."""
    from freespace import cli

    tree = ast.parse((PACKAGE / "cli" / "__init__.py").read_text())
    defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    assert {"main", "build_parser"} <= defined and not [d for d in defined if d.startswith("cmd_")]
    for name, (_, _, build) in cli.COMMANDS.items():
        assert build.__module__.startswith("freespace.cli.") and build.__module__ != "freespace.cli.shared", name


def test_the_cli_holds_no_folder_logic() -> None:
    """Claiming an output folder, checking outputs, holding a run's records: the library's (``freespace.io``),
    called by the library's commands, never by the command line itself."""
    words = ("claim_folder", "check_writable", "check_outputs", "hold_labels_record", "freespace.io.outdir")
    found = [f"{p.relative_to(ROOT)}: {w}" for p in sorted((PACKAGE / "cli").glob("*.py")) for w in words
             if w in p.read_text()]
    assert not found, "move this into the library:\n" + "\n".join(found)


def test_the_training_configuration_is_one_job() -> None:
    config = PACKAGE / "engine" / "config.py"
    n = len(config.read_text().splitlines())
    assert n <= MAX_CONFIG_LINES, f"{config.relative_to(ROOT)} has {n} lines: move what is not TrainConfig's out"


def test_the_label_tree_has_one_home_free_of_torch_and_pydantic() -> None:
    """No module defines a function of ``freespace.data.label_tree`` again (one that delegates to it, as
    ``datagen.autolabel.write_label_files`` does for a labeller's result, aside), and it imports neither torch nor
    pydantic (``generate`` of the base install reads label trees)."""
    tree = PACKAGE / "data" / "label_tree.py"
    imported = {alias.name.split(".")[0] for node in ast.walk(ast.parse(tree.read_text()))
                if isinstance(node, (ast.Import, ast.ImportFrom))
                for alias in (node.names if isinstance(node, ast.Import) else [ast.alias(node.module or "")])}
    assert not imported & {"torch", "pydantic", "lightning"}, imported
    defined = {n.name for n in ast.parse(tree.read_text()).body if isinstance(n, ast.FunctionDef)}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == tree:
            continue
        again = [n.name for n in ast.parse(path.read_text()).body if isinstance(n, ast.FunctionDef)
                 and n.name in defined and f"label_tree.{n.name}" not in ast.unparse(n)]  # a wrapper delegates
        assert not again, f"{path.relative_to(ROOT)} defines {again} again"
