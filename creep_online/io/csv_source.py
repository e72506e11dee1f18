"""``csv:FILE``: a ``t,u,y`` file (or a PI GCS data-recorder file) replayed as a sample stream.

The sequence number is the row index. The file is read and checked whole by
``creep_online.io.csvfile.load_record``
(the same rules and one-line errors as ``identify``), then handed out in
chunks, or paced at the file's own step with ``?realtime=1``.
"""
from __future__ import annotations

import time

from ..record import check_amplitudes, check_time_and_output
from .frames import RawSample
from .source_options import REALTIME, STALL, WINDOW, Option, nonempty
from .sources import SampleSource


class CsvSource(SampleSource):
    """A ``t,u,y`` CSV file as a stream (sequence = row index), optionally paced in real time."""

    options = (REALTIME, WINDOW, STALL,
               Option("u_column", nonempty, None, "input column (CSV header name or GCS NAMEi)"),
               Option("y_column", nonempty, None, "output column (CSV header name or GCS NAMEi)"))
    target_label = "file"
    target_is_file = True

    def __init__(self, path: str, *, realtime: bool = False, chunk: int = 1000,
                 u_column: str | None = None, y_column: str | None = None, **kw) -> None:
        from .csvfile import load_record
        super().__init__(**kw)
        self.name = f"csv:{path}"
        rec = load_record(path, u_column, y_column)
        check_time_and_output(rec.t, rec.y, rec.source)   # (a replay of a record identify refuses is refused)
        check_amplitudes(rec.u, rec.y, rec.source)
        self.record = rec
        self.rate = 1.0 / rec.h if rec.h > 0 else None
        self._i = 0
        self._chunk = int(chunk)
        self._realtime = realtime
        self._t0 = time.monotonic()

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        rec, i = self.record, self._i
        if i >= len(rec):
            return None
        stop = min(i + self._chunk, len(rec))
        if self._realtime:
            due = int((time.monotonic() - self._t0) / rec.h) + 1
            stop = min(stop, max(due, i))
            if stop == i:
                time.sleep(min(timeout, rec.h))
                return []
        out = [RawSample(k, float(rec.t[k]), float(rec.u[k]), float(rec.y[k]), 0) for k in range(i, stop)]
        self._i = stop
        return out
