"""Reading a pseudo-terminal's master side in the tests that run the CLI on a real terminal."""
from __future__ import annotations

import math
import os
import select
import subprocess
import time


def read_until_closed(master: int, deadline: float = math.inf) -> bytes:
    """Everything the terminal shows until the child closes its side (EIO or EOF), or ``deadline`` (monotonic)."""
    chunks = []
    while time.monotonic() < deadline:
        try:
            data = os.read(master, 4096)
        except OSError:          # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    return b"".join(chunks)


def read_until_exit(master: int, proc: subprocess.Popen, timeout: float, idle: float = 0.5) -> bytes:
    """Everything the terminal shows until ``proc`` has exited and nothing more arrived for ``idle`` s (the
    caller keeps the slave side open, so no EIO can cut the tail short); at most ``timeout`` s."""
    chunks, deadline, last = [], time.monotonic() + timeout, time.monotonic()
    while time.monotonic() < deadline:
        if select.select([master], [], [], 0.05)[0]:
            chunks.append(os.read(master, 4096))
            last = time.monotonic()
        elif proc.poll() is not None and time.monotonic() - last >= idle:
            break
    proc.wait(timeout=max(deadline - time.monotonic(), 1.0))
    return b"".join(chunks)
