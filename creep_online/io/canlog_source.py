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
from .sources import SampleSource


class CanLogSource(SampleSource):
    def __init__(self, path: str, *, rate: float | None = None, dbc: str | None = None, realtime: bool = False,
                 window: int = 32, stall: float = 0.5, **kw) -> None:
        for k in ("format", "start", "reconnect", "reconnect_timeout", "bitrate", "fd"):
            kw.pop(k, None)
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
        self._iter = iter(can.MessageSync(reader, timestamps=True) if realtime else reader)
        self.decoder = CanDecoder(dbc, stats=self.stats.parser)
        self.stall_s = float("inf")   # a file cannot stall

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        out: list[RawSample] = []
        decode = self.decoder.decode
        try:
            for _ in range(BATCH):
                msg = next(self._iter, None)
                if msg is None:
                    return out if out else None
                if not msg.is_error_frame and not msg.is_remote_frame:
                    out += decode(msg.arbitration_id, msg.data)
        except Exception as exc:  # noqa: BLE001 - a corrupt log line or block
            raise DataError(f"{self.name}: unreadable log record ({str(exc).splitlines()[0][:100]})") from None
        return out

    def close(self) -> None:
        try:
            self._reader.stop()
        except Exception:  # noqa: BLE001 - closing a reader that failed half-way
            pass
        super().close()
