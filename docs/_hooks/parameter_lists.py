"""griffe extension: the library's aligned parameter lists render as lists in the API reference.

The docstrings describe constructor arguments as aligned text (``name:   what it is``, continuation
lines indented under the text), which Markdown would run together into one paragraph. At load
time each such block becomes a bullet list (``- `name`: what it is``); the source is unchanged.
"""
from __future__ import annotations

import re

import griffe

#: ``name:`` (one or two comma-separated names), spaces, the text: an entry of an aligned list. A list starts
#: with an entry whose gap is at least two spaces (prose has one); inside a list, the longest name has one.
ENTRY = re.compile(r"^(?P<names>[A-Za-z_]\w*(?:, [A-Za-z_]\w*)?):(?P<gap> +)(?P<text>\S.*)$")


class ParameterLists(griffe.Extension):
    """Rewrite aligned ``name: text`` blocks of class and function docstrings as Markdown lists."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = as_lists(obj.docstring.value)


def as_lists(text: str) -> str:
    """The docstring with each aligned entry (and its indented continuation lines) as one list item."""
    out: list[str] = []
    item: list[str] | None = None
    indent = 0
    for line in text.splitlines():
        m = ENTRY.match(line)
        if m and (item is not None or len(m.group("gap")) >= 2):
            _close(out, item)
            names = ", ".join(f"`{n}`" for n in m.group("names").split(", "))
            item = [f"- {names}: {m.group('text')}"]
            indent = len(m.group("names")) + 1 + len(m.group("gap"))
        elif item is not None and line.startswith(" " * indent) and line.strip():
            item.append(line.strip())
        else:
            _close(out, item)
            item = None
            out.append(line)
    _close(out, item)
    return "\n".join(out)


def _close(out: list[str], item: list[str] | None) -> None:
    if item:
        if out and out[-1].strip() and not out[-1].startswith("- "):
            out.append("")
        out.append(" ".join(item))
