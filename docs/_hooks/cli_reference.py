"""mkdocs hook: the command-line reference is the parsers' own help, rendered at build time.

A page line ``<!-- cli-help -->`` becomes one section per ``creep-online`` command
(``creep_online.cli.COMMANDS``, in that order) holding the text ``creep-online COMMAND --help``
prints, so the reference can never disagree with the program. ``<!-- cli-help: NAME -->``
renders one command (``NAME`` may be ``top`` for the top-level listing).
"""
from __future__ import annotations

import os
import re

MARKER = re.compile(r"^<!-- cli-help(?::\s*(?P<name>[\w-]+))?\s*-->$", re.MULTILINE)
#: The width the help is wrapped to, whatever terminal builds the site.
COLUMNS = "96"


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Replace each marker with the help text it names."""
    if "<!-- cli-help" not in markdown:
        return markdown
    return MARKER.sub(lambda m: _render(m.group("name")), markdown)


def _render(name: str | None) -> str:
    from creep_online.cli import COMMANDS
    if name is None:
        return "\n\n".join(_section(command) for command in COMMANDS)
    if name == "top":
        return _block(_help(None))
    if name not in COMMANDS:
        raise ValueError(f"cli-help marker names an unknown command {name!r} (commands: {', '.join(COMMANDS)})")
    return _section(name)


def _section(command: str) -> str:
    return f"## `creep-online {command}`\n\n" + _block(_help(command))


def _block(text: str) -> str:
    return "```text\n" + text.rstrip() + "\n```"


def _help(command: str | None) -> str:
    """What ``creep-online [COMMAND] --help`` prints, at a fixed width."""
    from creep_online.cli import build_parser
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = COLUMNS
    try:
        parser = build_parser(only=command)
        if command is None:
            return parser.format_help()
        sub = next(a for a in parser._actions if a.dest == "command")   # argparse keeps sub-parsers here
        return sub.choices[command].format_help()
    finally:
        if saved is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved
