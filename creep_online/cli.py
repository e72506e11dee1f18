"""The ``creep-online`` command line (its stable keys and exit codes: docs/reference/json.md, docs/reference/exit-codes.md).

Each sub-command lives in ``creep_online.commands.<name>`` and exposes
``register(subparsers)``, which adds its parser and sets ``func``. Any
CreepOnlineError becomes one line on stderr and exit code 2, never a traceback;
so does a bad flag (argparse's usage block is replaced by one line). Ctrl-C,
SIGTERM and SIGHUP end any command the same way (``creep_online._signals``):
the work done is kept, one line says so, the exit status is 128 + the signal.
Everything printed goes through ``TerminalText``: control characters from a
file name or a header reach the terminal escaped, never raw.
"""
from __future__ import annotations

import argparse
import contextlib
import gc
import importlib
import json
import os
import signal
import sys
import warnings
from typing import Iterator, TextIO

from . import _signals
from .errors import CreepOnlineError, CreepOnlineWarning, one_line as _one_line, printable

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


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (``creep-online CMD: error: ...``) with exit status 2, or
    one JSON object on stderr when ``--json`` was asked for."""

    json_errors = False
    command = ""

    def error(self, message: str):  # type: ignore[override]
        if self.json_errors:
            _print_error({"command": self.command or None, "error": printable(message, keep_return=False),
                          "type": "UsageError", "exit_code": 2}, as_json=True)
            self.exit(2)
        self.exit(2, f"{self.prog}: error: {printable(message, keep_return=False)} (see {self.prog} --help)\n")


class TerminalText:
    """A text stream that writes control characters escaped (``errors.printable``): what a record's name or a
    CSV header holds is shown, never acted on by the terminal. Everything else is the wrapped stream's."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        #: the wrapped stream, for a writer whose own escape sequences must reach the terminal (the status
        #: line drawn by rich); what it writes of untrusted text it escapes itself
        self.unescaped = stream

    def write(self, text: str) -> int:
        self._stream.write(printable(text))
        return len(text)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _terminal_text() -> Iterator[None]:
    """sys.stdout and sys.stderr through ``TerminalText`` for the command's run."""
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = (s if s is None or isinstance(s, TerminalText) else TerminalText(s) for s in saved)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = saved


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser; with ``only``, just that command is imported and the others are listed by name."""
    parser = OneLineParser(
        prog="creep-online",
        description="Identify the fractional-order creep model b / (s^alpha (1 + a1 s + a2 s^2)), batch or online.")
    parser.add_argument("--version", action=_VersionAction)
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
    """showwarning replacement: every warning on one line (ours as they are, others with their kind and where
    they came from); ``CREEP_ONLINE_DEBUG=1`` shows the others as Python prints them."""
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, CreepOnlineWarning):
            print(f"creep-online {command}: warning: {_one_line(message)}", file=sys.stderr)
        elif os.environ.get("CREEP_ONLINE_DEBUG"):
            default(message, category, filename, lineno, file, line)
        else:
            print(f"creep-online {command}: warning: {category.__name__}: {_one_line(message)} "
                  f"({os.path.basename(str(filename))}:{lineno})", file=sys.stderr)
    return show


def _stop_inside(exc: BaseException) -> KeyboardInterrupt | None:
    """The stop signal an exception wraps: a signal handled while compiled code ran (a numba kernel) comes back
    as ``SystemError: ... returned a result with an exception set`` whose cause is the KeyboardInterrupt."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


