"""OnlineEstimator: accuracy, start from nothing, tracking, changes, robustness, API contract.

Plants come from the exact simulator (``simulate``) and from ``hil_sim.scenarios``
(the seeded randomized families of bench/bench_online_scenarios.py); tolerances are
the issue's: alpha 2 %, b 3 %, a1 and a2 5 % (the textbook cases much tighter).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from creep_online.errors import CreepOnlineError, DataError
from creep_online.model import CreepModel
from creep_online.online import OnlineEstimate, OnlineEstimator
from dataclasses import replace

from creep_online.online.startup import Startup
from creep_online.online.trackers import window as tracker_module
from creep_online.online.trackers.settings import DEFAULT as TRACKER_DEFAULTS
from hil_sim.varying_plant import simulate_varying
from creep_online.simulate import simulate
from hil_sim import scenarios

TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}


def _plant(alpha, fn, zeta, b, h, seconds, amp, t0, seed=0, snr_db=40.0):
    model = CreepModel.from_resonance(alpha, fn, zeta, b)
    n = int(round(seconds / h))
    t = np.arange(n) * h
    u = np.where(t >= t0, amp, 0.0)
    y = simulate(model, t, u)
    sig = math.sqrt(np.mean(y[t >= t0] ** 2))
    y = y + np.random.default_rng(seed).normal(0, sig * 10 ** (-snr_db / 20), n)
    return model, t, u, y


def _errors(e: OnlineEstimate, truth: dict) -> dict:
    """Relative errors; inf for a value not yet estimated (None)."""
    return {k: math.inf if getattr(e, k) is None else abs(getattr(e, k) / truth[k] - 1) for k in TOL}


def _within(e: OnlineEstimate, truth: dict, scale: float = 1.0) -> bool:
    return all(v < scale * TOL[k] for k, v in _errors(e, truth).items())


def _truth(model: CreepModel) -> dict:
    return {"alpha": model.alpha, "a1": model.a1, "a2": model.a2, "b": model.b}


@pytest.fixture(scope="module")
def load_cell():
    """Load cell: alpha 0.06, fn 6 Hz, 200 Hz sampling, step of 50."""
    return _plant(0.06, 6.0, 0.1, 0.02, 5e-3, 12.0, 50.0, 0.1)


@pytest.fixture(scope="module")
def nanopositioner():
    """Nanopositioner: alpha 0.02, fn 300 Hz, 10 kHz sampling, 3 s."""
    return _plant(0.02, 300.0, 0.05, 0.15, 1e-4, 3.0, 10.0, 0.01)


# ---------------------------------------------------------------------- textbook accuracy
def test_load_cell_single_samples_phases_and_accuracy(load_cell):
    model, t, u, y = load_cell
    est = OnlineEstimator(5e-3)
    phases = []
    for k in range(u.size):
        est.update(u[k], y[k])
        e = est.estimate
        if not phases or phases[-1] != e.phase:
            phases.append(e.phase)
        values = (e.alpha, e.a1, e.a2, e.b)
        # a value is a finite number once estimated, None (not 0) before: all four together, with the model
        assert all(v is None for v in values) == (est.model is None), values
        assert all(v is None or math.isfinite(v) for v in values) and math.isfinite(e.t)
    assert phases[0] == "buffering" and phases[-1] == "tracking" and "searching" in phases
    e = est.estimate
    assert _within(e, _truth(model), scale=0.25)          # alpha 0.5 %, b 0.75 %, a1 a2 1.25 %
    assert e.quality == "good", e.reason
    assert est.last_prediction == pytest.approx(y[-1], abs=0.05 * abs(y[-1]))


def test_nanopositioner_block_textbook_accuracy(nanopositioner):
    """The paper's experiment: b within 0.3 %, alpha within 3 of its reported 1-sigma (issue 8: keep what works).

    At 40 dB the data determine alpha to ~0.35 % (1-sigma, reported and seen: 0.04-0.7 % over seeds 0-5), so
    0.3 % on alpha is a coin toss there; the 0.3 % of the paper is asserted at 60 dB below (1-sigma 0.035 %).
    """
    model, t, u, y = nanopositioner
    est = OnlineEstimator(1e-4)
    est.update_block(u, y)
    e = est.estimate
    assert abs(e.b / model.b - 1) < 0.003
    assert abs(e.alpha - model.alpha) < 3 * e.uncertainty["alpha"] < 0.02 * model.alpha
    assert e.fn_hz == pytest.approx(300.0, rel=0.002)


@pytest.mark.parametrize("seed", [0, 5])
def test_nanopositioner_textbook_accuracy_at_60_db(seed):
    """alpha and b within 0.3 % where the noise allows it (seeds 0-5 at 60 dB: alpha 0.01-0.07 %)."""
    model, t, u, y = _plant(0.02, 300.0, 0.05, 0.15, 1e-4, 3.0, 10.0, 0.01, seed=seed, snr_db=60.0)
    est = OnlineEstimator(1e-4)
    est.update_block(u, y)
    e = est.estimate
    assert abs(e.alpha / model.alpha - 1) < 0.003 and abs(e.b / model.b - 1) < 0.003


def test_block_and_single_agree(load_cell):
    model, t, u, y = load_cell
    a = OnlineEstimator(5e-3)
    a.update_block(u, y)
    b = OnlineEstimator(5e-3)
    for k in range(u.size):
        b.update(u[k], y[k])
    ea, eb = a.estimate, b.estimate
    for name in ("alpha", "a1", "a2", "b"):   # the sliced work lands a few samples later in single mode
        assert getattr(ea, name) == pytest.approx(getattr(eb, name), rel=5e-3)
    assert ea.samples == eb.samples == u.size


def test_window_error_sample_by_sample_is_block_modes_at_the_noise_floor():
    """The demo's plant (alpha 0.12, 420 Hz, noise 2e-4, one step), 6 s at 10 kHz: sample by sample the window
    error is block mode's and the noise floor's. The re-fit's statistics were once scaled in two slices a
    sample apart: the error read 1.35x the noise here (1.85x by 16 s, then "degraded" and a wrong re-search)
    with the parameters right, sample by sample only."""
    from hil_sim.plant import PlantConfig, generate, parse_params
    rec = generate(PlantConfig(model=parse_params(""), duration=6.0, t_start=0.2, seed=3))
    block, single = OnlineEstimator(1e-4), OnlineEstimator(1e-4)
    block.update_block(rec.u, rec.y)
    for u, y in zip(rec.u.tolist(), rec.y.tolist()):
        single.update(u, y)
    eb, es = block.estimate, single.estimate
    assert es.quality == eb.quality == "good", (es.reason, eb.reason)
    assert es.residual_rms == pytest.approx(eb.residual_rms, rel=0.02)
    assert es.residual_rms < 1.1 * es.noise_rms


# ---------------------------------------------------------------------- start from nothing
@pytest.mark.parametrize("alpha, fn, zeta, b, fs", [(0.3, 25.0, 0.2, 1.2, 2000), (0.5, 100.0, 0.3, -3.0, 10000),
                                                    (0.01, 1000.0, 0.02, 1e-3, 10000), (0.7, 3.0, 0.6, 40.0, 500)])
def test_starts_from_the_defaults_on_strong_creep(alpha, fn, zeta, b, fs):
    """No alpha0: the issue's failing demo plant (alpha 0.3, fn 25 Hz) and other corners of the range."""
    h = 1 / fs
    t = np.arange(int(8 / h)) * h
    u = np.where(t < 0.02, 0.0, np.floor(t / 0.5) % 3 - 1.0)   # from rest, a staircase with reversals
    model = CreepModel.from_resonance(alpha, fn, zeta, b)
    y = simulate(model, t, u)
    y = y + np.random.default_rng(1).normal(0, 0.003 * np.std(y), t.size)
    est = OnlineEstimator(h)
    est.update_block(u, y)
    assert _within(est.estimate, _truth(model)), _errors(est.estimate, _truth(model))


