"""FeedLoop (creep_online/io/feed.py): the one source -> estimator loop of stream, demo and the transport bench.

Real sources (the toy plug-in source, a serial port on a real pseudo-terminal)
and the real OnlineEstimator; a consumer without ``gap()`` stands for any
other estimator the loop may drive.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest

from creep_online.io.feed import FeedLoop, SampleAge
from creep_online.io import Sample, open_source
from creep_online.online import OnlineEstimator

sys.path.insert(0, str(Path(__file__).parent / "plugins"))
from toy_creep_source import ToyCreepSource  # noqa: E402

MODEL = "alpha=0.06,fn=6,zeta=0.1,b=0.02"
N, DROP, RATE = 2400, 50, 200.0


class Collector:
    """An estimator-like consumer with no ``gap()``: it only keeps what it was given."""

    def __init__(self) -> None:
        self.seen: list[tuple[float, float]] = []

    def update(self, u: float, y: float) -> None:
        self.seen.append((u, y))


def _toy(**kw) -> ToyCreepSource:
    return ToyCreepSource(MODEL, rate=RATE, samples=N, drop=DROP, on_event=None, **kw)


def test_gaps_reach_the_estimator_and_every_good_sample_is_fed_once():
    src = _toy()
    loop = FeedLoop(src, lambda dt: OnlineEstimator(dt), record=True)
    end = loop.run()
    sent = [k for k in range(N) if not src.lost(k)]
    inside = sent[-1] + 1 - len(sent)       # a loss after the last sample is never known
    assert end.reason == "end_of_stream" and end.error is None
    assert loop.estimator.dt == pytest.approx(1 / RATE)
    assert src.lost(N - 1) and inside == N // DROP - 1
    assert loop.lost == inside == loop.estimator.gaps and loop.lost_not_fed == 0
    assert loop.fed == len(sent) == len(loop.seqs) == loop.latency_us().size
    assert loop.estimator.samples == N - 1
    assert loop.seqs == sent


def test_an_estimator_without_gap_is_fed_and_the_lost_samples_are_counted():
    loop = FeedLoop(_toy(), lambda dt: Collector())
    assert loop.run().reason == "end_of_stream"
    assert len(loop.estimator.seen) == loop.fed == N - N // DROP
    assert loop.lost == 0 and loop.lost_not_fed == N // DROP - 1    # the last sample is lost too


def test_stop_condition_ends_with_limit():
    loop = FeedLoop(_toy(), lambda dt: Collector(), stop_when=lambda lp: lp.fed >= 600)
    assert loop.run().reason == "limit"
    assert 600 <= loop.fed < N - N // DROP


def test_step_from_the_first_samples_of_a_plain_iterable():
    samples = [Sample(k, 0.25 + k * 0.004, 1.0, 0.5) for k in range(10)]
    made: list[float] = []
    loop = FeedLoop(samples, lambda dt: made.append(dt) or Collector())
    assert loop.run().reason == "end_of_stream"
    assert made == [pytest.approx(0.004)] and loop.fed == 10


def test_ctrl_c_keeps_the_work_done_so_far():
    class Interrupted(ToyCreepSource):
        def _read_raw(self, timeout):
            if self._next >= 1000:
                raise KeyboardInterrupt
            return super()._read_raw(timeout)

    loop = FeedLoop(Interrupted(MODEL, rate=RATE, samples=N, on_event=None), lambda dt: OnlineEstimator(dt))
    end = loop.run()
    assert end.reason == "interrupted" and end.message == "interrupted (Ctrl-C)"
    assert isinstance(end.error, KeyboardInterrupt) and loop.estimator.samples == loop.fed == 1000


def test_a_lost_port_ends_with_link_lost():
    master, slave = os.openpty()
    src = open_source(f"serial:{os.ttyname(slave)}?format=ascii&reconnect=0", on_event=None)
    os.close(slave)
    os.write(master, b"".join(f"{k},{k * 1e-3:.3f},1.0,0.5\n".encode() for k in range(50)))
    received: list[int] = []

    def close_after_data(loop):
        if loop.fed >= 40 and master not in received:
            received.append(master)
            os.close(master)              # the device goes away

    loop = FeedLoop(src, lambda dt: Collector(), on_batch=close_after_data)
    end = loop.run()
    src.close()
    assert end.reason == "link_lost" and "reconnect is off" in end.message
    assert loop.fed >= 40


def test_an_error_before_any_estimator_is_raised():
    def refuse(dt):
        raise ValueError("no estimator today")

    with pytest.raises(ValueError, match="no estimator today"):
        FeedLoop(_toy(), refuse).run()


def test_an_error_after_samples_ends_with_error_and_keeps_the_estimator():
    class Fragile(Collector):
        def update(self, u, y):
            if len(self.seen) == 100:
                raise RuntimeError("numerics gave up\nsecond line")
            super().update(u, y)

    loop = FeedLoop(_toy(), lambda dt: Fragile())
    end = loop.run()
    assert end.reason == "error" and end.message == "RuntimeError: numerics gave up"
    assert len(loop.estimator.seen) == 100


def test_sample_age_is_measured_from_the_senders_clock():
    t0 = time.monotonic() + 1000.0          # a sender whose sample 0 is 1000 s in the future
    loop = FeedLoop(_toy(), lambda dt: Collector(), latency=SampleAge(t0, 1 / RATE))
    loop.run()
    ages = loop.latency_us()
    assert ages.size == loop.fed and ages.max() < -980e6
