"""How the online estimator reads a stream's start: a step at the first sample, a few samples of rest, in operation.

The most common first record: the plant at rest, the input switched to its level as the acquisition starts (the
input at its level from the first sample, the output rising from zero). Records of every scenario family that
start this way, in both feeding modes, stay here so that no later change loses them.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.online import OnlineEstimator
from creep_online.online import rest
from hil_sim import scenarios

TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
#: The paper's accuracy on alpha and b at t_c + 5 s.
PAPER = 0.003


def _step_record(seed: int, rest_samples: int = 0, snr_db: float = 80.0, seconds: float = 8.0):
    """(h, u, y, truth): one step held for ``seconds``, after ``rest_samples`` of rest, on a plant drawn over the
    scenario families' ranges (even seeds strong_creep's, odd the stationary families', as
    bench/bench_online_first_sample.py draws them)."""
    rng = np.random.default_rng([seed, 99])
    if seed % 2 == 0:
        p = scenarios._strong_creep_plant(rng)
    else:
        p = {**scenarios._stationary_plant(rng, 100.0, 2500.0), "fs": 1e4}
    level = float(rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(-1.0, 1.0))
    h = 1.0 / p["fs"]
    n = int(seconds / h)
    u = np.full(n, level)
    u[:rest_samples] = 0.0
    y = scenarios.simulate_tv(h, u, p["alpha"], p["a1"], p["a2"], p["b"])
    std = float(np.sqrt(np.mean(y ** 2)) * 10 ** (-snr_db / 20))
    y = y + np.random.default_rng(int(rng.integers(1 << 31))).normal(0.0, std, n)
    return h, u, y, {k: p[k] for k in ("alpha", "a1", "a2", "b")}


def _feed(est: OnlineEstimator, u: np.ndarray, y: np.ndarray, mode: str) -> None:
    if mode == "block":
        est.update_block(u, y)
    else:
        for a, b in zip(u.tolist(), y.tolist()):
            est.update(a, b)


def _estimate_after_t_c(h, u, y, mode: str, after_s: float = 5.0):
    """The estimate at the first 0.1 s chunk end at or after t_c + ``after_s``."""
    est = OnlineEstimator(h)
    step = int(round(0.1 / h))
    for k in range(0, u.size, step):
        _feed(est, u[k:k + step], y[k:k + step], mode)
        e = est.estimate
        if e.phase == "tracking" and e.t >= e.t_c + after_s:
            return e
    return est.estimate


# ---------------------------------------------------------------------- the reading's rules
def test_a_start_near_zero_that_moves_far_shows_a_step_and_one_far_from_zero_does_not():
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 1e-4
    rise = 1.0 - np.exp(-t / 0.002)
    noise = rng.normal(0.0, 1e-3, t.size)
    assert rest.starts_near_rest(rise + noise) and rest.shows_step(rise + noise)
    assert not rest.starts_near_rest(5.0 + 0.01 * t + noise)          # a stream in operation: far from 0, creeping
    # near zero but hardly moved: may be a step (the competition decides once the input moves), not shown yet
    flat = 0.002 * t + noise
    assert rest.starts_near_rest(flat) and not rest.shows_step(flat)


def test_the_in_operation_reading_must_fit_clearly_better():
    # equal costs, or a sliver better (more free responses always take one): the step's reading
    assert rest.prefer_step(1.0, 1.0, 5000, 6) and rest.prefer_step(1.01, 1.0, 10000, 6)
    # missing the plant's past misfits grossly: in operation
    assert not rest.prefer_step(1400.0, 1.0, 4000, 6)
    # not a number: the other reading
    assert not rest.prefer_step(math.inf, 1.0, 100, 6) and rest.prefer_step(1.0, math.inf, 100, 6)


def test_the_lead_in_completes_the_rest_to_rest_lead_samples():
    assert rest.lead_in(1) == rest.REST_LEAD - 1 and rest.lead_in(rest.REST_LEAD) == 0 and rest.lead_in(5000) == 0


# ---------------------------------------------------------------------- the paper's experiment
@pytest.mark.parametrize("seed", [1, 2, 5, 6, 8])
@pytest.mark.parametrize("mode", ["block", "single"])
def test_a_step_at_the_first_sample_is_read_from_rest_to_the_papers_accuracy(seed, mode):
    """The input at its level from the first sample (no sample of rest): alpha and b within 0.3 % at t_c + 5 s
    at 80 dB (bench/bench_online_first_sample.py: 20 plants, both modes). Before, such a record ended in phase
    buffering, "waiting for the input to move", with every value 0. Seed 6 is a 2 Hz mode at 10 kHz: its first
    search (0.05 s) ends on the box's edge (zeta 3, alpha 0.95), which now asks for a longer window."""
    h, u, y, truth = _step_record(seed)
    e = _estimate_after_t_c(h, u, y, mode)
    assert e.start == "step" and e.phase == "tracking", e.reason
    assert abs(e.alpha / truth["alpha"] - 1) < PAPER and abs(e.b / truth["b"] - 1) < PAPER, (e.alpha, e.b, truth)