@pytest.mark.parametrize("family, seed", [("strong_creep", 0), ("strong_creep", 1), ("controller", 0),
                                          ("mid_operation", 0), ("mid_operation", 1)])
def test_stationary_scenario_families(family, seed):
    """Creep (alpha, b) always; the resonance where the input excites it, else an honest "not determined"."""
    sc = scenarios.make(family, seed)
    est = OnlineEstimator(sc.h)
    est.update_block(sc.u, sc.y)
    e = est.estimate
    err = _errors(e, sc.final_truth)
    assert err["alpha"] < TOL["alpha"] and err["b"] < TOL["b"], (sc.params, err)
    if not (err["a1"] < TOL["a1"] and err["a2"] < TOL["a2"]):
        assert e.quality != "good" and ("a1" in e.reason or "a2" in e.reason), (sc.params, err, e.reason)


@pytest.mark.parametrize("seed", [1000, 1001])
def test_a_stream_in_operation_starts_in_the_right_basin_at_80_db(seed, monkeypatch):
    """mid_operation at 80 dB (u[0] != 0, 5 s of steps before the stream): the past input's fading memory
    dominated the start-up search's cost, which started creep and resonance at rest (seed 1000: ~9000 noise
    variances per row for every candidate, the plant's no lower), so the search took the resonance bound
    (fn 4.5 kHz) and the window stayed there, a2 -99.9 % to the end of the stream; the re-searches ranked by
    the same cost and found nothing better. The searches now project out the unknown start (the tracker's
    free decays and the resonance's free responses): all four within the tolerances after 4 s (a1 0.7 %; before,
    a1 -66 % / +26 %, a2 -99.9 % / -99.6 % there)."""
    monkeypatch.setattr(scenarios, "SNR_DB", 80.0)
    sc = scenarios.make("mid_operation", seed)
    n = int(round(4.0 / sc.h))
    est = OnlineEstimator(sc.h)
    est.update_block(sc.u[:n], sc.y[:n])
    e = est.estimate
    assert e.phase == "tracking"
    assert _within(e, sc.final_truth), (sc.params, _errors(e, sc.final_truth), e.quality, e.reason)


@pytest.mark.parametrize("seed", [1, 13])
def test_a_stream_in_operation_is_fitted_at_the_noise_floor_at_80_db(seed, monkeypatch):
    """mid_operation at 80 dB, sample by sample (issue 8): the window error crept to 1.4-2.8x the noise floor with
    every parameter within 0.1 % (seed 1 ended "degraded" at 2.75x, seed 13 went up to 2.6x), until a replay
    dropped the oldest samples. The past input's creep, b sum_k du_k (t - t_k)^alpha / Gamma(1 + alpha), is not
    spanned by an offset and four exponentials (0.03-5 /s) at that noise; the window now has eight (0.01-30 /s),
    fitted without the Marquardt damping's lag and with a weak prior in the covariance (else every variance read
    inf and the quality "provisional"). From 3 s on: at the floor, "good", within the tolerances. The window starts
    with four of the eight and frees the others on a score test (``tracker.WIDE_ON``), which these records pass."""
    monkeypatch.setattr(scenarios, "SNR_DB", 80.0)
    sc = scenarios.make("mid_operation", seed)
    est = OnlineEstimator(sc.h)
    update = est.update
    chunk = int(round(0.1 / sc.h))
    seen = []
    for k in range(0, sc.u.size, chunk):
        for u, y in zip(sc.u[k:k + chunk].tolist(), sc.y[k:k + chunk].tolist()):
            update(u, y)
        if (k + chunk) * sc.h > 3.0:
            e = est.estimate
            seen.append((round((k + chunk) * sc.h, 1), round(e.residual_rms / e.noise_rms, 2), e.quality))
    worst = max(seen, key=lambda v: v[1])
    assert worst[1] < TRACKER_DEFAULTS.research.clear_ratio, worst
    assert all(q == "good" for _, _, q in seen), [v for v in seen if v[2] != "good"][:5]
    assert _within(e, sc.final_truth, scale=0.1), (sc.params, _errors(e, sc.final_truth))
    assert est._tracker.free_wide      # the score test freed the four extra free responses (at 80 dB they are needed)


def test_a_stream_in_operation_fits_four_free_responses_until_the_data_need_more(monkeypatch):
    """mid_operation at 40 dB, seed 1009, sample by sample: the eight free responses the window needs at 80 dB
    (the past's creep, ``tracker.WINDOW_FREE_RATES``) took some of what determines alpha where the input barely
    moves: alpha's 1-sigma 1.06 % against 0.76 % with four, and the stream ended "provisional". The window now
    starts with four of them (``WINDOW_FREE_START``) and frees the others only when a score test finds them
    needed; at 40 dB it does not, and the stream ends "good" with alpha determined as before."""
    monkeypatch.setattr(scenarios, "SNR_DB", 40.0)
    sc = scenarios.make("mid_operation", 1009)
    est = OnlineEstimator(sc.h)
    update = est.update
    for u, y in zip(sc.u.tolist(), sc.y.tolist()):
        update(u, y)
    e = est.estimate
    assert e.uncertainty["alpha"] / e.alpha < 0.009, e.uncertainty       # 0.75 % (eight from the start: 1.06 %)
    assert e.quality == "good", (e.quality, e.reason)
    assert _within(e, sc.final_truth), (sc.params, _errors(e, sc.final_truth))
    assert not est._tracker.free_wide


# ---------------------------------------------------------------------- changes and drift
@pytest.mark.parametrize("family, seed", [("stiffness", 1), ("payload", 4)])
def test_a_change_is_followed_sample_by_sample(family, seed):
    """In real time (update() per sample, background work in bounded units), not just in block mode.

    stiffness 1 (damping x1.7) once left the post-change search walking a flat valley for 7 s
    of stream; the refinement now stops at ``search.MAX_EVALS`` evaluations per candidate.
    """
    sc = scenarios.make(family, seed)
    est = OnlineEstimator(sc.h)
    update = est.update
    for u, y in zip(sc.u.tolist(), sc.y.tolist()):
        update(u, y)
    e = est.estimate
    assert _within(e, sc.final_truth), (sc.params, _errors(e, sc.final_truth), e.reason)
    assert any(abs(v["t"] - sc.change_time) < 1.0 and v["settled"] for v in e.events), e.events



