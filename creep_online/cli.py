"""The ``creep-online`` command line (DESIGN.md section 6).

Each sub-command lives in ``creep_online.commands.<name>`` and exposes
``register(subparsers)``, which adds its parser and sets ``func``. Any
CreepOnlineError becomes one line on stderr and exit code 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from .errors import CreepOnlineError

COMMANDS = ("identify", "simulate", "stream", "diagnose", "fit", "demo")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="creep-online",
        description="Identify the fractional-order creep model b / (s^alpha (1 + a1 s + a2 s^2)), batch or online.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"creep_online.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"creep_online.commands.{name}":
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 failed check, 2 bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CreepOnlineError as exc:
        print(f"creep-online {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader (e.g. `| head`) went away: not an error of ours
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"creep-online {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
