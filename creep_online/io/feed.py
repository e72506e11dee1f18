"""The one loop that drives an estimator from a sample source: gaps, latency, live status, how it ended.

``creep-online stream``, ``creep-online demo`` and ``bench/bench_transports.py``
all run :class:`FeedLoop`. It reads batches from a source (a
``SampleSource`` or any iterable of samples), builds the estimator once the
sampling step is known, tells it about lost samples (``gap(n)`` when it has
one, time advancing with nothing invented), times every ``update`` and turns
Ctrl-C, a lost link or an error into an :class:`End` instead of losing the
work done so far. A stall (silence) is counted by the source itself; the
loop keeps reading with a timeout, so a silent link never blocks Ctrl-C, a
stop condition or the deadline.

The estimator is duck-typed (``update(u, y)``, optionally ``gap(n)``), so this
module does not depend on ``creep_online.online``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Protocol

import numpy as np

from .._signals import describe, exit_code
from ..errors import TransportError

#: How a feed can end (``End.reason``).
END_REASONS = ("end_of_stream", "limit", "link_lost", "error", "interrupted")


class Estimator(Protocol):
    """What the loop needs of an estimator (``OnlineEstimator`` is one)."""

    def update(self, u: float, y: float) -> Any: ...


@dataclass(frozen=True)
class End:
    """Why the feed stopped: one of ``END_REASONS``, a one-line message, and the exception if one stopped it."""

    reason: str
    message: str = ""
    error: BaseException | None = None

    @property
    def exit_code(self) -> int | None:
        """128 + the signal that interrupted the feed (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP); None otherwise."""
        return exit_code(self.error) if self.reason == "interrupted" and self.error is not None else None


class CallLatency:
    """Latency = the time ``update()`` itself took (``time.perf_counter_ns`` around the call)."""

    def __init__(self) -> None:
        self.values: list[int] = []      # ns

    def microseconds(self) -> np.ndarray:
        return np.asarray(self.values, dtype=np.int64) / 1e3


class SampleAge:
    """Latency = from the sample's time at the sender (``t0 + seq * dt`` on the shared monotonic clock)
    to the return of ``update()`` for it: transport, parsing, queueing and the update together."""

    def __init__(self, t0: float, dt: float) -> None:
        self.t0 = float(t0)
        self.dt = float(dt)
        self.values: list[float] = []    # s

    def microseconds(self) -> np.ndarray:
        return np.asarray(self.values, dtype=float) * 1e6


class FeedLoop:
    """Feed every good sample of ``source`` to an estimator, in order; see the module docstring.

    ``make_estimator(dt)`` is called once the step is known: ``dt`` if given,
    else the source's ``dt``, else from the first two samples' times.
    ``on_sample(loop, sample)`` runs after each update, ``on_batch(loop)``
    after each non-empty batch (live status). ``stop_when(loop)`` is checked
    after each batch, as is ``duration`` (seconds of wall time); either ends
    the feed with reason ``limit``. ``record=True`` keeps (seq, u, y) of
    every fed sample. The caller opens and closes the source.
    """

    def __init__(self, source: Any, make_estimator: Callable[[float], Estimator], *, dt: float | None = None,
                 latency: CallLatency | SampleAge | None = None, read_timeout: float = 0.1,
                 duration: float | None = None, stop_when: Callable[["FeedLoop"], bool] | None = None,
                 on_sample: Callable[["FeedLoop", Any], None] | None = None,
                 on_batch: Callable[["FeedLoop"], None] | None = None, record: bool = False) -> None:
        self.source = source
        self.make_estimator = make_estimator
        self.dt = dt
        self.latency = latency if latency is not None else CallLatency()
        self.read_timeout = read_timeout
        self.duration = duration
        self.stop_when = stop_when
        self.on_sample = on_sample
        self.on_batch = on_batch
        self.record = record
        self.estimator: Estimator | None = None
        self.fed = 0               # samples given to update()
        self.lost = 0              # missing sequence numbers told to the estimator with gap()
        self.lost_not_fed = 0      # missing sequence numbers an estimator without gap() never heard of
        self.last_seq: int | None = None
        self.seqs: list[int] = []
        self.us: list[float] = []
        self.ys: list[float] = []
        self.started = math.nan    # time.monotonic() when run() began
        self.wall_s = 0.0
        self.end: End | None = None
        self._pending: list = []

    # ------------------------------------------------------------------ running
    def run(self) -> End:
        """Feed until the stream ends, a stop condition holds, or something stops it; return how it ended.

        An error before the estimator exists (nothing to keep) is raised, not returned.
        """
        self.started = time.monotonic()
        deadline = math.inf if self.duration is None else self.started + self.duration
        end = End("end_of_stream")
        try:
            for batch in self._batches():
                if batch:
                    self._feed(batch)
                    if self.on_batch is not None:
                        self.on_batch(self)
                if (self.stop_when is not None and self.stop_when(self)) or time.monotonic() > deadline:
                    end = End("limit")
                    break
        except KeyboardInterrupt as exc:    # Ctrl-C, SIGTERM, SIGHUP (``creep_online._signals``)
            end = End("interrupted", describe(exc), exc)
        except TransportError as exc:
            end = End("link_lost", str(exc), exc)
        except Exception as exc:  # noqa: BLE001 - keep the work done so far; say what stopped it
            if self.estimator is None:
                raise
            first = str(exc).splitlines()[0] if str(exc) else ""
            end = End("error", f"{type(exc).__name__}: {first}"[:300], exc)
        self.wall_s = time.monotonic() - self.started
        self.end = end
        return end

    def _batches(self) -> Iterator[list]:
        read = getattr(self.source, "read", None)
        if read is None:                      # a plain iterable of samples
            for sample in self.source:
                yield [sample]
            return
        while not getattr(self.source, "ended", False):
            yield read(self.read_timeout)

    def _feed(self, batch: Iterable) -> None:
        for sample in batch:
            if self.estimator is None:
                todo = self._start(sample)
            else:
                todo = (sample,)
            for smp in todo:
                self._feed_one(smp)

    def _start(self, sample: Any) -> list:
        """Hold samples until the step is known, then build the estimator; return the samples to feed."""
        self._pending.append(sample)
        pending = self._pending
        dt = self.dt or getattr(self.source, "dt", None)
        if not dt and len(pending) >= 2 and pending[-1].seq > pending[0].seq:
            dt = (pending[-1].t - pending[0].t) / (pending[-1].seq - pending[0].seq)
        if not dt or dt <= 0:
            return []
        self.estimator = self.make_estimator(dt)
        self.dt = dt
        self._pending = []
        return pending

    def _feed_one(self, smp: Any) -> None:
        est = self.estimator
        last = self.last_seq
        if last is not None and smp.seq > last + 1:
            self._gap(smp.seq - last - 1)
        self.last_seq = smp.seq
        latency = self.latency
        if isinstance(latency, SampleAge):
            est.update(smp.u, smp.y)
            latency.values.append(time.monotonic() - (latency.t0 + smp.seq * latency.dt))
        else:
            t0 = time.perf_counter_ns()
            est.update(smp.u, smp.y)
            latency.values.append(time.perf_counter_ns() - t0)
        self.fed += 1
        if self.record:
            self.seqs.append(smp.seq)
            self.us.append(smp.u)
            self.ys.append(smp.y)
        if self.on_sample is not None:
            self.on_sample(self, smp)

    def _gap(self, n: int) -> None:
        gap = getattr(self.estimator, "gap", None)
        if gap is None:
            self.lost_not_fed += n
            return
        gap(n)
        self.lost += n

    # ------------------------------------------------------------------ results
    def latency_us(self) -> np.ndarray:
        """Per-sample latency of every fed sample, in microseconds (see CallLatency / SampleAge)."""
        return self.latency.microseconds()

    def recent_latency_us(self, n: int) -> np.ndarray:
        """The last ``n`` latencies in microseconds (live status)."""
        tail = self.latency.values[-n:]
        scale = 1e6 if isinstance(self.latency, SampleAge) else 1e-3
        return np.asarray(tail, dtype=float) * scale
