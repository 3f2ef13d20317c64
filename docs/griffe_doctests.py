"""Griffe extension of the API reference (``mkdocs.yml``): a docstring's ``>>>`` examples become code.

The docstrings give examples under ``Example:`` (which the Google-style parser reads as an admonition, not an
examples section) or in their text; either way Markdown would read ``>>>`` as nested quotes and an output such
as ``[[1.0, 2.0], ...]`` as a reference link. Each run of ``>>>`` lines with their output, up to a blank line,
is fenced as a ``pycon`` block at its own indentation before the docstring is parsed.
"""

from __future__ import annotations

from typing import Any

import griffe


def fence_examples(text: str) -> str:
    """``text`` with every ``>>>`` block (to the next blank line) inside a ``pycon`` code fence."""
    out: list[str] = []
    lines = text.split("\n")
    i, in_fence = 0, False
    while i < len(lines):
        line = lines[i]
        stripped = line.lstrip()
        if stripped.startswith("```"):
            in_fence = not in_fence
        if not in_fence and stripped.startswith(">>>"):
            indent = line[: len(line) - len(stripped)]
            out.append(indent + "```pycon")
            while i < len(lines) and lines[i].strip():
                out.append(lines[i])
                i += 1
            out.append(indent + "```")
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


class DoctestBlocks(griffe.Extension):
    """Fences the ``>>>`` examples of every docstring (see the module docstring)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None and ">>>" in obj.docstring.value:
            obj.docstring.value = fence_examples(obj.docstring.value)
