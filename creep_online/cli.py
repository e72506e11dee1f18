"""The ``creep-online`` command line (its stable keys and exit codes: README.md, docs/reliability.md).

Each sub-command lives in ``creep_online.commands.<name>`` and exposes
``register(subparsers)``, which adds its parser and sets ``func``. Any
CreepOnlineError becomes one line on stderr and exit code 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import warnings

from .errors import CreepOnlineError, CreepOnlineWarning, one_line as _one_line

COMMANDS = ("identify", "simulate", "stream", "diagnose", "fit", "compare", "demo", "batch")
#: One-line help of each command for the top-level listing, so that ``--help`` imports no command
#: (their modules load scipy and numba); tests check they match what the commands register.
SUMMARIES = {
    "identify": "identify alpha, a1, a2, b from a t,u,y CSV (two-layer TRF)",
    "simulate": "simulate the model for the input of a t,u CSV",
    "stream": "run the online estimator on a stream (csv:FILE, serial:PORT, can:..., canlog:FILE, pi:PORT)",
    "diagnose": "find which catalogue effect the creep model is missing",
    "fit": "fit the creep model extended by catalogue effects",
    "compare": "fit percent and residual of a saved model on a record",
    "demo": "stream the simulated plant over a pty and identify it live",
    "batch": "identify a fleet of records (folder, glob or long id,t,u,y CSV) on Dask",
}


class _Parser(argparse.ArgumentParser):
    """argparse with its usage errors as one JSON line on stderr when ``--json`` was asked for (exit 2)."""

    json_errors = False
    command = ""

    def error(self, message: str):
        if self.json_errors:
            _print_error({"command": self.command or None, "error": message, "type": "UsageError",
                          "exit_code": 2}, as_json=True)
            sys.exit(2)
        super().error(message)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser; with ``only``, just that command is imported and the others are listed by name."""
    parser = _Parser(
        prog="creep-online",
        description="Identify the fractional-order creep model b / (s^alpha (1 + a1 s + a2 s^2)), batch or online.")
    parser.add_argument("--version", action="version", version=f"creep-online {_version()}")
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


def _version() -> str:
    """The installed creep_online's version (the package's own when it is not installed)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("creep_online")
    except PackageNotFoundError:
        from . import __version__
        return __version__


def _print_error(error: dict, as_json: bool) -> None:
    """One line on stderr: ``creep-online CMD: error: MESSAGE``, or (``--json``) the error as one JSON object."""
    if as_json:
        print(json.dumps(error), file=sys.stderr)
    else:
        kind = "internal error" if error["exit_code"] == 3 else "error"
        print(f"creep-online {error['command']}: {kind}: {error['error']}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 failed check, 2 bad input, 3 internal error).

    ``creep-online stream`` has its own codes for how a stream ended (see its --help). With ``--json``
    an error is one JSON object on stderr: {"command", "error", "type", "exit_code"}.
    """
    argv = sys.argv[1:] if argv is None else list(map(str, argv))
    _Parser.json_errors, _Parser.command = "--json" in argv, _requested(argv)
    parser = build_parser(only=_requested(argv))
    args = parser.parse_args(argv)
    as_json = bool(getattr(args, "json", False))
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _warning_printer(args.command)
            return int(args.func(args) or 0)
    except CreepOnlineError as exc:
        _print_error({"command": args.command, "error": _one_line(exc), "type": type(exc).__name__,
                      "exit_code": 2}, as_json)
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
        _print_error({"command": args.command, "error": f"{type(exc).__name__}: {_one_line(exc)} (please report it; "
                      "CREEP_ONLINE_DEBUG=1 shows the traceback)", "type": type(exc).__name__, "exit_code": 3},
                     as_json)
        return 3


def console() -> None:
    """The ``creep-online`` program (and ``python -m creep_online``): ``main`` with its status as the exit code.

    After the command has returned, the interpreter still shuts down (Dask's
    cluster, threads, buffered output); a Ctrl-C then used to end the process
    by the signal with no word (seen after ``batch``). From that point a Ctrl-C
    flushes the output, says in one line that the command had ended and with
    which status, and exits with 130. A process started with Ctrl-C ignored
    keeps it ignored.
    """
    code = main()
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, _interrupted_while_exiting(code))
    sys.exit(code)


def _interrupted_while_exiting(code: int):
    """A SIGINT handler for the interpreter's shutdown after the command ended with ``code``."""
    def handler(signum, frame) -> None:
        _quietly(sys.stdout.flush)
        _quietly(lambda: print(f"creep-online: interrupted while exiting (the command had ended, exit status "
                               f"{code})", file=sys.stderr, flush=True))
        os._exit(130)
    return handler


def _quietly(write) -> None:
    """Run ``write``; a closed or vanished stream has nothing more to say."""
    try:
        write()
    except (OSError, ValueError, AttributeError):
        pass


def _requested(argv: list[str]) -> str:
    """The command named on the command line ('' when none: only the top-level listing is needed)."""
    for arg in argv:
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else ""
    return ""


if __name__ == "__main__":
    console()
