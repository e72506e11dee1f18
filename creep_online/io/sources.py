"""Live and recorded sample sources behind one interface: ``open_source(spec)``.

Specs (DESIGN.md section 6/7)::

    csv:FILE                       a t,u,y file, replayed sample by sample
    serial:PORT_OR_URL             /dev/ttyUSB0, /dev/pts/N, socket://host:port, loop://
    can:slcan:PORT                 SLCAN adapter (or the simulated plant's pty)
    can:virtual:CHANNEL            python-can's in-process virtual bus
    can:<interface>:<channel>      any other python-can interface (socketcan:can0, pcan:PCAN_USBBUS1, ...)
    canlog:FILE                    replay of a .asc / .blf / .csv CAN log

Options follow a ``?`` as ``key=value`` pairs joined by ``&`` (or are passed
as keyword arguments): ``format=auto|ascii|binary``, ``rate=HZ`` (binary and
CAN frames carry a counter, not a time), ``baud=N``, ``reconnect=0|1``,
``reconnect_timeout=S``, ``stall=S``, ``window=N`` (reorder window),
``start=TEXT`` (bytes sent after opening, e.g. to start a recorder),
``dbc=FILE``, ``bitrate=N``, ``fd=0|1``.

Every source yields :class:`Sample` objects in sequence order; everything that
was not a good sample is counted in :class:`SourceStats` and never delivered.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Iterator, NamedTuple
from urllib.parse import parse_qsl

from ..errors import CreepOnlineError, DataError
from .frames import ParserStats, RawSample
from .sequence import SequenceStats, SequenceTracker


class TransportError(CreepOnlineError):
    """A source could not be opened or was lost for good (one-line message)."""


class Sample(NamedTuple):
    """One good sample: sequence number, time (s), input, output, amplifier status."""

    seq: int
    t: float
    u: float
    y: float
    status: int = 0
    t_rx: float = 0.0   # host time.monotonic() when the sample was decoded


@dataclass
class SourceStats:
    """Everything a source counted: frames, corruption, order, link events."""

    parser: ParserStats = field(default_factory=ParserStats)
    sequence: SequenceStats = field(default_factory=SequenceStats)
    disconnects: int = 0
    reconnects: int = 0
    stalls: int = 0
    events: list = field(default_factory=list)

    # flat read-only views of the most used counters
    @property
    def samples(self) -> int:
        return self.sequence.delivered

    @property
    def missing(self) -> int:
        return self.sequence.missing

    @property
    def crc_errors(self) -> int:
        return self.parser.crc_errors

    @property
    def bad_frames(self) -> int:
        return self.parser.crc_errors + self.parser.malformed

    def as_dict(self) -> dict:
        """Flat JSON-ready dict of every counter (plus the last few link events)."""
        d: dict = {"samples": self.samples}
        d.update({k: v for k, v in self.parser.as_dict().items()})
        d.update({k: v for k, v in self.sequence.as_dict().items() if k != "delivered"})
        d.update(disconnects=self.disconnects, reconnects=self.reconnects, stalls=self.stalls)
        d["events"] = list(self.events[-20:])
        return d

    def summary(self) -> str:
        """One line for a status display."""
        p, s = self.parser, self.sequence
        return (f"{s.delivered} samples; lost {s.missing} in {s.gaps} gap(s), dup {s.duplicates}, "
                f"reordered {s.reordered}, late {s.late}; crc {p.crc_errors}, malformed {p.malformed}, "
                f"garbage {p.garbage_bytes} B; disconnects {self.disconnects}, stalls {self.stalls}")


def _stderr_event(msg: str) -> None:
    print(f"creep-online: {msg}", file=sys.stderr, flush=True)


class SampleSource:
    """Base class: turns raw decoded frames into ordered, accounted samples.

    Subclasses implement ``_read_raw(timeout) -> list[RawSample] | None``
    (``None`` = the stream ended for good) and may override ``close``.
    ``t_from_seq`` sources (binary, CAN) derive time from the unwrapped counter.
    """

    name = "source"

    def __init__(self, *, window: int = 16, modulus: int | None = None, rate: float | None = None,
                 t_from_seq: bool = False, stall: float = 0.5,
                 on_event: Callable[[str], None] | None = _stderr_event) -> None:
        self.stats = SourceStats()
        self.tracker: SequenceTracker = SequenceTracker(window=window, modulus=modulus,
                                                        stats=self.stats.sequence)
        self.rate = rate
        self.t_from_seq = t_from_seq
        self.stall_s = float(stall)
        self.on_event = on_event
        self.ended = False
        self._last_data: float | None = None   # no stall before the first data
        self._in_stall = False
        self._dt_est: float | None = None
        self._first_t: tuple[int, float] | None = None

    # -------------------------------------------------------------- events
    def event(self, msg: str) -> None:
        self.stats.events.append(f"{time.strftime('%H:%M:%S')} {msg}")
        if self.on_event is not None:
            self.on_event(f"{self.name}: {msg}")

    # -------------------------------------------------------------- reading
    def _read_raw(self, timeout: float) -> list[RawSample] | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def read(self, timeout: float = 0.1) -> list[Sample]:
        """Good samples available within ``timeout`` seconds (possibly none), in order."""
        if self.ended:
            return []
        raw = self._read_raw(timeout)
        now = time.monotonic()
        if raw is None:
            self.ended = True
            return self._deliver(self.tracker.flush(), now)
        if raw:
            self._last_data = now
            self._in_stall = False
            out: list[tuple[int, RawSample]] = []
            push = self.tracker.push
            for r in raw:
                out += push(r.seq, r)
            return self._deliver(out, now)
        if (not self._in_stall and self._last_data is not None and self.link_up
                and now - self._last_data > self.stall_s):
            self._in_stall = True
            self.stats.stalls += 1
            self.event(f"no data for {now - self._last_data:.2f} s (stall)")
            return self._deliver(self.tracker.flush(), now)
        return []

    @property
    def link_up(self) -> bool:
        """False while a lost port is being reopened (no stall is counted then)."""
        return True

    def _deliver(self, pairs: list[tuple[int, RawSample]], now: float) -> list[Sample]:
        if not pairs:
            return []
        if self.t_from_seq:
            dt = 1.0 / self.rate if self.rate else 1.0
            return [Sample(s, s * dt, r.u, r.y, r.status, now) for s, r in pairs]
        if self._dt_est is None:
            self._estimate_dt(pairs)
        return [Sample(s, r.t, r.u, r.y, r.status, now) for s, r in pairs]

    def _estimate_dt(self, pairs: list[tuple[int, RawSample]]) -> None:
        if self._first_t is None:
            self._first_t = (pairs[0][0], pairs[0][1].t)
        s0, t0 = self._first_t
        s1, r1 = pairs[-1]
        if s1 > s0 and r1.t > t0:
            self._dt_est = (r1.t - t0) / (s1 - s0)

    def __iter__(self) -> Iterator[Sample]:
        while not self.ended:
            yield from self.read(0.1)

    def close(self) -> None:
        self.ended = True

    def __enter__(self) -> "SampleSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def dt(self) -> float | None:
        """Sampling step (s) when known (rate option or ASCII time stamps)."""
        if self.rate:
            return 1.0 / self.rate
        return self._dt_est


# ------------------------------------------------------------------ CSV replay
class ReconnectingSource(SampleSource):
    """A source over a link that can disappear (a serial port, a CAN adapter).

    On loss it says so once and reopens with backoff (50 ms doubling to 2 s)
    for at most ``reconnect_timeout`` seconds, or raises at once when
    ``reconnect`` is off. Subclasses implement ``_open()`` and ``_close_link()``.
    """

    link = "link"  # what the messages call it

    def __init__(self, *, reconnect: bool = True, reconnect_timeout: float | None = None, **kw) -> None:
        super().__init__(**kw)
        self.reconnect = bool(reconnect)
        self.reconnect_timeout = reconnect_timeout
        self._down_since: float | None = None
        self._next_try = 0.0
        self._backoff = 0.05

    def _open(self) -> None:
        raise NotImplementedError

    def _close_link(self) -> None:
        raise NotImplementedError

    def _lost(self, why: str) -> None:
        self._close_link()
        self.stats.disconnects += 1
        if not self.reconnect:
            self.event(f"{self.link} disappeared ({why}); not reconnecting")
            raise TransportError(f"{self.name}: {self.link} disappeared ({why}); reconnect is off")
        self.event(f"{self.link} disappeared ({why}); reconnecting with backoff")
        self._down_since = time.monotonic()
        self._next_try = self._down_since + 0.05
        self._backoff = 0.05

    def _try_reconnect(self, timeout: float) -> bool:
        """One reopening attempt if it is due; True when the link is back."""
        now = time.monotonic()
        if self.reconnect_timeout is not None and now - self._down_since > self.reconnect_timeout:
            raise TransportError(f"{self.name}: {self.link} did not come back within {self.reconnect_timeout:g} s")
        if now < self._next_try:
            time.sleep(min(timeout, self._next_try - now))
            return False
        try:
            self._open()
        except Exception:  # noqa: BLE001 - any failure to open means: not back yet
            self._backoff = min(self._backoff * 2, 2.0)
            self._next_try = time.monotonic() + self._backoff
            return False
        self.stats.reconnects += 1
        self.tracker.expect_restart()
        self.event(f"reconnected after {time.monotonic() - self._down_since:.2f} s")
        self._down_since = None
        return True


class CsvSource(SampleSource):
    """A ``t,u,y`` CSV file as a stream (sequence = row index), optionally paced in real time."""

    def __init__(self, path: str, *, realtime: bool = False, chunk: int = 1000, **kw) -> None:
        from .csvfile import load_csv
        super().__init__(**kw)
        self.name = f"csv:{path}"
        rec = load_csv(path)
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


# ------------------------------------------------------------------ spec parsing
#: Options understood by open_source; anything else stays in a pyserial URL.
KNOWN_OPTIONS = {"format", "rate", "baud", "reconnect", "reconnect_timeout", "stall", "window",
                 "start", "dbc", "bitrate", "fd", "checksum", "scale_u", "scale_y", "realtime",
                 "frame"}


def split_options(rest: str) -> tuple[str, dict[str, str]]:
    """``PORT?k=v&k2=v2`` -> (PORT, {k: v}); unknown keys stay in the port string."""
    if "?" not in rest:
        return rest, {}
    base, query = rest.split("?", 1)
    ours: dict[str, str] = {}
    theirs: list[str] = []
    for k, v in parse_qsl(query, keep_blank_values=True):
        if k in KNOWN_OPTIONS:
            ours[k] = v
        else:
            theirs.append(f"{k}={v}" if v else k)
    port = base + ("?" + "&".join(theirs) if theirs else "")
    return port, ours


_CONVERT = {"rate": float, "baud": int, "reconnect": lambda v: v.lower() not in ("0", "false", "no", "off"),
            "reconnect_timeout": float, "stall": float, "window": int, "bitrate": int,
            "fd": lambda v: v.lower() not in ("0", "false", "no", "off"),
            "realtime": lambda v: v.lower() not in ("0", "false", "no", "off"),
            "scale_u": float, "scale_y": float}


def _convert(spec: str, opts: dict[str, str]) -> dict:
    out: dict = {}
    for k, v in opts.items():
        try:
            out[k] = _CONVERT.get(k, str)(v)
        except ValueError:
            raise DataError(f"{spec}: option {k}={v!r} is not valid") from None
    if "baud" in out:
        out["baudrate"] = out.pop("baud")
    return out


def open_source(spec: str, **options) -> SampleSource:
    """Open a sample source from a spec string (see the module docstring)."""
    if ":" not in spec:
        raise DataError(f"{spec!r}: not a source spec (use csv:FILE, serial:PORT, can:IFACE:CHANNEL or canlog:FILE)")
    kind, rest = spec.split(":", 1)
    kind = kind.lower()
    target, opts = split_options(rest)
    kw = {**_convert(spec, opts), **options}
    if not target:
        raise DataError(f"{spec!r}: missing {'file' if kind in ('csv', 'canlog') else 'port'} after '{kind}:'")
    if kind == "csv":
        allowed = {"realtime", "window", "stall", "on_event", "chunk"}
        return CsvSource(target, **{k: v for k, v in kw.items() if k in allowed})
    if kind == "serial":
        from .serial_source import SerialSource
        return SerialSource(target, **kw)
    if kind == "can":
        if ":" not in target:
            raise DataError(f"{spec!r}: CAN spec needs an interface and a channel, e.g. can:slcan:/dev/ttyACM0")
        interface, channel = target.split(":", 1)
        from .can_source import CanSource
        return CanSource(interface, channel, **kw)
    if kind == "canlog":
        from .canlog_source import CanLogSource
        return CanLogSource(target, **kw)
    raise DataError(f"{spec!r}: unknown source kind {kind!r} (csv, serial, can, canlog)")