@pytest.mark.parametrize("rest_samples", [1, 10])
def test_a_step_after_one_or_ten_samples_of_rest(rest_samples):
    h, u, y, truth = _step_record(3, rest_samples)
    e = _estimate_after_t_c(h, u, y, "block")
    assert e.start == "rest"
    assert abs(e.alpha / truth["alpha"] - 1) < PAPER and abs(e.b / truth["b"] - 1) < PAPER, (e.alpha, e.b, truth)


def test_a_held_input_whose_output_starts_far_from_zero_is_in_operation_and_estimates_nothing():
    """Joined after the step (the output already at a level, creeping on): nothing to estimate until the input
    moves, and every value is None (not 0)."""
    h = 1e-3
    t = np.arange(3000) * h
    u = np.full(t.size, 1.0)
    y = 2.0 * (t + 0.3) ** 0.3 + np.random.default_rng(1).normal(0.0, 1e-3, t.size)
    est = OnlineEstimator(h)
    est.update_block(u, y)
    e = est.estimate
    assert e.start == "operation" and e.phase == "buffering" and "waiting for the input to move" in e.reason
    assert e.alpha is None and e.b is None and e.t_c is None


def test_a_stream_in_operation_that_starts_near_zero_loses_the_competition(monkeypatch):
    """mid_operation seed 1000 at 80 dB: its output starts near zero and creeps far before the input's first move,
    which is what a step from rest looks like; searched on the samples after the move too, the step's reading
    costs 1400x the in-operation one's."""
    monkeypatch.setattr(scenarios, "SNR_DB", 80.0)
    sc = scenarios.make("mid_operation", 1000)
    est = OnlineEstimator(sc.h)
    est.update_block(sc.u[:int(3.0 / sc.h)], sc.y[:int(3.0 / sc.h)])
    assert est.estimate.start == "operation"


# ---------------------------------------------------------------------- every family, from the first sample
#: One seed per family whose record with 0.05-0.3 s of rest ends within the tolerances at 40 dB.
FAMILY_SEEDS = {"strong_creep": 1, "payload": 1, "stiffness": 1, "drift": 0, "controller": 1, "close_modes": 1,
                "quiet_start": 1}


@pytest.mark.parametrize("family", [pytest.param(f, marks=pytest.mark.long) if f == "close_modes" else f
                                    for f in scenarios.FROM_REST])
def test_every_family_starting_at_the_first_sample(family):
    assert set(FAMILY_SEEDS) == set(scenarios.FROM_REST)
    sc = scenarios.make(family, FAMILY_SEEDS[family], 0)
    est = OnlineEstimator(sc.h)
    step = int(round(0.1 / sc.h))
    for k in range(0, sc.u.size, step):
        est.update_block(sc.u[k:k + step], sc.y[k:k + step])
    e = est.estimate
    assert e.start == ("step" if sc.u[0] != 0.0 else "rest")
    err = {k: abs(getattr(e, k) / v - 1) for k, v in sc.final_truth.items()}
    assert all(err[k] <= TOL[k] for k in TOL), (err, e.quality, e.reason)


@pytest.mark.parametrize("family", ["controller", "payload"])
def test_families_starting_at_the_first_sample_sample_by_sample(family):
    sc = scenarios.make(family, FAMILY_SEEDS[family], 0)
    est = OnlineEstimator(sc.h)
    _feed(est, sc.u, sc.y, "single")
    e = est.estimate
    assert e.start == "step"
    err = {k: abs(getattr(e, k) / v - 1) for k, v in sc.final_truth.items()}
    assert all(err[k] <= TOL[k] for k in TOL), (err, e.quality, e.reason)


@pytest.mark.long
def test_a_step_after_one_sample_of_rest_beside_close_modes_is_not_a_wrong_basin():
    """close_modes seed 2 at 40 dB, one sample of rest: without the rest lead-in the window's free offset let a
    second basin fit as well (alpha +18 %, b -14 %, a1 -20 %, to the end); without the noise monitor's seed the
    step's transient read as noise (5x) and that basin read "good" at 0.4x the floor."""
    sc = scenarios.make("close_modes", 2, 1)
    est = OnlineEstimator(sc.h)
    est.update_block(sc.u, sc.y)
    e = est.estimate
    err = {k: abs(getattr(e, k) / v - 1) for k, v in sc.final_truth.items()}
    assert all(err[k] <= TOL[k] for k in TOL), (err, e.quality, e.reason)
    assert e.noise_rms == pytest.approx(sc.params["noise_std"], rel=0.1)
