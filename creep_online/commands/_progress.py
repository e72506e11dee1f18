"""Progress on the terminal for runs that take a while (``diagnose``, ``fit``, ``identify``, ``demo``).

A status line on stderr: rewritten in place on a terminal, or one plain line
every few seconds when asked for on a non-terminal (the demo's CI logs). The
batch commands show it only when stdout is a terminal and ``--json`` is off
(``for_command``), so scripts and pipes see nothing but their output. While a
stage runs, a background ticker refreshes the elapsed time, so a single long
fit still shows that the program is alive; the line is erased when the work ends.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import TextIO

#: Default width of the status line (characters).
WIDTH = 100
#: Refresh period on a terminal and of plain lines elsewhere (s).
TTY_PERIOD = 0.25
PLAIN_PERIOD = 2.0


class Progress:
    """A status line: rewritten in place on a terminal, one line every few seconds otherwise."""

    def __init__(self, enabled: bool, stream: TextIO | None = None, width: int = WIDTH) -> None:
        self.enabled = enabled
        self.width = width
        self.stream = sys.stderr if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.period = TTY_PERIOD if self.tty else PLAIN_PERIOD
        self._last = 0.0
        self._lock = threading.Lock()
        self._text = ""
        self._stage_t0 = 0.0
        self._ticker: threading.Thread | None = None
        self._stop = threading.Event()

    def show(self, text: str, force: bool = False) -> None:
        """Make ``text`` the status line (written at most once per period unless ``force``)."""
        if not self.enabled:
            return
        self._text = text
        now = time.monotonic()
        if force or now - self._last >= self.period:
            self._write(text, now)

    def stage(self, text: str) -> None:
        """Start a named stage: shown at once; on a terminal a ticker then adds its elapsed time."""
        if not self.enabled:
            return
        self._stage_t0 = time.monotonic()
        self.show(text, force=True)
        if self.tty and self._ticker is None:
            self._ticker = threading.Thread(target=self._tick, name="progress", daemon=True)
            self._ticker.start()

    def _tick(self) -> None:
        while not self._stop.wait(self.period):
            now = time.monotonic()
            self._write(f"{self._text} {now - self._stage_t0:5.1f} s", now)

    def _write(self, text: str, now: float) -> None:
        with self._lock:
            self._last = now
            if self.tty:
                self.stream.write("\r" + text[:self.width].ljust(self.width))
            else:
                self.stream.write(text + "\n")
            self.stream.flush()

    def close(self) -> None:
        """Stop the ticker and erase the line (a terminal) so the command's output starts clean."""
        if not self.enabled:
            return
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
            self._ticker = None
        if self.tty:
            with self._lock:
                self.stream.write("\r" + " " * self.width + "\r")
                self.stream.flush()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def for_command(json_output: bool) -> Progress:
    """The batch commands' progress: on only when stdout and stderr are terminals and the output is not JSON."""
    def tty(stream) -> bool:
        return bool(getattr(stream, "isatty", lambda: False)())
    return Progress(tty(sys.stdout) and tty(sys.stderr) and not json_output)