@pytest.mark.parametrize("family, seed", [("payload", 4), ("mid_operation", 0)])
def test_a_stream_leaves_no_reference_cycles_so_the_collector_can_be_off_in_the_loop(family, seed):
    """The docs' hard-real-time loop may run with ``gc.disable()`` (the collector's passes are 10-50 us of a call):
    that is safe only if the estimator's garbage is freed by reference counting alone. A stream with a change
    (start-up search, re-fits, change test, post-change search, replays), and one taken in operation (its searches
    project out the unknown start: a kernel of 20 arguments left each call's arguments in a cycle), sample by
    sample, the collector off: it then finds nothing unreachable."""
    import gc
    from creep_online.online import warm_kernels
    sc = scenarios.make(family, seed)
    u, y = sc.u.tolist(), sc.y.tolist()
    warm_kernels()                         # (as the docs' loop: numba's loading of a kernel makes a ctypes type cycle)
    gc.collect()
    est = OnlineEstimator(sc.h)
    gc.disable()
    try:
        for uk, yk in zip(u, y):
            est.update(uk, yk)
        unreachable = gc.collect()
    finally:
        gc.enable()
    if family == "payload":
        assert est.estimate.events, "the stream's change was not seen: the test covers less than it says"
    assert est.estimate.quality != "none"
    assert unreachable == 0


def test_a_stream_taken_in_operation_triggers_no_collector_pass():
    """With the collector on, a pass runs inside whichever call crosses its threshold (700 tracked objects more
    allocated than freed): 15-50 us of one update(). The estimator's own allocations stay below it over a stream
    taken in operation (its start-up search projects out the unknown start; a compiled kernel called with 20
    arguments cost the threshold two objects per call there: three passes in the first 0.25 s)."""
    import gc
    from creep_online.online import warm_kernels
    sc = scenarios.make("mid_operation", 0)
    u, y = sc.u.tolist(), sc.y.tolist()
    warm_kernels()
    passes = []
    gc.collect()
    est = OnlineEstimator(sc.h)
    gc.freeze()                            # (the docs' loop)
    gc.callbacks.append(lambda phase, info: passes.append(info["generation"]) if phase == "start" else None)
    try:
        for uk, yk in zip(u, y):
            est.update(uk, yk)
    finally:
        gc.callbacks.pop()
        gc.unfreeze()
    assert est.estimate.quality != "none"
    assert passes == []


_PER_SAMPLE = ("update() sample by sample ends this way, and update_block() follows update()'s schedule of the "
               "background work (the same estimates, ==)")


@pytest.mark.parametrize("family, seed", [("payload", 8), pytest.param("stiffness", 0, marks=pytest.mark.xfail(
    strict=True, raises=AssertionError, reason="6 replays with and without the wait: " + _PER_SAMPLE))])
def test_a_replay_triggered_by_a_change_waits_for_the_test_and_is_dropped(family, seed, monkeypatch):
    """A settled window whose resonance runs off after a change triggers a replay of the whole ring; it waits
    for the change test due next (``tracker.REPLAY_AFTER_TEST``), which declares the change, and the restart
    drops it. Same detection and the same end as replaying at once, with fewer replays."""
    sc = scenarios.make(family, seed)
    outcome = {}
    for wait in (False, True):
        monkeypatch.setattr(tracker_module, "DEFAULT", replace(TRACKER_DEFAULTS, replay_after_test=wait))
        est = OnlineEstimator(sc.h)
        est.update_block(sc.u, sc.y)
        e = est.estimate
        assert _within(e, sc.final_truth), (wait, sc.params, _errors(e, sc.final_truth))
        outcome[wait] = ([round(v["t"], 3) for v in e.events], est._tracker.relinearizations)
    assert outcome[True][0] == outcome[False][0] and outcome[True][0], outcome
    assert outcome[True][1] < outcome[False][1], outcome


@pytest.mark.parametrize("family, seed", [("payload", 8), ("stiffness", 8)])
def test_at_80_db_the_first_search_pass_is_reported_at_once(family, seed, monkeypatch):
    """At 80 dB the post-change search's own cost (the resonance at rest at its segment's start) sat above
    1.5x the floor with the right resonance, and the estimate waited for two longer passes (re-convergence
    3.3 s on both records). A pass's result that is clearly better than the live estimate is reported at
    once (``Researcher.take_if_better``): re-convergence within 2 s, and it stays."""
    monkeypatch.setattr(scenarios, "SNR_DB", 80.0)
    sc = scenarios.make(family, seed)
    est = OnlineEstimator(sc.h)
    chunk = int(round(0.1 / sc.h))
    within_since = None
    for k in range(0, sc.u.size, chunk):
        est.update_block(sc.u[k:k + chunk], sc.y[k:k + chunk])
        t = min(k + chunk, sc.u.size) * sc.h
        truth = {p: float(v) for p, v in sc.truth_at(min(k + chunk, sc.u.size) - 1).items()}
        within_since = (within_since or t) if _within(est.estimate, truth) else None
    assert within_since is not None and within_since - sc.change_time < 2.0, (within_since, sc.change_time)


def test_a_calm_window_is_refitted_less_often_and_a_change_restores_the_pace():
    """Re-fits that move nothing double their period up to the change test's (``tracker.CALM_MOVE``): two per
    second on a settled window instead of ten; after a stiffness change the re-fits run every
    ``update_every_s`` again until the window is calm, and the estimate ends within the tolerances."""
    sc = scenarios.make("stiffness", 2)
    est = OnlineEstimator(sc.h)
    per_s = int(round(1.0 / sc.h))
    counts = []
    for k in range(0, sc.u.size, per_s):
        before = est._tracker.refits if est._tracker is not None else 0
        est.update_block(sc.u[k:k + per_s], sc.y[k:k + per_s])
        counts.append(est._tracker.refits - before)
    change = int(sc.change_time)
    assert max(counts[3:change]) <= 3, counts          # calm: every 0.5 s (10 per second at the base pace)
    assert max(counts[change:change + 4]) >= 6, counts  # after the change: back to every 0.1 s
    assert max(counts[-3:]) <= 3, counts                # calm again
    assert _within(est.estimate, sc.final_truth), _errors(est.estimate, sc.final_truth)


def test_a_start_up_correction_is_reported_as_such():
    """close_modes 7 (three modes, the start-up estimate a2 +650 % from a first step of 2 % of the next one): the
    change test corrects the start (detected at 1.5 s; at 2.5 s while the input gate fed the second step 2 ms late).
    The estimate it was judged against had not settled, so the event says so (``estimate_settled``
    False), alpha is neither restored from it nor held, and the quality reads "provisional", not "changing",
    while it settles; the text summary says it may correct the estimate rather than the plant."""
    from creep_online.commands._common import unsettled_note

    sc = scenarios.make("close_modes", 7)
    est = OnlineEstimator(sc.h)
    chunk = int(0.1 / sc.h)
    k = 0
    while not est.estimate.events and k < int(4.0 / sc.h):
        est.update_block(sc.u[k:k + chunk], sc.y[k:k + chunk])
        k += chunk
    ev = est.estimate.events
    assert len(ev) == 1 and ev[0]["estimate_settled"] is False and not ev[0]["settled"], ev
    assert est.estimate.quality == "provisional" and "estimate corrected" in est.estimate.reason
    assert "may correct the estimate" in unsettled_note(ev[0])
    est.update_block(sc.u[k:], sc.y[k:])
    truth = sc.final_truth
    assert _within(est.estimate, truth), _errors(est.estimate, truth)

