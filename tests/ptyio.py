"""Reading a pseudo-terminal's master side in the tests that run the CLI on a real terminal."""
from __future__ import annotations

import math
import os
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