class _VersionAction(argparse.Action):
    """``--version``: prints ``creep-online VERSION`` and exits. The version is looked up only then (the package
    metadata takes ~25 ms to import; every other command would pay for it)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="show program's version number and exit")

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print(f"creep-online {_version()}")
        parser.exit()


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
    """Entry point; returns the exit code (0 ok, 1 failed check, 2 bad input, 3 internal error, 128 + N ended
    by signal N: 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP).

    ``creep-online stream`` has its own codes for how a stream ended (see its --help). With ``--json``
    an error is one JSON object on stderr: {"command", "error", "type", "exit_code"}.
    """
    argv = sys.argv[1:] if argv is None else list(map(str, argv))
    command = _requested(argv) or "creep-online"
    OneLineParser.json_errors, OneLineParser.command = "--json" in argv, _requested(argv)
    as_json = running = False
    with _signals.stop_signals(), _terminal_text():
        try:
            parser = build_parser(only=_requested(argv))
            try:
                args = parser.parse_args(argv)
            except SystemExit as stop:     # --help, --version, or a bad flag (its one line already printed)
                return stop.code if isinstance(stop.code, int) else 2
            command = args.command
            as_json = bool(getattr(args, "json", False))
            with warnings.catch_warnings():
                warnings.showwarning = _warning_printer(args.command)
                running = True
                return int(args.func(args) or 0)
        except CreepOnlineError as exc:
            _print_error({"command": command, "error": _one_line(exc), "type": type(exc).__name__,
                          "exit_code": 2}, as_json)
            return 2
        except BrokenPipeError:
            # the reader (e.g. `| head`) went away: not an error of ours
            _quietly(sys.stderr.close)
            return 0
        except KeyboardInterrupt as exc:    # Ctrl-C, SIGTERM, SIGHUP (``_signals.Interrupted``)
            said = f"creep-online {command}: {_signals.describe(exc)}" + ("" if running else " while starting")
            _quietly(lambda: print(said, file=sys.stderr))
            return _signals.exit_code(exc)
        except Exception as exc:  # noqa: BLE001 - a bug of ours: one line, not a traceback
            stop = _stop_inside(exc)
            if stop is not None:            # a signal raised inside compiled code, wrapped (numba: SystemError)
                said = f"creep-online {command}: {_signals.describe(stop)}"
                _quietly(lambda: print(said, file=sys.stderr))
                return _signals.exit_code(stop)
            if os.environ.get("CREEP_ONLINE_DEBUG"):
                raise
            _print_error({"command": command, "error": f"{type(exc).__name__}: {_one_line(exc)} (please report "
                          "it; CREEP_ONLINE_DEBUG=1 shows the traceback)", "type": type(exc).__name__,
                          "exit_code": 3}, as_json)
            return 3


def console() -> None:
    """The ``creep-online`` program (and ``python -m creep_online``): ``main`` with its status as the exit code.

    After the command has returned, the interpreter still shuts down (Dask's
    cluster, threads, buffered output); a Ctrl-C then used to end the process
    by the signal with no word (seen after ``batch``). From that point a Ctrl-C
    flushes the output, says in one line that the command had ended and with
    which status, and exits with 130 (SIGTERM and SIGHUP alike, with their
    own status). A process started with a signal ignored keeps it ignored.
    """
    code = 130
    try:
        code = main()
        for signum in _signals.STOP_SIGNALS:
            if signal.getsignal(signum) is not signal.SIG_IGN:
                signal.signal(signum, _interrupted_while_exiting(code))
    except KeyboardInterrupt as exc:   # (between main's handlers and these: a few microseconds)
        _interrupted_while_exiting(code)(_signals.exit_code(exc) - 128, None)
    _skip_final_collections()
    sys.exit(code)


def _skip_final_collections() -> None:
    """Keep the interpreter's shutdown from walking every object numba, llvmlite and scipy created.

    Shutting down runs the cyclic garbage collector over all live objects several times; after numba has
    loaded a kernel that is ~0.1 s of CPU (a sixth of a cold ``identify``) spent freeing memory the
    operating system takes back anyway. Frozen objects are skipped by those passes. Everything else
    about the shutdown stays: atexit handlers (Dask's cluster, logging), the flush of stdout and stderr,
    and the finalizers of objects freed by reference counting. Only objects in reference cycles are no
    longer finalized, which Python never promised at exit; the commands close their files themselves.
    """
    gc.freeze()


def _interrupted_while_exiting(code: int):
    """A stop-signal handler for the interpreter's shutdown after the command ended with ``code``."""
    def handler(signum, frame) -> None:
        _quietly(sys.stdout.flush)
        what = "interrupted" if signum == signal.SIGINT else _signals.STOP_SIGNALS.get(signum, "stopped")
        _quietly(lambda: print(f"creep-online: {what} while exiting (the "
                               f"command had ended, exit status {code})", file=sys.stderr, flush=True))
        os._exit(128 + signum)
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