def test_close_modes_the_resonance_stays_where_the_statistics_hold():
    """close_modes 0 (modes at 2.05 and 2.29 fn), sample by sample: the second step's beating is misfit at 3.5x
    the noise. Re-fits that moved the resonance beyond where the window's statistics hold (their first-order
    expansion around the linearization point) walked a1 to +1159 % and a2 onto the higher modes (-95 %) and the
    record ended at a1 +7.8 %. Within the trust region (``tracker.TRUST``) a2 stays on the first mode and the
    estimate ends within the tolerances of the best second-order description."""
    sc = scenarios.make("close_modes", 0)
    best = sc.truth_best
    est = OnlineEstimator(sc.h)
    chunk = int(0.1 / sc.h)
    a2_ratios = []
    for k0 in range(0, sc.u.size, chunk):
        for a, b in zip(sc.u[k0:k0 + chunk].tolist(), sc.y[k0:k0 + chunk].tolist()):
            est.update(a, b)
        if est.estimate.phase == "tracking":
            a2_ratios.append(est.estimate.a2 / best["a2"])
    assert 0.5 < min(a2_ratios) and max(a2_ratios) < 2.0, (min(a2_ratios), max(a2_ratios))
    assert _within(est.estimate, best), _errors(est.estimate, best)


def _reconvergence_s(est: OnlineEstimator, sc, single: bool) -> float:
    """Feed the record in 0.1 s chunks; seconds from the change until the estimate enters the tolerances
    for good (inf if it ends outside)."""
    chunk = int(0.1 / sc.h)
    back_within = math.inf
    for k0 in range(0, sc.u.size, chunk):
        u, y = sc.u[k0:k0 + chunk], sc.y[k0:k0 + chunk]
        if single:
            for a, b in zip(u.tolist(), y.tolist()):
                est.update(a, b)
        else:
            est.update_block(u, y)
        t = min(k0 + chunk, sc.u.size) * sc.h
        inside = _within(est.estimate, sc.truth_at(min(k0 + chunk, sc.u.size) - 1))
        if t > sc.change_time and inside and math.isinf(back_within):
            back_within = t
        elif not inside:
            back_within = math.inf
    return back_within - sc.change_time


@pytest.mark.parametrize("family, seed", [("payload", 10), ("stiffness", 0)])
def test_the_search_after_a_change_uses_the_step_that_revealed_it(family, seed):
    """Sample by sample, re-convergence within 2.5 s.

    payload 10: the mass changes 0.3 s before a large step, the change test sees it 0.4 s after the step,
    and the next two steps are small. Searched on the samples after the detection, the resonance came out
    at the noise floor in a wrong basin and re-convergence took 4.2 s; searched from the input's last
    move it takes ~1.5 s. stiffness 0: the gain changes too, which shows during a hold at any instant, so
    the window restarts at the detection (from the last move it never re-converged).
    """
    sc = scenarios.make(family, seed)
    est = OnlineEstimator(sc.h)
    assert _reconvergence_s(est, sc, single=True) <= 2.5, (sc.params, est.estimate.events)


def test_a_damping_change_on_a_lightly_damped_mode_is_declared():
    """stiffness 18: a1 x0.70 on a 555 Hz mode with zeta 0.05. Its tests read 24-59 with a1 determined to
    5-8 %: under the old threshold (100) it was never declared and the window followed it by forgetting
    in 6.9 s; at 50 it is declared (a1 moved) and followed within 3.5 s."""
    sc = scenarios.make("stiffness", 18)
    est = OnlineEstimator(sc.h)
    assert _reconvergence_s(est, sc, single=False) <= 3.5, (sc.params, _errors(est.estimate, sc.final_truth))
    assert any("a1" in ev["moved"] and abs(ev["t"] - sc.change_time) < 1.5 for ev in est.estimate.events)


def test_a_change_the_test_cannot_see_is_found_by_the_sudden_misfit(monkeypatch):
    """payload 9 at 80 dB: mass +36 % on a 416 Hz, zeta 0.045 mode. The change test's fit starts at the old
    resonance and stays near it: a2's ln move of 0.31 came out as 0.003 and no change was declared. The window
    went from the floor to 6x it in 0.4 s (sudden), and the re-search on the samples after that finds a2 moved:
    declared as a change (``found_by`` "re-search") and followed within 3 s, sample by sample. (Before, the
    re-search searched the newest 2 s, half a second of the old plant among them, and took a1 +48 %; the window
    wandered at 40-50x the floor and re-converged 7.2 s after the change.)"""
    monkeypatch.setattr(scenarios, "SNR_DB", 80.0)
    sc = scenarios.make("payload", 9)
    est = OnlineEstimator(sc.h)
    assert _reconvergence_s(est, sc, single=True) <= 3.0, (sc.params, est.estimate.events)
    events = est.estimate.events
    assert len(events) == 1 and events[0]["found_by"] == "re-search" and events[0]["moved"] == ["a2"], events
    assert sc.change_time - 1.0 <= events[0]["t"] <= sc.change_time, events
    from creep_online.commands._common import event_line
    assert "a2 moved" in event_line(events[0]) and "found by re-searching a sudden misfit" in event_line(events[0])


def test_a_misfit_after_an_undetermined_estimate_is_no_change():
    """quiet start 8: the small first steps are fitted at the noise floor by a start-up estimate with alpha +7000 %
    (nothing determines it there); the first large step misfits at 3.8x. That is new excitation revealing a wrong
    estimate, not a change: the re-search frees alpha and no change is declared (taken for a sudden change, the
    search held that alpha and the estimate sat at alpha -83 % until 5.5 s; now alpha +1.0 % at 4 s). Sample
    by sample."""
    sc = scenarios.make("quiet_start", 8)
    est = OnlineEstimator(sc.h)
    k = int(4.0 / sc.h)
    for a, b in zip(sc.u[:k].tolist(), sc.y[:k].tolist()):
        est.update(a, b)
    e = est.estimate
    assert not e.events and abs(e.alpha / sc.alpha[0] - 1) < TOL["alpha"], (e.events, e.alpha / sc.alpha[0] - 1)


