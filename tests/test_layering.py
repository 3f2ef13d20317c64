"""Imports follow the layering of docs/architecture.md (its table is read here): no module imports a higher layer,
and no modules import each other (directly or round a longer loop). Every ``import`` statement counts, also those
inside functions (a lazy import is still a dependency)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "freespace"

ARCHITECTURE = ROOT / "docs" / "architecture.md"


def _read_layers(text: str) -> list[tuple[str, ...]]:
    """The table under ``## Layers`` of docs/architecture.md, lowest layer first: rows ``| N | `module`, ... |``
    with N = 0, 1, 2, ... in order. A module belongs to the entry that names it or its closest enclosing
    package; the root package's entry, "freespace", names its __init__ only, so a new module at the root must be
    given a layer there."""
    section = re.search(r"^## Layers\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    if section is None:
        raise ValueError("docs/architecture.md has no '## Layers' section")
    layers: list[tuple[str, ...]] = []
    for number, modules in re.findall(r"^\|\s*(\d+)\s*\|(.*)\|\s*$", section.group(1), re.M):
        if int(number) != len(layers):
            raise ValueError(f"docs/architecture.md: layer {number} where layer {len(layers)} was expected")
        names = tuple(re.findall(r"`([\w.]+)`", modules))
        if not names:
            raise ValueError(f"docs/architecture.md: layer {number} names no module")
        layers.append(names)
    if not layers:
        raise ValueError("docs/architecture.md's '## Layers' section has no table rows '| N | `module`, ... |'")
    return layers


LAYERS: list[tuple[str, ...]] = _read_layers(ARCHITECTURE.read_text())

def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _graph() -> dict[str, dict[str, int]]:
    """``{module: {imported freespace module: line}}`` from every import statement."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, dict[str, int]] = {}
    for name, path in mods.items():
        deps: dict[str, int] = {}
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                # `from pkg import submodule` depends on the submodule, `from pkg import name` on pkg
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            for target in targets:
                dep = resolve(target) if target.split(".")[0] == "freespace" else None
                if dep is not None and dep != name:
                    deps.setdefault(dep, node.lineno)
        graph[name] = deps
    return graph


def _layer(module: str) -> int | None:
    best, layer = -1, None
    for i, names in enumerate(LAYERS):
        for prefix in names:
            inside = module.startswith(prefix + ".") and prefix != PACKAGE.name
            if (module == prefix or inside) and len(prefix) > best:
                best, layer = len(prefix), i
    return layer


def _cycles(graph: dict[str, dict[str, int]]) -> list[frozenset[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[frozenset[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(frozenset(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_every_module_has_a_layer() -> None:
    assert [m for m in _modules() if _layer(m) is None] == [], \
        "give new modules a layer in docs/architecture.md's table"


def test_no_upward_imports() -> None:
    graph = _graph()
    upward = [f"{m} (layer {_layer(m)}) imports {d} (layer {_layer(d)}) at line {line}"
              for m, deps in graph.items() for d, line in deps.items()
              if (_layer(d) or 0) > (_layer(m) or 0)]
    assert upward == []


def test_no_import_cycles() -> None:
    cycles = [sorted(c) for c in _cycles(_graph())]
    assert cycles == []


def test_geometry_reads_no_files() -> None:
    """The geometry is functions of arrays (kornia style): files are read and written by the io layer."""
    graph = _graph()
    found = [f"{m} imports {d} at line {line}" for m, deps in graph.items() for d, line in deps.items()
             if m.startswith("freespace.geometry") and d.startswith("freespace.io")]
    assert found == []


def test_checker_sees_a_cycle_and_an_upward_import() -> None:
    graph = {"freespace.io": {"freespace.data.base": 1}, "freespace.data.base": {"freespace.io": 1}}
    assert _cycles(graph) == [frozenset(graph)]
    assert _layer("freespace.data.base") > _layer("freespace.io")  # type: ignore[operator]
    assert _layer("freespace.engine.train") == _layer("freespace.engine")
    assert _layer("freespace.unplaced") is None and _layer("freespace") == 0  # a root module needs its own entry


def test_the_layer_table_is_read_as_written() -> None:
    """The parser takes the rows in order, every backquoted module of a row, and refuses a table with a gap."""
    text = ("## Layers\n\n| layer | modules |\n|---:|---|\n| 0 | `freespace`, `freespace.errors` |\n"
            "| 1 | `freespace.io` |\n")
    assert _read_layers(text) == [("freespace", "freespace.errors"), ("freespace.io",)]
    with pytest.raises(ValueError, match="layer 2 where layer 1"):
        _read_layers(text.replace("| 1 |", "| 2 |"))
    with pytest.raises(ValueError, match="no '## Layers' section"):
        _read_layers(text.replace("## Layers", "## Layering"))
    assert LAYERS[0][0] == "freespace" and ("freespace.cli",) in LAYERS and ("freespace.geometry" in LAYERS[1])
    every = [m for names in LAYERS for m in names]
    assert len(every) == len(set(every)), "a module stands in two layers of docs/architecture.md"
    mods = _modules()
    assert [m for m in every if m not in mods] == [], "docs/architecture.md names modules that do not exist"


# a flag may stand in a library string only inside a command the user is told to run
_COMMAND = re.compile(r"(freespace [a-z-]+|pip install|sbatch|SLURM)[^`\n]*$")


def test_flags_live_in_the_cli_only() -> None:
    """The library speaks in parameters (``freespace.errors.param``), the command line in flags: no module but
    those of ``freespace/cli/`` spells a ``--flag``, in code, messages or docstrings, except inside a command the
    text tells the user to run (``freespace export --format onnx``, ``pip install --force-reinstall ...``)."""
    found = []
    for module, path in _modules().items():
        if module == "freespace.cli" or module.startswith("freespace.cli."):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                for m in re.finditer(r"--[a-z][a-z0-9-]*", node.value):
                    if not _COMMAND.search(node.value[:m.start()]):
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno} {m.group()}")
    assert not found, "flags outside freespace/cli/ (name the parameter with errors.param):\n" + "\n".join(found)
