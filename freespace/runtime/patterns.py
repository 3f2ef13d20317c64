"""Regular expressions a user writes (a generic layout's ``scenario_pattern``), bounded so that none stalls a command.

Python's :mod:`re` backtracks: a quantifier over a group that can match one text in several ways (``(a+)+``,
``(\\w+\\s?)+``, ``(ab|a)*``, ``(a?){30}``) takes time exponential in the length of the name it fails on, and
unbounded quantifiers in a row (``.*.*.*=``) a power of it. Two bounds:

* :func:`check_pattern` refuses, in one line that states the rule, a pattern of more than :data:`MAX_PATTERN`
  characters, one with a backreference, and one with a **repeated group that holds a quantifier or an
  alternation** (``|`` of more than single characters): a group under ``*``, ``+`` or ``{m,n}`` with n > 1 holds
  neither ``*``, ``+``, ``?``, ``{m,n}`` nor ``|`` (``(?:_\\d+)+`` is refused, ``(?:_\\d)+`` and ``(_\\d+)?`` are
  not). These are the patterns that backtrack exponentially;
* :func:`search_names` matches the names in a child process that gets :data:`MATCH_SECONDS` seconds in all: what the
  rule lets through and still backtracks (many quantifiers in a row over long names) is refused after that time,
  in one line, instead of running for minutes.

The standard library only.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Sequence
from re import _constants as _sre  # type: ignore[attr-defined]  # the parser's op codes (CPython ≥ 3.11)
from re import _parser as _sre_parse  # type: ignore[attr-defined]
from typing import Any

from freespace.errors import InvalidOptionError

__all__ = ["MAX_PATTERN", "MATCH_SECONDS", "RULE", "check_pattern", "search_names"]

#: the most characters a user's pattern may have
MAX_PATTERN = 200
#: the seconds a child process has to match all the names against a user's pattern
MATCH_SECONDS = 5.0
#: the rule, as the messages state it
RULE = (f"at most {MAX_PATTERN} characters, no backreference, and no quantifier (*, +, ?, {{m,n}}) or | inside a "
        f"group that is itself repeated (*, +, {{m,n}})")
_REPEATS = {_sre.MAX_REPEAT, _sre.MIN_REPEAT, getattr(_sre, "POSSESSIVE_REPEAT", _sre.MAX_REPEAT)}
_BACKREFERENCES = {_sre.GROUPREF, _sre.GROUPREF_EXISTS, _sre.GROUPREF_IGNORE, _sre.GROUPREF_LOC_IGNORE,
                   _sre.GROUPREF_UNI_IGNORE}
#: what the child process runs: the pattern and names as JSON on stdin, ``[matched, group]`` a name on stdout
_CHILD = """import json, re, sys
job = json.load(sys.stdin)
pattern, group = re.compile(job["pattern"]), job["group"]
found = []
for name in job["names"]:
    m = pattern.search(name)
    found.append([m is not None, None if m is None or group is None else m.group(group)])
json.dump(found, sys.stdout)
"""


def _parts(value: Any) -> list[Any]:
    """The sub-patterns of a parsed item's argument (a group's body, a repeat's, each branch of an alternation)."""
    found, stack = [], [value]
    while stack:
        item = stack.pop()
        if isinstance(item, _sre_parse.SubPattern):
            found.append(item)
        elif isinstance(item, (tuple, list)):
            stack.extend(item)
    return found


def _backtracks(pattern: Any, repeated: bool = False) -> str | None:
    """What in the parsed ``pattern`` breaks the rule (:data:`RULE`), or None; ``repeated``: it is the body of a
    repeated group."""
    for op, value in pattern.data:
        if op in _BACKREFERENCES:
            return "a backreference"
        if repeated and op in _REPEATS:
            return "a quantifier inside a repeated group"
        if repeated and op is _sre.BRANCH:
            return "an alternation (|) inside a repeated group"
        inner = repeated or (op in _REPEATS and value[1] > 1)
        for part in _parts(value):
            found = _backtracks(part, inner)
            if found is not None:
                return found
    return None


def _shown(text: str) -> str:
    """A pattern as a message shows it: as written, or as a Python string when it holds a line break or a
    character that does not print."""
    return text if text.isprintable() else repr(text)


def check_pattern(text: str, where: str) -> re.Pattern[str]:
    """``text`` compiled, after checking that it follows the rule (:data:`RULE`; module docstring).

    Args:
        text: the user's pattern. where: what set it, the start of the message (``"ROOT/freespace.yaml:
            scenario_pattern"``).

    Raises:
        InvalidOptionError: no regular expression, or one that breaks the rule (what breaks it, and the rule).
    """
    if len(text) > MAX_PATTERN:
        raise InvalidOptionError(f"{where} has {len(text)} characters; a pattern has {RULE}: write a shorter one")
    try:
        parsed = _sre_parse.parse(text)
        compiled = re.compile(text)
    except re.error as exc:
        raise InvalidOptionError(f"{where} is not a regular expression ({exc})") from None
    except RecursionError:  # groups nested thousands deep
        raise InvalidOptionError(f"{where} nests its groups too deep; a pattern has {RULE}") from None
    problem = _backtracks(parsed)
    if problem is not None:
        raise InvalidOptionError(f"{where} {_shown(text)} has {problem}, which can take minutes to match a name; a "
                                 f"pattern has {RULE}: e.g. (?P<scenario>[^_]+)_ instead of (?P<scenario>(?:[^_]+_)+)")
    return compiled


def search_names(text: str, names: Sequence[str], where: str, group: str | None = None,
                 seconds: float | None = None) -> list[tuple[bool, str | None]]:
    """``re.search`` of the pattern ``text`` (checked by :func:`check_pattern`) in each of ``names``: whether it
    matched and, with ``group``, that group's text (None where it matched nothing), in a child process given
    ``seconds`` in all (None: :data:`MATCH_SECONDS`; matched here when no child can be started).

    Raises:
        InvalidOptionError: the pattern breaks the rule, or took longer than ``seconds`` (named, with ``where``).
    """
    compiled = check_pattern(text, where)
    seconds = MATCH_SECONDS if seconds is None else seconds
    job = json.dumps({"pattern": text, "group": group, "names": list(names)})
    try:
        done = subprocess.run([sys.executable, "-I", "-S", "-c", _CHILD], input=job, capture_output=True, text=True,
                              timeout=seconds, check=True) if sys.executable else None
    except subprocess.TimeoutExpired:
        raise InvalidOptionError(f"{where} {_shown(text)} took more than {seconds:g} s to match {len(names)} names (it "
                                 f"backtracks: quantifiers in a row, such as .*.*.*); write a simpler pattern, e.g. "
                                 f"(?P<scenario>[^_]+)_") from None
    except (OSError, subprocess.CalledProcessError):
        done = None
    if done is None:
        matches = [compiled.search(name) for name in names]
        return [(m is not None, None if m is None or group is None else m.group(group)) for m in matches]
    return [(bool(matched), value) for matched, value in json.loads(done.stdout)]
