"""Online agrees with batch: at the end of a record that ``identify`` fits at the noise floor, the online estimate
lies within the looser of the two's combined 1-sigma and the scenario tolerances (alpha 2 %, b 3 %, a1 and a2
5 %). A small case: short records of a stationary plant under a controller's staircase; the table over every
scenario family is ``bench/bench_online_batch.py``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.global_fit import floor_ratio
from creep_online.identification import FLOOR_WARNING, identify
from creep_online.online import OnlineEstimator
from hil_sim import scenarios

TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}


def _record(seed: int, seconds: float = 4.0, snr_db: float = 60.0):
    """(h, u, y): a plant of the stationary families' ranges (fn 100-1000 Hz) under a random staircase from rest."""
    rng = np.random.default_rng([seed, 40])
    plant = scenarios._stationary_plant(rng, 100.0, 1000.0)
    h = 1e-4
    t = np.arange(int(seconds / h)) * h
    u = scenarios.random_staircase(t, rng)
    y = scenarios.simulate_tv(h, u, plant["alpha"], plant["a1"], plant["a2"], plant["b"])
    std = float(np.sqrt(np.mean(y ** 2)) * 10 ** (-snr_db / 20))
    return h, u, y + rng.normal(0.0, std, y.size)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_online_estimate_at_the_end_agrees_with_identify(seed):
    h, u, y = _record(seed)
    est = OnlineEstimator(h)
    for a, b in zip(u.tolist(), y.tolist()):
        est.update(a, b)
    online = est.estimate
    batch = identify(np.arange(u.size) * h, u, y)
    assert floor_ratio(y - batch.y_hat) <= FLOOR_WARNING
    assert online.quality == "good"
    for p, tol in TOL.items():
        on, ba = getattr(online, p), batch.model.params()[p]
        sigma = math.hypot(online.uncertainty[p], batch.uncertainty[p])
        assert abs(on - ba) <= max(sigma, tol * abs(ba)), (p, on, ba, sigma)


def _row(seed: int, sd_rel: dict, at_floor: bool = True, agrees: bool = True) -> dict:
    """A results row of ``bench_online_batch`` as its summary reads it (batch at 1.0, truth 1.0)."""
    model = {p: 1.0 for p in TOL}
    return {"seed": seed, "quality": "good", "agrees": agrees, "online": dict(model), "truth": dict(model),
            "batch": {"model": model, "sd": {p: sd_rel.get(p, 1e-3) for p in TOL}, "at_floor": at_floor},
            "agreement": {p: {"rel_diff": 0.0} for p in TOL}, "max_window_ratio": 0.5, "divergent_windows": 0,
            "max_ratio_away_from_change": 0.5, "max_ratio_after_change": None}


def test_the_bench_counts_a_record_where_the_batch_fit_determines_every_parameter():
    """A record determines the plant where ``identify`` is at the floor with every relative 1-sigma within the
    online estimator's "determined" limits (alpha 1 %, b 1.5 %, a1 and a2 2.5 %); only those are judged."""
    from bench.bench_online_batch import determined, family_summary, undetermined
    rows = [_row(0, {}), _row(1, {"a2": 0.03}, agrees=False), _row(2, {"alpha": 0.011, "a1": 0.2}),
            _row(3, {}, at_floor=False, agrees=False), _row(4, {"b": 0.015, "a1": 0.025})]
    assert [determined(r) for r in rows] == [True, False, False, False, True]
    assert undetermined(rows[2]["batch"]) == ["alpha", "a1"]
    m = family_summary(rows)
    assert (m["records"], m["at_batch_floor"], m["determined"], m["agree_determined"]) == (5, 4, 2, 1.0)
    assert [u["seed"] for u in m["undetermined"]] == [1, 2]
    assert m["undetermined"][0]["batch_undetermined"] == ["a2"]
