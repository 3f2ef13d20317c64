"""Each top folder of scripts imports the package and its own folder only (issue 60: one home for each job).

``tests/``, ``bench/``, ``studies/`` and ``docs/`` never reach into one another: no ``sys.path`` entry (nor
``site.addsitedir``) of another top folder, no module loaded by path from one (``spec_from_file_location``,
``runpy.run_path``, ``SourceFileLoader``), no import of one (``import bench``, ``from tests import ...``) and no
import of a module that only another top folder holds (``from helpers import ...`` in a study: ``tests/helpers.py``).
What two of them share lives in the package (``freespace.evaluation.real_frames``: the real labelled frames) or is
a test's own data. A folder may load its own scripts by path (a study's tests load that study's scripts); running
another folder's script as a program, as a user would (``python bench/realtime.py`` in a test of its refusals), is
no import and is allowed.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the top folders of scripts outside the package
TOPS = ("tests", "bench", "studies", "docs")
#: the calls that put a folder on the import path or load a module from a file
_PATH_CALLS = {"insert", "append", "addsitedir", "spec_from_file_location", "run_path", "SourceFileLoader",
               "spec_from_loader", "extend"}


def _scripts(top: str) -> list[Path]:
    return sorted(p for p in (ROOT / top).rglob("*.py") if ".venv" not in p.parts)


def _modules(top: str) -> set[str]:
    """The module names a folder's scripts could import one another by (file stems, package folders)."""
    names = {p.stem for p in _scripts(top)} | {p.parent.name for p in _scripts(top) if p.name == "__init__.py"}
    return names - {"conftest", "__init__"}


def _strings(node: ast.AST) -> set[str]:
    return {n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)}


def _call_name(call: ast.Call) -> str | None:
    func = call.func
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else None


def _is_path_call(call: ast.Call) -> bool:
    """A call that adds to the import path or loads a module from a file (``sys.path.insert``, not ``list.insert``)."""
    name = _call_name(call)
    if name in ("insert", "append", "extend"):
        owner = call.func.value if isinstance(call.func, ast.Attribute) else None
        return isinstance(owner, ast.Attribute) and owner.attr == "path" and isinstance(owner.value, ast.Name) \
            and owner.value.id == "sys"
    return name in _PATH_CALLS


def crossings(source: str, top: str, others: dict[str, set[str]]) -> list[str]:
    """What the script ``source`` of the top folder ``top`` takes from another top folder, one line each.

    ``others``: every other top folder's module names (:func:`_modules`), less those ``top`` holds itself."""
    tree = ast.parse(source)
    foreign = set(TOPS) - {top}
    assigned: dict[str, set[str]] = {}  # a name → the strings of the values assigned to it (one step of indirection)
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    assigned.setdefault(target.id, set()).update(_strings(node.value))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and _is_path_call(node):
            texts = set().union(*(_strings(a) for a in [*node.args, *(k.value for k in node.keywords)]))
            for name in {n.id for a in node.args for n in ast.walk(a) if isinstance(n, ast.Name)}:
                texts |= assigned.get(name, set())
            parts = {part for text in texts for part in text.replace("\\", "/").split("/")}
            if parts & foreign:
                found.append(f"line {node.lineno}: {_call_name(node)}(...) reaches into {sorted(parts & foreign)[0]}/")
        elif isinstance(node, ast.Import | ast.ImportFrom):
            if isinstance(node, ast.ImportFrom) and (node.level or node.module is None):
                continue
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module]
            for name in names:
                first = name.split(".")[0]
                if first in foreign:
                    found.append(f"line {node.lineno}: imports {name}, another top folder")
                elif first not in sys.stdlib_module_names:
                    owner = next((o for o, mods in others.items() if first in mods), None)
                    if owner is not None:
                        found.append(f"line {node.lineno}: imports {first}, a module of {owner}/")
    return found


def _others(top: str) -> dict[str, set[str]]:
    own = _modules(top)
    return {other: _modules(other) - own for other in TOPS if other != top}


@pytest.mark.parametrize("top", TOPS)
def test_a_top_folder_imports_the_package_and_itself_only(top: str) -> None:
    others = _others(top)
    found = [f"{path.relative_to(ROOT)} {line}" for path in _scripts(top)
             for line in crossings(path.read_text(encoding="utf-8"), top, others)]
    assert found == [], "move what two folders share into the package (or the test's own data):\n" + "\n".join(found)


@pytest.mark.parametrize("top,source", [
    ("tests", 'import importlib.util\nfrom pathlib import Path\nspec = importlib.util.spec_from_file_location('
              '"real_frames", Path(__file__).resolve().parents[1] / "bench" / "real_frames.py")\n'),
    ("tests", 'import importlib.util\nfrom pathlib import Path\npath = Path(__file__).parents[1] / "bench" / "d.py"\n'
              'spec = importlib.util.spec_from_file_location("d", path)\n'),
    ("bench", 'import sys\nfrom pathlib import Path\nROOT = Path(__file__).parents[1]\n'
              'sys.path.insert(0, str(ROOT / "tests"))\n'),
    ("studies", 'import sys\nfrom pathlib import Path\nsys.path.insert(0, str(Path(__file__).parents[2] / "bench"))\n'),
    ("studies", "def f():\n    from helpers import tiny_road_checkpoint\n"),
    ("studies", "from realtime import f_scores\n"),
    ("tests", "import bench.realtime\n"),
    ("bench", "from tests.helpers import synthetic_pair\n"),
])
def test_the_check_sees_each_way_of_reaching_across(top: str, source: str) -> None:
    """The ways the folders reached into one another before issue 60, each one found."""
    assert len(crossings(source, top, _others(top))) == 1, source


@pytest.mark.parametrize("top,source", [
    ("bench", 'import sys\nfrom pathlib import Path\nsys.path.insert(0, str(Path(__file__).resolve().parent))\n'
              "from _common import machine\n"),
    ("studies", 'import importlib.util\nfrom pathlib import Path\nSTUDY = Path(__file__).resolve().parents[1]\n'
                'spec = importlib.util.spec_from_file_location("m", STUDY / "evaluate.py")\n'),
    ("tests", "from freespace.evaluation import real_frames\nfrom helpers import SHARED\nimport json, os.path\n"),
    ("bench", "names = []\nnames.insert(0, 'tests')\n"),
])
def test_the_check_lets_a_folder_use_the_package_and_itself(top: str, source: str) -> None:
    assert crossings(source, top, _others(top)) == [], source
