"""Stop signals as the command line takes them: Ctrl-C, SIGTERM and SIGHUP all end a run the same way.

A service manager (systemd, Docker, Kubernetes) stops a process with SIGTERM,
a closed terminal sends SIGHUP, a user presses Ctrl-C (SIGINT). Inside
``stop_signals()`` (the CLI's ``main``) each raises :class:`Interrupted`, a
``KeyboardInterrupt``, so every place that keeps the work done on Ctrl-C (a
stream printing its estimate, a batch writing its rows, a temporary file
removed) does the same for the other two. The exit status is 128 + the signal
number (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP), as a shell reports a process
killed by it. A signal whose disposition was "ignore" when the process
started (``nohup``, a background job) stays ignored.

``deferred()`` marks a short stretch that must not be cut (the final report
of a stream that has already stopped): a signal arriving within it is noted
and raised when it ends. ``flagged()`` turns the first signal into a flag the
code polls (the batch asks it between records) and only a second one raises.

Python runs a signal handler only between two bytecodes, so a stop signal
that arrives while a compiled kernel runs for minutes (a full-memory
simulation of a long record) would wait for it. A watchdog thread, woken by
the signal itself (``signal.set_wakeup_fd``), gives the handler
``GRACE_S`` seconds; past them it removes the temporary files in flight
(``temporary``), says so in one line and ends the process with the same
status.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterator

#: Seconds a stop signal may wait for Python to handle it before the watchdog ends the process.
GRACE_S = 3.0
#: How often the watchdog looks whether the handler has run while it waits.
POLL_S = 0.02

#: The signals that stop a run, and how the one-line message names them.
STOP_SIGNALS = {signal.SIGINT: "interrupted (Ctrl-C)", signal.SIGTERM: "terminated (SIGTERM)",
                signal.SIGHUP: "hung up (SIGHUP)"}


class Interrupted(KeyboardInterrupt):
    """A stop signal received: ``signum`` and the exit status it gives (128 + signum)."""

    def __init__(self, signum: int = signal.SIGINT, note: str = "") -> None:
        super().__init__(STOP_SIGNALS.get(signum, f"signal {signum}"))
        self.signum = int(signum)
        self.note = note                     # what the stop left undone, e.g. "before the first sample"

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    def __str__(self) -> str:
        name = STOP_SIGNALS.get(self.signum, f"signal {self.signum}")
        return f"{name} {self.note}" if self.note else name


def exit_code(exc: BaseException) -> int:
    """The exit status of a run ended by ``exc`` (a plain KeyboardInterrupt is Ctrl-C: 130)."""
    return exc.exit_code if isinstance(exc, Interrupted) else 128 + signal.SIGINT


def describe(exc: BaseException) -> str:
    """``interrupted (Ctrl-C)``, ``terminated (SIGTERM)``, ...: how a stop signal is named in messages."""
    return str(exc) if isinstance(exc, Interrupted) else STOP_SIGNALS[signal.SIGINT]


class _State:
    """What the handlers do now: raise (the default), note for later (``deferred``), or set a flag."""

    def __init__(self) -> None:
        self.mode = "raise"
        self.pending: int | None = None      # a signal noted while deferred or flagged
        self.count = 0                       # signals seen while flagged
        self.installed = False               # our handlers are in place (``stop_signals``)
        self.handled = 0                     # signals the Python handler has seen (the watchdog compares)
        self.temporary: set[str] = set()     # temporary files and folders in flight (``temporary``)


_state = _State()


def _handler(signum: int, frame: Any) -> None:
    _state.handled += 1
    if _state.mode == "raise":
        raise Interrupted(signum)
    if _state.mode == "flag":
        _state.count += 1
        if _state.count > 1:
            raise Interrupted(signum)
    if _state.pending is None:
        _state.pending = signum


@contextlib.contextmanager
def stop_signals() -> Iterator[None]:
    """Within: SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` (those not ignored); restored after.

    Off the main thread (a test runner's worker) signals cannot be handled here: nothing changes.
    """
    if _state.installed or threading.current_thread() is not threading.main_thread():
        yield
        return
    previous: dict[int, Any] = {}
    for signum in STOP_SIGNALS:
        current = signal.getsignal(signum)
        if current is signal.SIG_IGN or current is None:
            continue
        previous[signum] = current
        signal.signal(signum, _handler)
    _state.mode, _state.pending, _state.count, _state.installed = "raise", None, 0, True
    watchdog = _Watchdog() if previous else None
    try:
        yield
    finally:
        _state.installed = False
        if watchdog is not None:
            watchdog.stop()
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@contextlib.contextmanager
def temporary(path: str | Path) -> Iterator[None]:
    """Within: ``path`` (a temporary file or folder) is removed if the watchdog has to end the process."""
    key = str(path)
    _state.temporary.add(key)
    try:
        yield
    finally:
        _state.temporary.discard(key)


class _Watchdog:
    """Ends the process when a stop signal is not handled within GRACE_S (module docstring)."""

    def __init__(self) -> None:
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)
        try:
            self._previous_fd = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        except ValueError:           # (not the main thread: no watchdog)
            os.close(self._read)
            os.close(self._write)
            self._read = -1
            return
        self._thread = threading.Thread(target=self._watch, name="creep-online-signals", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        answered = _state.handled    # the Python handler's count when the signals read so far were answered
        while True:
            try:
                data = os.read(self._read, 64)
            except OSError:
                return
            if not data:
                return
            stops = [b for b in data if b in STOP_SIGNALS]
            if not stops:
                continue
            # The handler may already have run (the main thread is often faster than this thread to wake):
            # a count above ``answered`` is the answer, whenever it came.
            deadline = time.monotonic() + GRACE_S
            while _state.handled == answered and time.monotonic() < deadline:
                time.sleep(POLL_S)
            if _state.handled == answered and _state.installed:
                self._end(stops[0])
            answered = _state.handled

    @staticmethod
    def _end(signum: int) -> None:
        for path in list(_state.temporary):
            if os.path.isdir(path):
                shutil.rmtree(path, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    os.unlink(path)
        with contextlib.suppress(Exception):
            sys.stderr.write(f"creep-online: {STOP_SIGNALS[signum]} while busy in a computation: stopped now, "
                             f"nothing written\n")
            sys.stderr.flush()
        os._exit(128 + signum)

    def stop(self) -> None:
        if self._read < 0:
            return
        with contextlib.suppress(ValueError):
            signal.set_wakeup_fd(self._previous_fd)
        os.close(self._write)
        self._thread.join(1.0)
        os.close(self._read)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Within: a stop signal is noted, not raised; at the end the first one noted is raised."""
    with stop_signals():
        mode, _state.mode = _state.mode, "defer"
        try:
            yield
        finally:
            _state.mode = mode
            pending, _state.pending = _state.pending, None
        if pending is not None and mode == "raise":
            raise Interrupted(pending)


def pending_signal() -> int | None:
    """The stop signal noted (``deferred`` or ``flagged``) and not raised yet, if any."""
    return _state.pending


@contextlib.contextmanager
def flagged() -> Iterator[Callable[[], int | None]]:
    """Within: the first stop signal only sets a flag, read by the yielded function (its number, or None);
    a second one raises :class:`Interrupted` as usual."""
    with stop_signals():
        mode, count = _state.mode, _state.count
        _state.mode, _state.count, _state.pending = "flag", 0, None
        try:
            yield lambda: _state.pending
        finally:
            _state.mode, _state.count, _state.pending = mode, count, None
