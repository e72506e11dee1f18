"""An estimator fed by the application's own ``can.Notifier``: ``EstimatorListener``.

An application that already reads its bus with a ``can.Notifier`` (in its
thread, or on an asyncio loop with ``Notifier(bus, listeners, loop=loop)``)
adds this listener beside its own. Each message is decoded and ordered as
``CanSource`` does it (``can_source.CanMessages``: the DBC, the sample
counters, the reorder window; lost, duplicated and late frames counted), and
each good sample goes to the estimator's ``update(u, y)``; lost samples are
told with ``gap(n)`` (time advances, nothing is invented). ``stop()`` (the
notifier calls it) feeds what the reorder window still holds.

The listener runs on the notifier's thread (or the loop); ``estimate`` reads
the estimator's estimate under the lock the feeding holds, so another thread
never sees one half updated. The work per message is one ``update`` per
sample: bounded, it never waits.
"""
from __future__ import annotations

import threading
from typing import Any, Callable

try:
    import can
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError("EstimatorListener needs python-can: pip install 'creep_online[can]'") from exc

from ..errors import DataError, one_line
from .can_source import CanMessages
from .feed import Estimator
from .sources import Sample, SourceStats


class EstimatorListener(can.Listener):
    """A ``can.Listener`` that feeds an estimator (e.g. ``OnlineEstimator``) from the amplifier's frames.

    estimator: anything with ``update(u, y)`` (and ``gap(n)``, used when it has one).
    rate:      sample rate (Hz) of the amplifier's counter; None: ``1 / estimator.dt``.
    dbc:       the DBC file describing the frames (None: the built-in ``amplifier.dbc``).
    window:    reorder window (samples) a late frame may arrive within, as ``CanSource``'s.
    on_sample: called as ``on_sample(sample)`` after each update (on the notifier's thread).
    """

    def __init__(self, estimator: Estimator, *, rate: float | None = None, dbc: str | None = None,
                 window: int = 32, on_sample: Callable[[Sample], None] | None = None) -> None:
        if not callable(getattr(estimator, "update", None)):
            raise DataError(f"EstimatorListener needs an estimator with update(u, y), got {type(estimator).__name__}")
        if rate is None:
            dt = getattr(estimator, "dt", None)
            if not dt:
                raise DataError("EstimatorListener: give rate= (Hz): the estimator has no dt to take it from")
            rate = 1.0 / float(dt)
        self.estimator = estimator
        self.messages = CanMessages(rate=rate, dbc=dbc, window=window, name="can:listener")
        self.on_sample = on_sample
        self.lock = threading.Lock()
        self.fed = 0               # samples given to update()
        self.lost = 0              # missing samples told to the estimator with gap() (or counted without it)
        self.errors = 0            # bus errors the notifier reported (``on_error``)
        self.last_error = ""
        self.stopped = False
        self._last_seq: int | None = None

    # ------------------------------------------------------------------ can.Listener
    def on_message_received(self, msg: can.Message) -> None:
        """Decode ``msg`` and feed the samples it completes (the notifier's thread or loop calls this)."""
        if self.stopped:
            return
        with self.lock:
            for sample in self.messages.samples_of(msg):
                self._feed(sample)

    def on_error(self, exc: Exception) -> None:
        """A bus error the notifier caught: counted and kept (``errors``, ``last_error``); the bus is the
        application's, so what happens to it next is the application's choice."""
        self.errors += 1
        self.last_error = one_line(exc)
        self.messages.event(f"bus error: {self.last_error}")

    def stop(self) -> None:
        """Feed the samples the reorder window still holds; later messages are ignored."""
        with self.lock:
            if self.stopped:
                return
            self.stopped = True
            for sample in self.messages.flush():
                self._feed(sample)

    # ------------------------------------------------------------------ reading
    @property
    def estimate(self) -> Any:
        """The estimator's current estimate, read under the feeding's lock (safe from any thread)."""
        with self.lock:
            return self.estimator.estimate

    @property
    def stats(self) -> SourceStats:
        """Frames, corruption and ordering counters (as a ``CanSource``'s: ``stats.as_dict()``)."""
        return self.messages.stats

    # ------------------------------------------------------------------ feeding
    def _feed(self, sample: Sample) -> None:
        last = self._last_seq
        if last is not None and sample.seq > last + 1:
            n = sample.seq - last - 1
            gap = getattr(self.estimator, "gap", None)
            if gap is not None:
                gap(n)
            self.lost += n
        self._last_seq = sample.seq
        self.estimator.update(sample.u, sample.y)
        self.fed += 1
        if self.on_sample is not None:
            self.on_sample(sample)
