"""Replay of a recorded CAN log (``.asc``, ``.blf``, ``.csv``, ... anything ``can.LogReader`` reads).

Frames are decoded exactly as on a live bus (DBC + cantools), so a log of a
faulty session reproduces the same counters. ``?realtime=1`` paces the replay
with the log's own timestamps (``can.MessageSync``); by default it runs as
fast as possible. A log carries counters, not a sample time: give ``?rate=HZ``.
"""
from __future__ import annotations

import itertools
from pathlib import Path

from ..errors import DataError
from .can_frames import COUNTER_MODULUS, CanDecoder
from .can_source import BATCH, _can
from .frames import RawSample
from .source_options import DBC, RATE, REALTIME, WINDOW
from .sources import SampleSource

#: Bytes scanned for the next object after a corrupt block of a .blf log.
BLF_SCAN = 1 << 24
#: Unreadable records in a row (no good one between) after which the rest of a log is taken as unreadable.
MAX_FAILURES_IN_A_ROW = 1000


class _HeaderFirst:
    """A text log file that yields a header line first (python-can's CSV reader skips one each time it starts
    reading), then the file's lines from where they stopped; everything else is the file's."""

    def __init__(self, file) -> None:
        self._file = file
        self._lines = itertools.chain(["timestamp,arbitration_id,extended,remote,error,dlc,data\n"], file)

    def __iter__(self):
        return self._lines

    def __next__(self) -> str:
        return next(self._lines)

    def __getattr__(self, name: str):
        return getattr(self._file, name)


def _resync_blf(reader) -> bool:
    """Move a BLF reader to the next object signature after a corrupt one (scanning at most ``BLF_SCAN`` bytes);
    False at the end of the file or when none is found.

    The block after a lost one may start with the end of an object that began in the lost one: its data are
    read from their first object signature on (python-can's reader expects one at the start).
    """
    reader._tail = b""
    if not getattr(reader, "_creep_resync", False):
        parse = reader._parse_container

        def parse_after_loss(data: bytes):
            if reader._creep_lost:
                reader._creep_lost = False
                found = data.find(b"LOBJ")
                data = data[found:] if found >= 0 else b""
            return parse(data)
        reader._parse_container = parse_after_loss
        reader._creep_resync = True
    reader._creep_lost = True
    fh = reader.file
    try:
        start = fh.tell()
        data = fh.read(BLF_SCAN)
    except (OSError, ValueError):
        return False
    found = data.find(b"LOBJ")
    if found < 0:
        return False
    fh.seek(start + found)
    return True


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
        self._failures_in_a_row = 0
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
            self._failures_in_a_row = 0
            if not msg.is_error_frame and not msg.is_remote_frame:
                out += decode(msg.arbitration_id, msg.data)
        return out

    def _skip_bad_record(self, exc: Exception) -> bool:
        """Count a record the log reader could not parse; True when reading can go on after it.

        Every format python-can reads line by line (.asc, .log, .csv, .trc) resumes at the next line; a binary
        .blf resumes at its next object (``_resync_blf``): the unreadable record (a line, or the rest of a
        compressed block) is counted in ``malformed`` and the replay goes on. Only a reader this does not
        know how to resume ends the replay there, with a message.
        """
        self.stats.parser.malformed += 1
        why = (str(exc).splitlines() or [type(exc).__name__])[0][:100]
        self._failures_in_a_row += 1
        if self._failures_in_a_row > MAX_FAILURES_IN_A_ROW:
            self.event(f"{self._failures_in_a_row} unreadable log records in a row ({why}); replay ends here")
            return False
        reader, can = self._reader, _can()
        if isinstance(reader, can.BLFReader):
            resumed = _resync_blf(reader)
        elif hasattr(reader, "_extract_header") and hasattr(reader, "file"):     # .asc: the header is read once
            reader._extract_header = lambda: None
            resumed = True
        elif isinstance(reader, can.CSVReader):   # its iterator skips a header line first: give it one
            reader.file = _HeaderFirst(reader.file)
            resumed = True
        else:                                     # .log, .trc: a new iterator reads on from the next line
            resumed = hasattr(reader, "file")
        if not resumed:
            self.event(f"unreadable log record ({why}); the rest of the log cannot be read, replay ends here")
            return False
        if self.stats.parser.malformed <= 3:
            self.event(f"unreadable log record skipped ({why})")
        self._iter = self._messages()
        return True

    def close(self) -> None:
        try:
            self._reader.stop()
        except Exception:  # noqa: BLE001 - closing a reader that failed half-way
            pass
        super().close()
