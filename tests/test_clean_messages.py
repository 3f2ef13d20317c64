"""Messages never carry placeholders or control bytes (issue 60): no error or log message is a template that was
never filled (a ``{name}`` without its ``f``, a ``%s`` nobody formats, a :func:`~freespace.errors.param` marker
that reaches a log line), and a control byte from a user's file name is shown escaped, in errors and warnings."""

from __future__ import annotations

import ast
import logging
import re
from pathlib import Path

import pytest

from freespace.errors import param

from helpers import refused

ROOT = Path(__file__).resolve().parents[1]
#: a ``str.format``/f-string field: ``{name}``, ``{obj.attr}``, ``{x!r}``, ``{v:.2f}`` (not YAML's ``{a: b}``)
_FIELD = re.compile(r"\{[A-Za-z_][A-Za-z0-9_.]*(\[[^\]]*\])?(![rsa])?(:[^{}\s][^{}]*)?\}")
_LOG_CALLS = {"debug", "info", "warning", "error", "exception", "critical"}


def unfilled(source: str) -> list[str]:
    """The messages of ``source`` (the first argument of an ``...Error(...)`` or a logger call) that hold a
    placeholder nothing fills, and the log calls that pass a ``param()`` marker, as ``line: text``."""
    tree = ast.parse(source)
    parent = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    found = []
    for call in (n for n in ast.walk(tree) if isinstance(n, ast.Call) and n.args):
        name = call.func.attr if isinstance(call.func, ast.Attribute) else getattr(call.func, "id", "")
        is_error = name.endswith("Error")
        is_log = name in _LOG_CALLS and isinstance(call.func, ast.Attribute)
        if not (is_error or is_log):
            continue
        for node in ast.walk(call.args[0]):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and not isinstance(parent.get(node), ast.JoinedStr):
                up = parent.get(node)
                filled = (isinstance(up, ast.Attribute) and up.attr == "format") or \
                    (isinstance(up, ast.BinOp) and isinstance(up.op, ast.Mod)) or (is_log and len(call.args) > 1)
                if not filled and (_FIELD.search(node.value) or (is_error and re.search(r"%[sdrf]", node.value))):
                    found.append(f"{node.lineno}: {node.value[:70]!r}")
            if is_log and isinstance(node, ast.Call) and getattr(node.func, "id", "") == "param":
                found.append(f"{node.lineno}: param() in a log message (the log line would show its marker)")
    return found


def test_no_message_of_the_package_is_an_unfilled_template() -> None:
    found = [f"{p.relative_to(ROOT)}:{line}" for p in sorted((ROOT / "freespace").rglob("*.py"))
             for line in unfilled(p.read_text(encoding="utf-8"))]
    assert found == [], "a message that is never filled (add its f, or format it):\n" + "\n".join(found)


@pytest.mark.parametrize("source,count", [
    ('raise InvalidOptionError("unknown dataset {name!r}; choose one")', 1),
    ('raise InputFileError("no file %s" )', 1),
    ('log.warning(f"{param(\'labels\')} is ignored")', 1),
    ('raise InvalidOptionError(f"unknown dataset {name!r}; e.g. {{a: b}}")', 0),
    ('raise InvalidOptionError("give test_sets as a mapping (e.g. {shifted: shifted})")', 0),
    ('log.warning("%s frames left out", n)', 0),
    ('raise InputFileError("no file %s" % path)', 0),
])
def test_the_scan_sees_an_unfilled_template(source: str, count: int) -> None:
    assert len(unfilled(source)) == count


def test_a_control_byte_in_a_name_is_shown_escaped_in_an_error(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "bell\x07 and \x1b[31mred\x1b[0m and\rback"
    err = refused(capsys, ["datasets", "info", "--dataset", "kitti", "--root", str(root)])
    assert not any(ord(c) < 32 or ord(c) == 127 for c in err), repr(err)
    assert "\\x07" in err and "\\x1b[31mred" in err and "\\r" in err and "\x00" not in err


def test_a_control_byte_or_a_parameter_in_a_warning_is_shown_clean(capsys: pytest.CaptureFixture) -> None:
    from freespace.runtime.log import setup_logging

    setup_logging(0)
    logging.getLogger("freespace.test").warning("frame \x1b[2Jcleared\x07 of %s", f"{param('labels')} tree\ragain")
    err = capsys.readouterr().err
    assert err.endswith("\n") and err.count("\n") == 1, repr(err)
    assert not any(ord(c) < 32 and c != "\n" for c in err), repr(err)
    assert "\\x1b[2Jcleared\\x07" in err and "labels tree\\ragain" in err and "\x00" not in err
