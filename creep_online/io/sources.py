"""The source contract: every live or recorded stream yields ordered, accounted :class:`Sample` objects.

A source is a :class:`SampleSource` subclass that implements
``_read_raw(timeout)`` and declares the ``?key=value`` options its spec takes
(``options``, see ``source_options.Option``); :class:`ReconnectingSource` adds
reopening a lost link with backoff. Which class opens which spec kind
(``csv:``, ``serial:``, ``can:``, ``canlog:`` or a plug-in's) is decided by
``creep_online.io.registry``; this module imports none of the concrete
sources. The kinds, options and how to add one: docs/transports.md.

Every source yields :class:`Sample` objects in sequence order; everything that
was not a good sample is counted in :class:`SourceStats` and never delivered.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Iterator, NamedTuple

from ..checks import count, positive
from ..errors import TransportError
from .frames import ParserStats, RawSample
from .sequence import SequenceStats, SequenceTracker
from .source_options import (IDLE_TIMEOUT, IDLE_TIMEOUT_S, OPTION_MAX, RECONNECT, RECONNECT_TIMEOUT, RECONNECT_TIMEOUT_S, STALL,
                             WINDOW, Option)

__all__ = ["Sample", "SourceStats", "SampleSource", "ReconnectingSource", "TransportError", "open_source"]


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

    What a spec ``KIND:TARGET?key=value`` may say is declared on the class:
    ``options`` (the keys, converted and passed as constructor keywords),
    ``target_label`` (what TARGET is, for messages), ``keeps_unknown_options``
    (unknown keys stay in TARGET instead of being refused) and ``from_spec``
    (how TARGET becomes constructor arguments).
    """

    name = "source"
    options: ClassVar[tuple[Option, ...]] = (WINDOW, STALL)
    target_label: ClassVar[str] = "target"
    target_is_file: ClassVar[bool] = False     # TARGET names a file the source reads (csv:, canlog:)
    keeps_unknown_options: ClassVar[bool] = False

    @classmethod
    def from_spec(cls, spec: str, target: str, **kwargs: Any) -> "SampleSource":
        """Open the source named by ``target`` (the spec after ``KIND:``, options removed)."""
        return cls(target, **kwargs)

    def __init__(self, *, window: int = 16, modulus: int | None = None, rate: float | None = None,
                 t_from_seq: bool = False, stall: float = 0.5,
                 on_event: Callable[[str], None] | None = _stderr_event) -> None:
        window = count(window, "window (reorder window, samples)", minimum=0, maximum=1 << 20)
        stall = positive(stall, "stall (s of silence)", maximum=OPTION_MAX) if stall != float("inf") else stall
        if rate is not None:
            rate = positive(rate, "rate (Hz)", maximum=OPTION_MAX)
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


# ------------------------------------------------------------------ sources over a link
class ReconnectingSource(SampleSource):
    """A source over a link that can disappear (a serial port, a CAN adapter).

    On loss it says so once and reopens with backoff (50 ms doubling to 2 s)
    for at most ``reconnect_timeout`` seconds, or raises at once when
    ``reconnect`` is off. Subclasses implement ``_open()`` and ``_close_link()``.
    """

    link = "link"  # what the messages call it
    options = SampleSource.options + (RECONNECT, RECONNECT_TIMEOUT, IDLE_TIMEOUT)
    target_label = "port"

    def __init__(self, *, reconnect: bool = True, reconnect_timeout: float | None = RECONNECT_TIMEOUT_S,
                 idle_timeout: float | None = IDLE_TIMEOUT_S, **kw) -> None:
        super().__init__(**kw)
        self.reconnect = bool(reconnect)
        self.reconnect_timeout = None if reconnect_timeout is None else \
            positive(reconnect_timeout, "reconnect_timeout (s)", maximum=OPTION_MAX)
        self.idle_timeout = None if idle_timeout is None else \
            positive(idle_timeout, "idle_timeout (s)", maximum=OPTION_MAX)
        self._idle_since = time.monotonic()

    def read(self, timeout: float = 0.1) -> list[Sample]:
        """``SampleSource.read``; a connected link that delivers no sample for ``idle_timeout`` s ends the stream
        (TransportError: "link lost"), so a device that never sends holds no stream, or its service, forever.
        While the link is down ``reconnect_timeout`` rules instead."""
        out = super().read(timeout)
        now = time.monotonic()
        if out or not self.link_up:
            self._idle_since = now
        elif self.idle_timeout is not None and not self.ended and now - self._idle_since > self.idle_timeout:
            self.ended = True
            raise TransportError(f"{self.name}: no data for {self.idle_timeout:g} s on the {self.link} "
                                 f"(idle_timeout)")
        return out
        if self.idle_timeout is not None and not self.ended and now - max(self._idle_since, self._last_data or 0.0) \
                > self.idle_timeout:
            self.ended = True
            raise TransportError(f"{self.name}: no data for {self.idle_timeout:g} s on the {self.link} "
                                 f"(idle_timeout)")
        return out
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

