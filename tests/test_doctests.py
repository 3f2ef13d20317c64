"""The docstrings' ``>>>`` examples run, and every public function of ``freespace.geometry`` has one.

Only the modules whose source holds an example are imported, so a module without one (most of the torch side)
costs nothing here. Each module's examples must all be found by doctest: an example in a place doctest does not
reach (a private nested function, a comment) is a line that never runs, and fails the test.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "freespace"
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
_PROMPT = re.compile(r"^\s*>>>", re.M)


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules_with_examples() -> dict[str, int]:
    """``{module: number of >>> lines in its source}`` for every module of the package that has one."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        count = len(_PROMPT.findall(path.read_text(encoding="utf-8")))
        if count:
            found[_module(path)] = count
    return found


EXAMPLES = _modules_with_examples()


def _doctests(name: str) -> list[doctest.DocTest]:
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder(exclude_empty=True).find(module, name) if t.examples]


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_docstring_examples_run(name: str) -> None:
    tests = _doctests(name)
    found = sum(len(t.examples) for t in tests)
    assert found == EXAMPLES[name], (f"{name} has {EXAMPLES[name]} '>>>' lines but doctest finds {found} examples: "
                                     f"put every example in a docstring doctest reaches")
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    report: list[str] = []
    for test in tests:
        runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def _public_functions(package: str) -> dict[str, object]:
    """``{qualified name: function}``: the public functions of every module of ``package`` and the public
    methods (plain, class or static; not properties) of its public classes, each where it is defined."""
    pkg = importlib.import_module(package)
    out: dict[str, object] = {}
    for info in pkgutil.iter_modules(pkg.__path__):
        module = importlib.import_module(f"{package}.{info.name}")
        for name, obj in vars(module).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
                continue
            if inspect.isfunction(obj):
                out[f"{module.__name__}.{name}"] = obj
            elif inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    func = member.__func__ if isinstance(member, (classmethod, staticmethod)) else member
                    if not attr.startswith("_") and inspect.isfunction(func):
                        out[f"{module.__name__}.{name}.{attr}"] = func
    return out


def test_every_public_geometry_function_has_an_example() -> None:
    functions = _public_functions("freespace.geometry")
    assert "freespace.geometry.road_model.fit_road_model" in functions
    assert "freespace.geometry.homography.StereoCalibration.from_kitti" in functions  # a classmethod counts
    missing = [name for name, func in functions.items() if ">>>" not in (inspect.getdoc(func) or "")]
    assert missing == [], "public functions of freespace.geometry without a '>>>' example:\n" + "\n".join(missing)


def test_a_failing_example_fails() -> None:
    """The runner used above reports a wrong output and an example that raises."""
    def wrong() -> None:
        """
        >>> 1 + 1
        3
        >>> int("x")
        """
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    for test in doctest.DocTestFinder().find(wrong, "wrong", globs={}):
        runner.run(test, out=lambda _: None)
    assert runner.failures == 2


def test_the_readme_python_quickstart_runs() -> None:
    """The README's first Python example (the method on one rendered pair) runs as printed (it needs no file)
    and finds the renderer's roll."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", readme, re.S)
    assert blocks, "the README has a Python quickstart"
    scope: dict[str, object] = {}
    exec(compile(blocks[0], "README.md", "exec"), scope)  # noqa: S102 - the project's own README
    model, generated, sample = scope["model"], scope["generated"], scope["s"]
    assert abs(model.roll_deg - sample.meta["roll_deg"]) < 0.05  # the fit finds the rig's true roll
    assert generated.shape == sample.left.shape