@pytest.mark.parametrize("family, seed", [("payload", 0), ("payload", 1), ("stiffness", 0)])
def test_abrupt_change_is_detected_named_and_followed(family, seed):
    sc = scenarios.make(family, seed)
    est = OnlineEstimator(sc.h)
    assert _reconvergence_s(est, sc, single=False) <= 3.0, (sc.params, _errors(est.estimate, sc.final_truth))
    e = est.estimate
    ev = [v for v in e.events if abs(v["t"] - sc.change_time) < 1.0]
    assert ev, e.events
    moved = set(ev[0]["moved"])
    assert ev[0]["estimate_settled"] is True       # judged against an estimate that stood: a plant change
    truly = {k for k in ("a1", "a2", "b") if abs(sc.final_truth[k] / sc.truth_at(0)[k] - 1) > 0.1}
    assert truly <= moved | {"b"} and moved <= truly | {"alpha", "b"}


def test_tracks_a_drifting_plant():
    """alpha +20 % and b +10 % over 60 s (square-wave input, 250 Hz).

    The drift rates follow it with or without forgetting; a window that neither
    forgets nor models drift averages over the whole record and lags.
    """
    h = 4e-3
    t = np.arange(int(75 / h)) * h
    base = CreepModel.from_resonance(0.05, 20.0, 0.2, 1.0)
    u = np.where(t >= 0.1, np.where(((t - 0.1) // 2) % 2 == 0, 1.0, -1.0), 0.0)
    ramp = np.clip((t - 10.0) / 60.0, 0.0, 1.0)
    alpha, b = 0.05 * (1 + 0.2 * ramp), 1.0 + 0.1 * ramp
    y = simulate_varying(t, u, alpha, base.a1, base.a2, b)
    y = y + np.random.default_rng(0).normal(0, 0.01 * np.sqrt(np.mean(y**2)), t.size)
    tracking = OnlineEstimator(h, window_s=5.0)
    growing = OnlineEstimator(h, window_s=None)
    static = OnlineEstimator(h, window_s=None, track_drift=False)
    errs, errs_none, errs_static = [], [], []
    for k0 in range(0, t.size, 2500):
        sl = slice(k0, k0 + 2500)
        for est in (tracking, growing, static):
            est.update_block(u[sl], y[sl])
        k = min(k0 + 2500, t.size) - 1
        if t[k] > 20:
            errs.append(abs(tracking.estimate.alpha / alpha[k] - 1))
            errs_none.append(abs(growing.estimate.alpha / alpha[k] - 1))
            errs_static.append(abs(static.estimate.alpha / alpha[k] - 1))
    assert max(errs) < 0.02
    assert max(errs_none) < 0.02
    assert tracking.estimate.b == pytest.approx(b[-1], rel=0.01)
    assert growing.estimate.b == pytest.approx(b[-1], rel=0.01)
    assert max(errs_static) > 2 * max(errs)     # neither forgetting nor rates: it lags


DRIFT_SEEDS = (100, 101, 102, 103, 104, 105)     # not the bench's seeds 0-19 the drift model was developed on


@pytest.fixture(scope="module")
def drift_runs():
    """The drift family (alpha +10-20 %, b +5-10 % over 60 s at 2 kHz) on seeds the model was not tuned on."""
    runs = []
    for seed in DRIFT_SEEDS:
        sc = scenarios.make("drift", seed)
        est = OnlineEstimator(sc.h)
        est.update_block(sc.u, sc.y)
        runs.append((sc, est.estimate))
    return runs


def test_drift_family_is_followed(drift_runs):
    """alpha and b are the values now, not window averages: within tolerance at the end of the drift.

    The damping is another matter in this family: small staircase steps on a large level at
    40 dB leave a1 with a 1-sigma of 5-10 % even over the whole record, so a miss of a1 or a2
    must only never read "good".
    """
    creep_ok = 0
    for sc, e in drift_runs:
        err = _errors(e, sc.final_truth)
        creep_ok += err["alpha"] < TOL["alpha"] and err["b"] < TOL["b"]
        if not _within(e, sc.final_truth):
            assert e.quality != "good", (sc.seed, err, e.reason)
    assert creep_ok >= 5, [(sc.seed, _errors(e, sc.final_truth)) for sc, e in drift_runs]


def test_drift_family_reports_honest_uncertainty_and_rates(drift_runs):
    """Errors of alpha and b lie within 3 reported sigma; the drift rates have the drift's sign."""
    honest = 0
    for sc, e in drift_runs:
        err = {k: abs(getattr(e, k) - sc.final_truth[k]) for k in ("alpha", "b")}
        honest += all(err[k] <= 3.0 * e.uncertainty[k] for k in err)
        if e.rate_uncertainty:                  # the rates are on: both grow in this family
            assert e.b_rate / e.b > 0 and e.alpha_rate > 0, (sc.seed, e.b_rate, e.alpha_rate)
            assert set(e.rate_uncertainty) == {"b_rate", "alpha_rate"}
        else:
            assert e.b_rate == 0.0 and e.alpha_rate == 0.0
    assert honest >= 5
    assert sum(bool(e.rate_uncertainty) for _, e in drift_runs) >= 5


def test_no_drift_rates_from_a_single_step(load_cell):
    """One step cannot tell a drifting gain from creep: the rates stay off and alpha keeps its accuracy."""
    model, t, u, y = load_cell
    est = OnlineEstimator(5e-3)
    est.update_block(u, y)
    e = est.estimate
    assert e.b_rate == 0.0 and e.alpha_rate == 0.0 and e.rate_uncertainty == {}
    assert _within(e, _truth(model), scale=0.25)


# ---------------------------------------------------------------------- robustness (issue 14)
@pytest.fixture(scope="module")
def stepping():
    """10 kHz, steps every second, 14 s: the reference run for the outlier tests."""
    h = 1e-4
    t = np.arange(int(14 / h)) * h
    rng = np.random.default_rng(3)
    u = rng.uniform(-1, 1, 15)[np.floor(t).astype(int)]
    model = CreepModel.from_resonance(0.05, 250.0, 0.1, 1.0)
    y = simulate(model, t, u)
    y = y + rng.normal(0, 0.01 * np.std(y), t.size)
    ref = OnlineEstimator(h)
    ref.update_block(u, y)
    return h, u, y, ref.estimate


@pytest.mark.parametrize("where, value", [("y", 1e6), ("y", -1e300), ("u", 1000.0), ("u", 1e300)])
def test_single_outlier_moves_nothing(stepping, where, value):
    h, u, y, ref = stepping
    u2, y2 = u.copy(), y.copy()
    k = 103_217                                           # 10.3 s: past the search, between steps
    (y2 if where == "y" else u2)[k] = value
    est = OnlineEstimator(h)
    est.update_block(u2, y2)
    e = est.estimate
    for name in ("alpha", "b", "a1", "a2"):
        assert getattr(e, name) == pytest.approx(getattr(ref, name), rel=0.2 * TOL[name])
    assert (e.outliers if where == "y" else e.input_outliers) >= 1
    assert e.quality == "good", e.reason


@pytest.mark.parametrize("mode", ["single", "block"])
def test_a_real_step_far_beyond_the_first_one_reaches_the_model_on_time(mode, monkeypatch):
    """Payload seed 3004 at 80 dB: a first step of 0.023, the second (1.07 s) to -0.67, 30 ranges away: a glitch
    candidate for the input gate. It stays, so it is a move, and the model must see it when it came. (Held for
    burst_s and then fed, the step reached the model 2 ms late: the window sat at 390x the noise floor from 1.11 s
    on, alpha -25 %, and a re-search took a wrong resonance; re-convergence after the later payload change 5.4 s.)
    Nothing is counted as an input outlier, and the estimate stays at the noise floor and within the tolerances."""
    monkeypatch.setattr(scenarios, "SNR_DB", 80.0)
    sc = scenarios.make("payload", 3004)
    k = int(1.5 / sc.h)
    assert abs(sc.u[int(1.08 / sc.h)]) > 20 * abs(sc.u[int(0.5 / sc.h)])
    est = OnlineEstimator(sc.h)
    if mode == "block":
        est.update_block(sc.u[:k], sc.y[:k])
    else:
        for a, b in zip(sc.u[:k].tolist(), sc.y[:k].tolist()):
            est.update(a, b)
    e = est.estimate
    assert e.input_outliers == 0 and e.outliers == 0
    assert e.residual_rms < 2.0 * e.noise_rms, e.residual_rms / e.noise_rms
    assert _within(e, sc.truth_at(k - 1)), _errors(e, sc.truth_at(k - 1))


@pytest.mark.parametrize("mode", ["single", "block"])
def test_a_glitch_run_is_held_counted_and_caught_up(stepping, mode):
    """Five input samples at 1000 (10.3 s, between steps) and back: a glitch. They are kept back until the input
    returns, then fed with the last plausible input: counted exactly (5), the estimate as without them; the samples
    kept back are all fed (per sample: a few per update(), caught up within the next ~5 calls)."""
    h, u, y, ref = stepping
    u2 = u.copy()
    u2[103_217:103_222] = 1000.0
    est = OnlineEstimator(h)
    if mode == "block":
        est.update_block(u2, y)
    else:
        for a, b in zip(u2.tolist(), y.tolist()):
            est.update(a, b)
    e = est.estimate
    assert e.input_outliers == 5 and e.samples == u.size
    assert not est._held and not est._backlog
    for name in ("alpha", "b", "a1", "a2"):
        assert getattr(e, name) == pytest.approx(getattr(ref, name), rel=0.2 * TOL[name])
    assert e.quality == "good", e.reason


def test_input_gate_zero_takes_every_input_and_determined_matches_quality(stepping):
    """``input_gate=0``: inputs the caller computed (a compensator's commands) are never held as glitches;
    ``determined`` holds all four parameters exactly when the quality is good."""
    h, u, y, ref = stepping
    u2 = u.copy()
    u2[103_217] = 1000.0
    est = OnlineEstimator(h, input_gate=0)
    est.update_block(u2, y)
    assert est.estimate.input_outliers == 0 and est.get_params()["input_gate"] == 0
    assert ref.quality == "good" and sorted(ref.determined) == ["a1", "a2", "alpha", "b"]
    with pytest.raises(DataError, match="input_gate"):
        OnlineEstimator(h, input_gate=-1.0)


def test_frozen_sensor_is_flagged_within_half_a_second(stepping):
    h, u, y, _ = stepping
    y2 = y.copy()
    k0 = 100_000
    y2[k0:] = y2[k0]
    est = OnlineEstimator(h)
    est.update_block(u[:k0], y2[:k0])
    flagged = None
    for k in range(k0, k0 + 20_000):
        est.update(u[k], y2[k])
        if "frozen" in est.estimate.reason:
            flagged = (k - k0) * h
            break
    assert flagged is not None and flagged <= 0.5
    assert est.estimate.quality == "degraded"


def test_an_input_that_stops_moving_is_not_reported_good(load_cell):
    """Issue 14: an input that does not excite the plant is said so in quality, never "good"."""
    model, t, u, y = _plant(0.06, 6.0, 0.1, 0.02, 5e-3, 30.0, 50.0, 0.1)
    est = OnlineEstimator(5e-3, window_s=5.0)
    est.update_block(u, y)          # one step at 0.1 s, then 30 s of the same input
    e = est.estimate
    assert e.quality == "provisional" and "input constant" in e.reason
    assert _within(e, _truth(model))             # the estimate itself stays where the data put it


def test_wrong_model_is_not_reported_good():
    """Honest quality: a plant outside the model (a strong second mode) never reads 'good'."""
    h = 1e-4
    t = np.arange(int(6 / h)) * h
    u = np.floor(t) % 2
    first = simulate(CreepModel.from_resonance(0.05, 200.0, 0.1, 1.0), t, u)
    second = simulate(CreepModel.from_resonance(0.05, 900.0, 0.02, 0.5), t, u)
    y = first + second + np.random.default_rng(0).normal(0, 1e-3, t.size)
    est = OnlineEstimator(h)
    est.update_block(u, y)
    assert est.estimate.quality != "good"
    assert est.estimate.reason


def test_a_small_model_error_is_named_and_the_creep_part_still_determined():
    """close_modes 14 at 40 dB (two unmodeled modes 1.3-2.5x above the first): the best second-order fit leaves
    ~1.5x the noise floor. That is below "degraded" (2x) but not the floor: the estimate reads "provisional"
    with the misfit as its reason (it read "good" while the floor check was 2x), and it still names alpha and b
    determined (what a compensator's gate takes) and sits within the tolerances of the best second-order fit."""
    sc = scenarios.make("close_modes", 14)
    est = OnlineEstimator(sc.h)
    est.update_block(sc.u, sc.y)
    e = est.estimate
    ratio = e.residual_rms / e.noise_rms
    assert 1.2 < ratio < 2.0, ratio
    assert e.quality == "provisional" and e.reason.startswith("window error"), (e.quality, e.reason)
    assert {"alpha", "b"} <= set(e.determined)
    tol = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
    assert all(abs(getattr(e, p) / sc.truth_best[p] - 1) < tol[p] for p in tol), _errors(e, sc.truth_best)


def test_right_model_windows_end_within_the_good_ratio_of_the_floor():
    """The other side of GOOD_RATIO: payload and stiffness changes, a controller's staircase and a start in
    operation (one seeded plant each, 40 dB) end with the window at the floor within 1.2x and read "good"."""
    from creep_online.online.settings import QualitySettings
    GOOD_RATIO = QualitySettings().good_ratio
    for family, seed in (("payload", 1), ("stiffness", 2), ("controller", 3), ("mid_operation", 4)):
        sc = scenarios.make(family, seed)
        est = OnlineEstimator(sc.h)
        est.update_block(sc.u, sc.y)
        e = est.estimate
        assert e.residual_rms / e.noise_rms < GOOD_RATIO and e.quality == "good", (family, seed, e.reason)


# ---------------------------------------------------------------------- guard rails and API
def test_nonfinite_samples_are_skipped_and_counted(load_cell):
    model, t, u, y = load_cell
    u2, y2 = u.copy(), y.copy()
    bad = np.random.default_rng(5).choice(np.arange(50, u.size), 40, replace=False)
    y2[bad[:20]] = np.nan
    u2[bad[20:30]] = np.inf
    y2[bad[30:]] = -np.inf
    est = OnlineEstimator(5e-3)
    est.update_block(u2[:1000], y2[:1000])
    for k in range(1000, u.size):
        est.update(u2[k], y2[k])
    assert est.skipped_nonfinite == 40
    assert est.samples == u.size - 40
    assert _within(est.estimate, _truth(model))


def test_lost_samples_advance_time(load_cell):
    model, t, u, y = load_cell
    est = OnlineEstimator(5e-3)
    keep = np.ones(u.size, bool)
    keep[[600, 601, 602, 1500]] = False
    for k in range(u.size):
        if keep[k]:
            est.update(u[k], y[k])
        elif keep[k - 1]:
            est.gap(int(np.argmax(keep[k:])))
    assert est.gaps == 4 and est.samples == u.size
    assert _within(est.estimate, _truth(model))


def test_estimate_is_finite_before_any_model():
    est = OnlineEstimator(1e-3)
    e = est.estimate
    assert isinstance(e, OnlineEstimate)
    assert e.phase == "buffering" and e.quality == "none" and e.reason
    # not yet estimated: None, never 0.0 (JSON null)
    assert all(getattr(e, k) is None for k in ("alpha", "a1", "a2", "b", "fn_hz", "zeta", "offset", "t_c",
                                               "noise_rms", "residual_rms", "b_rate", "alpha_rate"))
    assert json.loads(json.dumps(e.to_dict()))["alpha"] is None and e.frozen is False
    assert est.model is None and est.last_prediction is None and est.predict_one(1.0) is None
    for _ in range(5000):
        est.update(0.0, 0.01)          # no excitation: nothing to identify, memory stays bounded
    assert est.estimate.phase == "buffering" and est._startup.nbuf <= 4096
    assert set(e.to_dict()) >= {"alpha", "a1", "a2", "b", "phase", "quality", "reason", "uncertainty", "t",
                                "samples", "events", "outliers", "input_outliers"}


def test_freeze_unfreeze_and_reset():
    model, t, _, _ = _plant(0.06, 6.0, 0.1, 0.02, 5e-3, 12.0, 50.0, 0.1)
    u = np.where(t < 0.1, 0.0, 50.0 * (1 + (np.floor(t) % 2)))     # steps every second: b is identifiable
    y = simulate(model, t, u) + np.random.default_rng(2).normal(0, 0.01, t.size)
    est = OnlineEstimator(5e-3, window_s=1.0)
    est.update_block(u[:1200], y[:1200])
    est.freeze()
    before = est.estimate
    est.update_block(u[1200:1800], y[1200:1800] * 1.2)     # would change b by 20 %
    after = est.estimate
    assert after.b == pytest.approx(before.b, rel=1e-3)
    assert after.samples == 1800
    est.unfreeze()
    est.update_block(u[1800:], y[1800:] * 1.2)
    assert est.estimate.b > 1.1 * before.b                 # adapting again
    est.reset()
    e = est.estimate
    assert e.phase == "buffering" and e.samples == 0 and est.skipped_nonfinite == 0 and est.model is None


def test_predict_one_and_learn_one(load_cell):
    model, t, u, y = load_cell
    est = OnlineEstimator(5e-3)
    for k in range(u.size - 1):
        est.learn_one(u[k], y[k])
    clean = simulate(model, t, u)[-1]
    assert est.predict_one(u[-2]) == pytest.approx(clean, rel=0.01)


def test_parameters_are_stored_verbatim_and_round_trip():
    est = OnlineEstimator(2e-4, window_s=5.0, alpha0=0.3, alpha_bounds=(0.01, 0.9), work_units=2,
                          track_drift=False)
    params = est.get_params()
    assert params["track_drift"] is False
    assert params["dt"] == 2e-4 and params["window_s"] == 5.0 and params["alpha_bounds"] == (0.01, 0.9)
    assert params["update_every_s"] == 0.1 and params["work_units"] == 2
    clone = OnlineEstimator(**params)
    assert clone.get_params() == params


@pytest.mark.parametrize("kwargs", [{"dt": 0.0}, {"dt": float("nan")}, {"dt": 1e-3, "alpha0": 1.5},
                                    {"dt": 1e-3, "t_c": -1.0}, {"dt": 1e-3, "window_s": 0.0},
                                    {"dt": 1e-3, "alpha_bounds": (0.9, 0.1)}, {"dt": 1e-3, "t_c_max": -1.0},
                                    {"dt": 1e-3, "update_every_s": 0.0}, {"dt": 1e-3, "work_units": 0},
                                    {"dt": 1e-3, "outlier_gate": -1.0}, {"dt": "fast"},
                                    {"dt": 1e-3, "track_drift": "yes"}])
def test_bad_parameters_raise_one_line_errors(kwargs):
    dt = kwargs.pop("dt")
    with pytest.raises(DataError) as info:
        OnlineEstimator(dt, **kwargs)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("u, y", [(None, 1.0), ("x", 1.0), (1.0, [1, 2])])
def test_update_rejects_non_numbers_with_the_library_error(u, y):
    est = OnlineEstimator(1e-3)
    with pytest.raises(CreepOnlineError):
        est.update(u, y)


def test_update_block_rejects_two_dimensional_and_mismatched_arrays():
    est = OnlineEstimator(1e-3)
    with pytest.raises(CreepOnlineError):
        est.update_block(np.zeros((10, 2)), np.zeros((10, 2)))
    with pytest.raises(CreepOnlineError):
        est.update_block(np.zeros(10), np.zeros(9))


def test_long_forgetting_run_has_no_overflow():
    """The forgetting weight g = f^-n is renormalised: a short window over many samples stays finite."""
    from hil_sim.varying_plant import PlantStream
    h = 1e-3
    model = CreepModel.from_resonance(0.05, 20.0, 0.2, 1.0)
    plant = PlantStream(h, model.alpha, model.a1, model.a2, model.b)
    t = np.arange(100_000) * h
    u = np.where(((t // 2) % 2) == 0, 1.0, 0.5)
    y = plant.step_block(u) + np.random.default_rng(1).normal(0, 0.005, t.size)
    est = OnlineEstimator(h, window_s=0.5)
    est.update_block(u, y)
    e = est.estimate
    assert all(math.isfinite(v) for v in (e.alpha, e.a1, e.a2, e.b))
    assert e.alpha == pytest.approx(0.05, rel=0.15)   # a 0.5 s window is noisy


@pytest.mark.xfail(strict=True, raises=AssertionError, reason="no read at 0.1 s steps says the last second "
                   "disagrees (1.1 s of good while outside, within the bound): " + _PER_SAMPLE)
def test_a_sub_threshold_change_reads_changing_not_good(monkeypatch):
    """Issue 8 item 6: stiffness scenario 13 (a damping change, a1 x0.72, at 7.1 s) is tested at statistics above 20 with
    a determined move for a second before the change is declared; that second read "good" with the estimate
    outside the tolerances. A disagreement (a move that counts as a change, statistic above 20, below the
    detection threshold) now reads "changing". Without it: 2.4 s of "good" while outside. (At the
    detection threshold of 50 this change is declared at its first test; the threshold it was found at,
    100, keeps it below.)"""
    monkeypatch.setattr(tracker_module, "DEFAULT", replace(
        TRACKER_DEFAULTS, change_rule=replace(TRACKER_DEFAULTS.change_rule, threshold=100.0)))
    sc = scenarios.make("stiffness", 13)
    est = OnlineEstimator(sc.h)
    good_outside, reasons = 0.0, []
    for k in range(0, sc.u.size, 1000):
        est.update_block(sc.u[k:k + 1000], sc.y[k:k + 1000])
        e = est.estimate
        truth = sc.truth_at(k + 999)
        if e.quality == "good" and not all(abs(getattr(e, p) / truth[p] - 1) <= TOL[p] for p in TOL):
            good_outside += 0.1
        reasons.append(e.reason)
    assert any(r.startswith("the last second disagrees") for r in reasons)
    assert good_outside <= 1.6


def test_a_slow_resonance_found_wrong_at_the_start_is_searched_again_and_followed():
    """strong_creep seed 3016 (a fresh seed: 1.2 Hz, zeta 0.075 at 10 kHz, a random staircase of 5-50 ms holds):
    the start-up search's 2 s took a 0.37 Hz, zeta 0.004 resonance with alpha 0.90 and b of the wrong sign (the
    window at ~110x the noise floor). Two things kept it there to the end (alpha +274 %, a2 +1900 %): the
    re-search's far better result (likelihood ratio 77614) was refused for its gain's sign, and the change test's
    post-change search waited one settling time of that wrong resonance (437 s) with the window not fitting. A
    gross misfit now lets the sign flip and that wait is capped by what the search holds."""
    sc = scenarios.make("strong_creep", 3016)
    est = OnlineEstimator(sc.h)
    est.update_block(sc.u, sc.y)
    e = est.estimate
    assert _within(e, sc.final_truth) and e.quality == "good", (_errors(e, sc.final_truth), e.reason)
    assert any(r["switched"] and r["relative_change"]["b"] < -1.0 for r in e.researches), e.researches


def test_a_change_that_never_settles_reads_degraded_once_the_window_misses_the_data(load_cell, monkeypatch):
    """An unsettled change event said "changing" / "estimate corrected" for as long as it stayed unsettled, and
    masked a window at 115x the noise floor for 9 s (strong_creep 3016 before its fix). After its first 1.5 s
    it yields to "degraded" when the window is above the floor ratio; below, it still names the change."""
    from creep_online.online.policy import quality as quality_module
    t, u, y = load_cell[1:]
    est = OnlineEstimator(t[1] - t[0])
    est.update_block(u, y)
    now = est.estimate.t
    est._tracker.events.append({"kind": "change", "t": now - 3.0, "detected_t": now - 2.0, "moved": ["a1"],
                                "settled": False, "estimate_settled": False})
    monkeypatch.setattr(quality_module, "floor_ratio", lambda view: 50.0)
    assert est.estimate.quality == "degraded" and est.estimate.reason.startswith("window error 50")
    monkeypatch.setattr(quality_module, "floor_ratio", lambda view: 1.1)
    assert est.estimate.quality == "provisional" and "had not settled" in est.estimate.reason
    est._tracker.events[-1]["detected_t"] = now - 1.0             # within its first 1.5 s: the change is named
    monkeypatch.setattr(quality_module, "floor_ratio", lambda view: 50.0)
    assert est.estimate.reason.startswith("estimate corrected"), est.estimate.reason
    assert est._settings.quality.floor_ratio < 50.0


def test_the_grid_planned_on_idle_calls_is_the_searchs_own_and_changes_nothing(monkeypatch):
    """The start-up search's grid frequencies are computed ahead on idle buffering calls (a few numpy calls per
    call) for the rows the search will take, and the search is built ahead on the next: it is the search that
    runs, its frequencies exactly bit for bit the frequencies an
    estimator without the plan computes in the search's first unit; that unit is then saved (the estimates
    land a sample earlier), and the stream ends at the same estimate: within a quarter of its reported 1-sigma
    (the re-fits then run on windows a sample apart; measured 0.12 sigma for alpha, 0.09 for b)."""
    _, _, u, y = _plant(0.2, 150.0, 0.1, 1.3, 1e-4, 0.6, 1.0, 0.05)

    def run() -> tuple[OnlineEstimator, np.ndarray, bool | None]:
        est, planned = OnlineEstimator(1e-4), None
        for a, b in zip(u.tolist(), y.tolist()):
            plan = est._startup.grid_plan
            est.update(a, b)
            search = est._startup.search
            if plan is not None and plan.freqs is not None and search is not None and planned is None:
                planned = search._freqs is plan.freqs and search is plan.search
        return est, est._startup.search._freqs, planned

    est, ahead, planned = run()
    assert planned and est.phase == "tracking"
    monkeypatch.setattr(Startup, "plan_grid", lambda self: None)
    direct, computed, never = run()
    assert never is None
    assert np.array_equal(ahead, computed)
    a, d = est.estimate, direct.estimate
    assert a.quality == d.quality == "good" and a.events == d.events
    for name in ("alpha", "a1", "a2", "b"):
        assert abs(getattr(a, name) - getattr(d, name)) <= 0.25 * a.uncertainty[name], name


def test_a_frozen_estimate_says_so_and_judges_itself_on_another_plant():
    """After freeze(), a plant with fn 200 Hz instead of 300 Hz and twice the gain for 4 s: the estimate stays, is
    ``frozen`` (in to_dict() too), never reads "good", and names its misfit (before, "good" with no reason)."""
    from hil_sim.scenarios import simulate_tv
    h = 1e-4

    def record(fn: float, b: float, n: int, seed: int):
        a1, a2 = 2 * 0.05 / (2 * math.pi * fn), 1 / (2 * math.pi * fn) ** 2
        t = np.arange(n) * h
        u = np.where(t < 0.05, 0.0, np.floor(t / 0.5) % 3 - 1.0)
        y = simulate_tv(h, u, 0.1, a1, a2, b)
        return u, y + np.random.default_rng(seed).normal(0, 1e-3, n)

    u, y = record(300.0, 1.0, 60000, 0)
    est = OnlineEstimator(h)
    est.update_block(u, y)
    assert est.estimate.quality == "good" and est.estimate.frozen is False
    est.freeze()
    held = est.estimate
    same_u, same_y = record(300.0, 1.0, 70000, 1)
    est.update_block(same_u[60000:], same_y[60000:])
    e = est.estimate
    assert e.frozen and e.quality == "provisional" and "frozen" in e.reason, e.reason     # still predicts well
    other_u, other_y = record(200.0, 2.0, 110000, 2)
    est.update_block(other_u[70000:], other_y[70000:])
    e = est.estimate
    assert e.to_dict()["frozen"] is True
    assert e.quality == "degraded" and "frozen" in e.reason and "misses the data" in e.reason, e.reason
    assert e.alpha == pytest.approx(held.alpha, rel=1e-4) and e.b == pytest.approx(held.b, rel=1e-4)
    est.unfreeze()
    assert est.estimate.frozen is False
