"""The ``creep-online`` command line (its stable keys and exit codes: README.md, docs/reliability.md).

Each sub-command lives in ``creep_online.commands.<name>`` and exposes
``register(subparsers)``, which adds its parser and sets ``func``. Any
CreepOnlineError becomes one line on stderr and exit code 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

from .errors import CreepOnlineError, CreepOnlineWarning, one_line as _one_line

COMMANDS = ("identify", "simulate", "stream", "diagnose", "fit", "demo", "batch")
#: One-line help of each command for the top-level listing, so that ``--help`` imports no command
#: (their modules load scipy and numba); tests check they match what the commands register.
SUMMARIES = {
    "identify": "identify alpha, a1, a2, b from a t,u,y CSV (two-layer TRF)",
    "simulate": "simulate the model for the input of a t,u CSV",
    "stream": "run the online estimator on a stream (csv:FILE, serial:PORT, can:..., canlog:FILE, pi:PORT)",
    "diagnose": "find which catalogue effect the creep model is missing",
    "fit": "fit the creep model extended by catalogue effects",
    "demo": "stream the simulated plant over a pty and identify it live",
    "batch": "identify a fleet of records (folder, glob or long id,t,u,y CSV) on Dask",
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser; with ``only``, just that command is imported and the others are listed by name."""
    parser = argparse.ArgumentParser(
        prog="creep-online",
        description="Identify the fractional-order creep model b / (s^alpha (1 + a1 s + a2 s^2)), batch or online.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        if only is not None and name != only:
            sub.add_parser(name, help=SUMMARIES[name])
            continue
        try:
            module = importlib.import_module(f"creep_online.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"creep_online.commands.{name}":
                raise
            continue
        module.register(sub)
    return parser


def _warning_printer(command: str):
    """showwarning replacement: our warnings as one line, anything else as Python prints it."""
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, CreepOnlineWarning):
            print(f"creep-online {command}: warning: {message}", file=sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)
    return show


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 failed check, 2 bad input, 3 internal error).

    ``creep-online stream`` has its own codes for how a stream ended (see its --help).
    """
    parser = build_parser(only=_requested(sys.argv[1:] if argv is None else argv))
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _warning_printer(args.command)
            return int(args.func(args) or 0)
    except CreepOnlineError as exc:
        print(f"creep-online {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader (e.g. `| head`) went away: not an error of ours
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"creep-online {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - a bug of ours: one line, not a traceback
        if os.environ.get("CREEP_ONLINE_DEBUG"):
            raise
        print(f"creep-online {args.command}: internal error: {type(exc).__name__}: {_one_line(exc)} "
              f"(please report it; CREEP_ONLINE_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 3


def _requested(argv: list[str]) -> str:
    """The command named on the command line ('' when none: only the top-level listing is needed)."""
    for arg in argv:
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else ""
    return ""


if __name__ == "__main__":
    sys.exit(main())
