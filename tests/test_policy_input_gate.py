"""The input gate's rule (``online/policy/input_gate.py``) as functions, and the estimator applying it."""
from __future__ import annotations

import numpy as np
import pytest

from creep_online.online import OnlineEstimator
from creep_online.online.policy import input_gate as G


@pytest.mark.parametrize("u, seen, gate, candidate", [
    (5.0, G.InputRange(0.0, 0.0, 0.0), 20.0, False),       # no range yet: nothing is a candidate
    (5.0, G.InputRange(0.0, 1.0, 0.5), 20.0, False),       # 4.5 ranges away
    (21.0, G.InputRange(0.0, 1.0, 0.5), 20.0, True),       # 20.5 ranges away
    (-19.6, G.InputRange(0.0, 1.0, 0.5), 20.0, True),      # the same below
    (20.5, G.InputRange(0.0, 1.0, 0.5), 20.0, False),      # exactly 20 ranges: not further
    (21.0, G.InputRange(0.0, 1.0, 0.5), 0.0, False),       # gate 0: disabled
    (2.0, G.InputRange(0.0, 0.1, 0.0), 10.0, True),        # a small range makes a modest jump a candidate
])
def test_glitch_candidate(u, seen, gate, candidate):
    assert G.glitch_candidate(u, seen, gate) is candidate


@pytest.mark.parametrize("candidate, held, burst, verdict", [
    (False, 0, 4, G.PASS),
    (True, 0, 4, G.HOLD),
    (True, 3, 4, G.HOLD),                # the burst's last sample is still held
    (True, 4, 4, G.MOVE),                # one more: a move, fed as it came
    (False, 1, 4, G.GLITCH),             # the input came back: a glitch
    (False, 4, 4, G.GLITCH),
])
def test_verdict(candidate, held, burst, verdict):
    assert G.verdict(candidate, held, burst) == verdict


def _fed(est: OnlineEstimator, u: np.ndarray, y: np.ndarray) -> list[tuple[float, float]]:
    """The (input as applied, output) pairs the estimator's input stage releases, sample by sample."""
    out = []
    for a, b in zip(u.tolist(), y.tolist()):
        est.samples += 1
        out.extend((est._inputs.accept(v), w) for v, w in est._inputs.classify(a, b))
    return out


def test_the_estimator_applies_the_rule_to_glitches_and_moves():
    """A glitch (2 samples, back within the burst) is fed with the last accepted input and counted; a move (held
    past the burst) is fed as it came; nothing is lost and the order is kept."""
    est = OnlineEstimator(1e-3, burst_s=0.004)       # a burst of 4 samples
    u = np.r_[np.zeros(3), np.ones(5), [90.0, 90.0], np.ones(3), np.full(8, 50.0)]
    y = np.arange(u.size, dtype=float)
    fed = _fed(est, u, y)
    assert [w for _, w in fed] == y[:fed.__len__()].tolist()
    applied = [v for v, _ in fed]
    assert applied[8:10] == [1.0, 1.0] and est.input_outliers == 2          # the glitch, replaced
    assert applied[13:18] == [50.0] * 5                                       # the move, as it came
    assert len(fed) == u.size


def test_random_streams_lose_no_sample_and_replace_only_glitches():
    """200 random streams of steps with random spikes: every sample comes out once, in order; an input is
    replaced only when it was held and the input came back (then by the last accepted one)."""
    rng = np.random.default_rng(451)
    for _ in range(200):
        n = int(rng.integers(20, 200))
        u = np.repeat(rng.uniform(-1, 1, n // 10 + 1), 10)[:n]
        spikes = rng.random(n) < 0.05
        u = np.where(spikes, rng.uniform(-100, 100, n), u)
        y = np.arange(n, dtype=float)
        est = OnlineEstimator(1e-3, burst_s=0.003)
        fed = _fed(est, u, y)
        fed = [(v + est._u_ref, w) for v, w in fed] + est._held   # (as given; candidates still held at the end)
        assert [w for _, w in fed] == y.tolist()
        replaced = sum(1 for (v, _), a in zip(fed, u.tolist()) if abs(v - a) > 1e-9)
        assert replaced == est.input_outliers
