"""Replay of a recorded CAN log (``.asc``, ``.blf``, ``.csv``, ... anything ``can.LogReader`` reads).

Frames are decoded exactly as on a live bus (DBC + cantools), so a log of a
faulty session reproduces the same counters. ``?realtime=1`` paces the replay
with the log's own timestamps (``can.MessageSync``); by default it runs as
fast as possible. A log carries counters, not a sample time: give ``?rate=HZ``.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import DataError
from .can_frames import COUNTER_MODULUS, CanDecoder
from .can_source import BATCH, _can
from .frames import RawSample
from .source_options import DBC, RATE, REALTIME, WINDOW
from .sources import SampleSource


class CanLogSource(SampleSource):
    """Samples decoded from a CAN log file (``canlog:FILE?rate=10000``); a file cannot stall."""

    options = (RATE, DBC, REALTIME, WINDOW.with_default(32))
    target_label = "file"
    target_is_file = True

    def __init__(self, path: str, *, rate: float | None = None, dbc: str | None = None, realtime: bool = False,
                 window: int = 32, stall: float = 0.5, **kw) -> None:
        super().__init__(window=window, modulus=COUNTER_MODULUS, rate=rate, t_from_seq=True,
                         stall=stall, **kw)
        self.name = f"canlog:{path}"
        p = Path(path)
        if not p.is_file():
            raise DataError(f"{path}: no such CAN log file")
        if not rate:
            raise DataError(f"{self.name}: CAN frames carry a counter, not a time: give the sample rate, "
                            f"e.g. canlog:{path}?rate=10000")
        can = _can()
        try:
            reader = can.LogReader(str(p))
        except Exception as exc:  # noqa: BLE001 - unknown suffix, unreadable file, ...
            raise DataError(f"{path}: cannot read as a CAN log ({str(exc).splitlines()[0][:100]})") from None
        self._reader = reader
        self._realtime = realtime
        self._iter = self._messages()
        self.decoder = CanDecoder(dbc, stats=self.stats.parser)
        self.stall_s = float("inf")   # a file cannot stall

    def _messages(self):
        can = _can()
        return iter(can.MessageSync(self._reader, timestamps=True) if self._realtime else self._reader)

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        out: list[RawSample] = []
        decode = self.decoder.decode
        for _ in range(BATCH):
            try:
                msg = next(self._iter, None)
            except Exception as exc:  # noqa: BLE001 - a corrupt log line or block
                if not self._skip_bad_record(exc):
                    return out if out else None
                continue
            if msg is None:
                return out if out else None
            if not msg.is_error_frame and not msg.is_remote_frame:
                out += decode(msg.arbitration_id, msg.data)
        return out

    def _skip_bad_record(self, exc: Exception) -> bool:
        """Count a record the log reader could not parse; True when reading can go on after it.

        Text logs (.asc) resume at the next line (the header is not read again).
        A corrupt block of a binary log ends the replay there, with a message.
        """
        self.stats.parser.malformed += 1
        why = (str(exc).splitlines() or [type(exc).__name__])[0][:100]
        if hasattr(self._reader, "_extract_header") and hasattr(self._reader, "file"):
            if self.stats.parser.malformed <= 3:
                self.event(f"unreadable log record skipped ({why})")
            self._reader._extract_header = lambda: None   # resume after the bad line, header already read
            self._iter = self._messages()
            return True
        self.event(f"unreadable log record ({why}); the rest of the log cannot be read, replay ends here")
        return False

    def close(self) -> None:
        try:
            self._reader.stop()
        except Exception:  # noqa: BLE001 - closing a reader that failed half-way
            pass
        super().close()
