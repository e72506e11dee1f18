"""Progress on the terminal for runs that take a while (``identify``, ``fit``, ``diagnose``, ``compare``, ``batch``,
``demo``, a live ``stream``).

On a terminal: one status line on stderr, drawn by rich (``rich.live.Live``),
cut to the terminal's width (asked of the terminal, on every refresh, so a
resized window is followed), a spinner and the stage's elapsed time refreshed
in the background while a long fit runs, and erased when the work ends, so the
command's output starts clean. Elsewhere, when asked for (the demo's CI logs):
one plain line every few seconds. The commands show it only when stdout and
stderr are terminals and ``--json`` is off (``for_command``): scripts and pipes
see nothing but their output.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import TextIO

#: Refreshes per second on a terminal, and the period of plain lines elsewhere (s).
REFRESH_PER_SECOND = 4
PLAIN_PERIOD = 2.0


class Progress:
    """A status line: redrawn in place on a terminal (fitted to its width), one line every few seconds otherwise."""

    def __init__(self, enabled: bool, stream: TextIO | None = None, width: int | None = None) -> None:
        self.enabled = enabled
        self.width = width              # None: the terminal's, asked on every refresh
        self.stream = sys.stderr if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._text = ""
        self._stage_t0: float | None = None
        self._last_plain = 0.0
        self._live = None
        self._lock = threading.Lock()

    def show(self, text: str, force: bool = False) -> None:
        """Make ``text`` the status line (a plain line at most once per PLAIN_PERIOD unless ``force``)."""
        if not self.enabled:
            return
        with self._lock:
            self._text = text
        if self.tty:
            self._start()
        else:
            now = time.monotonic()
            if force or now - self._last_plain >= PLAIN_PERIOD:
                self._last_plain = now
                self.stream.write(text + "\n")
                self.stream.flush()

    def stage(self, text: str) -> None:
        """Start a named stage: shown at once; on a terminal its elapsed time follows it."""
        if not self.enabled:
            return
        self._stage_t0 = time.monotonic()
        self.show(text, force=True)

    def line(self) -> str:
        """The status line as drawn now: the text and, within a stage, its elapsed time."""
        with self._lock:
            text, t0 = self._text, self._stage_t0
        return text if t0 is None else f"{text} {time.monotonic() - t0:5.1f} s"

    def _start(self) -> None:
        """The live display, started on the first line (rich's own thread refreshes it)."""
        if self._live is not None:
            self._live.refresh()
            return
        from rich.console import Console
        from rich.live import Live
        console = Console(file=self.stream, force_terminal=True, highlight=False, soft_wrap=False, width=self.width)
        self._live = Live(_StatusLine(self), console=console, transient=True, auto_refresh=True,
                          refresh_per_second=REFRESH_PER_SECOND, redirect_stdout=False, redirect_stderr=False)
        self._live.start()

    def close(self) -> None:
        """Stop the refreshes and erase the line (a terminal) so the command's output starts clean."""
        if self._live is not None:
            self._live.stop()
            self._live = None

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _StatusLine:
    """The renderable the live display redraws: a spinner and ``Progress.line()``, one line cut to the width."""

    def __init__(self, progress: Progress) -> None:
        from rich.spinner import Spinner
        self.progress = progress
        self.spinner = Spinner("dots")

    def __rich_console__(self, console, options):
        from rich.text import Text
        line = Text.assemble(self.spinner.render(console.get_time()), " ", self.progress.line())
        line.no_wrap = True
        line.overflow = "ellipsis"
        line.truncate(options.max_width, overflow="ellipsis")
        yield line


def for_command(json_output: bool) -> Progress:
    """The commands' progress: on only when stdout and stderr are terminals and the output is not JSON."""
    def tty(stream) -> bool:
        return bool(getattr(stream, "isatty", lambda: False)())
    return Progress(tty(sys.stdout) and tty(sys.stderr) and not json_output)
