"""The error contract of OnlineEstimator for internal faults (docs/online.md, "Error contract").

Real faults are injected into one kernel or one job of a real estimator (a ZeroDivisionError at its k-th
call, or NaN written into the parameters), never a mock of the estimator: update(), update_block(), gap()
and estimate must not raise, the fault must be counted and recorded as an event, the quality must read
"degraded" with the fault as reason, and the estimator must re-converge to the truth afterwards.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.errors import DataError
from creep_online.model import CreepModel
from creep_online.online import OnlineEstimator
from creep_online.online.policy import quality as quality_module
from creep_online.online.trackers import recursive as recursive_module   # (the tracker's and the estimator's ``sample``)
from creep_online.online._kernels import fit_machine as refit_module
from creep_online.online import search as search_module
from creep_online.online.trackers import window as tracker_module
from creep_online.online.trackers.scheduler import Scheduler
from creep_online.online._kernels import window as window_module
from creep_online.simulate import simulate
from hil_sim import scenarios

TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
H = 5e-4


@pytest.fixture(scope="module")
def staircase():
    """2 kHz, a random staircase (0.5 s holds) from rest, 16 s: alpha 0.1, fn 40 Hz, zeta 0.1, b 0.8, 0.3 % noise."""
    t = np.arange(int(round(16.0 / H))) * H
    rng = np.random.default_rng(2)
    u = np.where(t < 0.05, 0.0, rng.uniform(-1, 1, 33)[np.floor(t / 0.5).astype(int)])
    model = CreepModel.from_resonance(0.1, 40.0, 0.1, 0.8)
    y = simulate(model, t, u)
    y = y + rng.normal(0, 0.003 * np.std(y), t.size)
    return {"alpha": model.alpha, "a1": model.a1, "a2": model.a2, "b": model.b}, u, y


def _errors(e, truth: dict) -> dict:
    return {k: abs(getattr(e, k) / truth[k] - 1) for k in TOL}


def _within(e, truth: dict) -> bool:
    return all(v < TOL[k] for k, v in _errors(e, truth).items())


def _fail_at(monkeypatch, owner, name: str, calls: set[int], exc: type[BaseException] = ZeroDivisionError) -> list:
    """Replace ``owner.name`` by a wrapper that raises ``exc`` at the listed calls (1-based) and otherwise calls the
    original; returns the call counter (one-element list)."""
    original = getattr(owner, name)
    count = [0]

    def faulty(*args, **kwargs):
        count[0] += 1
        if count[0] in calls:
            raise exc(f"injected at call {count[0]}")
        return original(*args, **kwargs)

    monkeypatch.setattr(owner, name, faulty)
    return count


def _feed(est: OnlineEstimator, u: np.ndarray, y: np.ndarray, watch: bool = True) -> list:
    """Sample by sample; returns (t, quality, reason) of the estimates read right after each new fault."""
    seen = []
    faults = 0
    for a, b in zip(u.tolist(), y.tolist()):
        est.update(a, b)
        if watch and est.internal_faults != faults:
            faults = est.internal_faults
            e = est.estimate
            seen.append((e.t, e.quality, e.reason))
    return seen


def _fault_events(e) -> list[dict]:
    return [ev for ev in e.events if ev.get("kind") == "internal_fault"]


def _check_recorded(est: OnlineEstimator, seen: list, error: str, where: str, recovery: str) -> dict:
    """One fault: counted, an event with its type, place and recovery, reported as degraded with it named."""
    e = est.estimate
    assert est.internal_faults == 1 and e.internal_faults == 1
    (ev,) = _fault_events(e)
    assert ev["error"] == error and ev["where"] == where and recovery in ev["recovery"], ev
    assert "injected" in ev["message"] or error == "NonFiniteState"
    assert seen and seen[0][1] == "degraded" and error in seen[0][2] and "internal fault" in seen[0][2], seen
    return ev


def test_a_fault_in_a_refit_job_drops_the_job(staircase, monkeypatch):
    truth, u, y = staircase
    _fail_at(monkeypatch, Scheduler, "after_accept", {5})
    est = OnlineEstimator(H)
    seen = _feed(est, u, y)
    ev = _check_recorded(est, seen, "ZeroDivisionError", "update", "dropped the refit job")
    e = est.estimate
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)
    assert e.t > ev["t"] > 0 and e.phase == "tracking"


def test_a_fault_in_the_per_sample_kernel_restarts_from_the_remembered_samples(staircase, monkeypatch):
    truth, u, y = staircase
    _fail_at(monkeypatch, refit_module, "sample_work", {200})
    est = OnlineEstimator(H)
    phases = []
    for a, b in zip(u.tolist(), y.tolist()):
        est.update(a, b)
        if est.internal_faults and (not phases or phases[-1] != est.phase):
            phases.append(est.phase)
    e = est.estimate
    (ev,) = _fault_events(e)
    assert ev["error"] == "ZeroDivisionError" and "tracker restarted" in ev["recovery"], ev
    assert phases[0] in ("buffering", "searching") and phases[-1] == "tracking", phases
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)
    assert e.samples == u.size


def test_a_fault_in_the_start_up_search_searches_again(staircase, monkeypatch):
    truth, u, y = staircase
    _fail_at(monkeypatch, search_module.ResonanceSearch, "step", {3})
    est = OnlineEstimator(H)
    seen = _feed(est, u, y)
    _check_recorded(est, seen, "ZeroDivisionError", "update", "start-up search starts again")
    e = est.estimate
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)


def test_a_start_up_fault_that_repeats_drops_the_buffer_and_starts_on_new_samples(staircase, monkeypatch):
    truth, u, y = staircase
    _fail_at(monkeypatch, search_module.ResonanceSearch, "step", {1, 2, 3})
    est = OnlineEstimator(H)
    _feed(est, u, y, watch=False)
    e = est.estimate
    assert est.internal_faults == 3
    assert "start-up buffer dropped" in _fault_events(e)[-1]["recovery"]
    assert e.phase == "tracking" and _within(e, truth), (e.phase, _errors(e, truth))


def test_a_fault_in_the_replay_of_the_start_up_buffer_searches_again(staircase, monkeypatch):
    """Sample by sample, the block kernel runs only while the new tracker replays the start-up buffer."""
    truth, u, y = staircase
    count = _fail_at(monkeypatch, window_module, "block", {2})
    est = OnlineEstimator(H)
    seen = _feed(est, u, y)
    assert count[0] > 2
    _check_recorded(est, seen, "ZeroDivisionError", "update", "start-up search starts again")
    e = est.estimate
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)


def test_a_fault_during_a_replay_restarts_and_follows_the_change(monkeypatch):
    """payload 4 (10 kHz, mass added at 8.5 s): replays follow the change; one of them breaks at 10 s, while the
    estimator re-converges after the change (restarted on the post-change samples, ~4 s to the truth)."""
    sc = scenarios.make("payload", 4)
    count = _fail_at(monkeypatch, window_module, "replay_units", {200})
    est = OnlineEstimator(sc.h)
    seen = _feed(est, sc.u, sc.y)
    assert count[0] > 200
    _check_recorded(est, seen, "ZeroDivisionError", "update", "tracker restarted")
    e = est.estimate
    assert _within(e, sc.final_truth), (_errors(e, sc.final_truth), e.reason)
    assert e.quality != "degraded", e.reason


def test_a_fault_in_update_block_loses_no_sample(staircase, monkeypatch):
    truth, u, y = staircase
    _fail_at(monkeypatch, window_module, "block", {20})
    est = OnlineEstimator(H)
    est.update_block(u, y)
    e = est.estimate
    (ev,) = _fault_events(e)
    assert ev["error"] == "ZeroDivisionError" and ev["where"] == "update_block", ev
    assert e.samples == u.size
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)


def test_nan_poisoning_of_the_parameters_is_found_and_restarted_from(staircase, monkeypatch):
    """A re-fit kernel that writes NaN into the estimate (no exception): the guard checks the state itself."""
    truth, u, y = staircase
    accept = Scheduler.accept
    count = [0]

    def poisoned(self, tr):
        count[0] += 1
        raw = accept(self, tr)
        if count[0] == 8:
            tr.theta[2] = math.nan
        return raw

    monkeypatch.setattr(Scheduler, "accept", poisoned)
    est = OnlineEstimator(H)
    seen = _feed(est, u, y)
    ev = _check_recorded(est, seen, "NonFiniteState", "update", "tracker restarted")
    e = est.estimate
    assert all(math.isfinite(v) for v in (e.alpha, e.a1, e.a2, e.b))
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)
    assert 0 < ev["t"] < e.t


def test_nan_poisoning_is_found_by_the_estimate_too(staircase):
    truth, u, y = staircase
    est = OnlineEstimator(H)
    n = u.size // 2
    est.update_block(u[:n], y[:n])
    est._tracker.S[0, 0] = math.inf              # poisoned statistics, between two scheduled checks
    tracker = est._tracker
    e = est.estimate
    assert e.quality == "degraded" and "NonFiniteState" in e.reason, e.reason
    # a read changes nothing: the same answer again, the same tracker, the fault recorded at the next sample fed
    assert est.estimate == e and est._tracker is tracker and est.internal_faults == 0
    est.update_block(u[n:], y[n:])
    e = est.estimate
    ev = _fault_events(e)[0]
    assert est.internal_faults == 1 and ev["where"] == "estimate" and ev["recovery"].startswith("tracker restarted")
    assert ev["t"] == n * H
    assert e.quality == "good", e.reason
    assert _within(e, truth), _errors(e, truth)


def test_a_fault_while_the_estimate_is_built_is_reported_not_raised(staircase, monkeypatch):
    truth, u, y = staircase
    est = OnlineEstimator(H)
    est.update_block(u, y)
    _fail_at(monkeypatch, quality_module, "residual", {1}, ValueError)
    e = est.estimate
    assert e.quality == "degraded" and "ValueError in estimate" in e.reason, e.reason
    assert est.internal_faults == 0                # recorded at the next sample fed, not by the read
    est.update(float(u[-1]), float(y[-1]))
    e = est.estimate
    assert est.internal_faults == 1
    assert _fault_events(e)[0]["recovery"].startswith("estimate reported")


def test_a_fault_in_gap_is_caught(staircase, monkeypatch):
    truth, u, y = staircase
    est = OnlineEstimator(H)
    est.update_block(u[:8000], y[:8000])
    _fail_at(monkeypatch, tracker_module.WindowTracker, "feed", {2})
    est.gap(5)
    assert est.samples == 8005 and est.gaps == 5
    assert est.internal_faults == 1 and _fault_events(est.estimate)[0]["where"] == "gap"


def test_a_fault_in_the_recursive_tracker_restarts_it(staircase, monkeypatch):
    """(Patched once the tracker runs: the module's other kernels call ``sample`` and would then fail to compile,
    a numba TypingError, which the guard also catches, at every start.)"""
    truth, u, y = staircase
    est = OnlineEstimator(H, refit="recursive")
    est.update_block(u[:4000], y[:4000])
    _fail_at(monkeypatch, recursive_module, "sample", {100})
    _feed(est, u[4000:], y[4000:], watch=False)
    e = est.estimate
    assert est.internal_faults == 1 and "new samples" in _fault_events(e)[0]["recovery"]
    assert e.phase == "tracking"
    assert abs(e.alpha / truth["alpha"] - 1) < TOL["alpha"] and abs(e.b / truth["b"] - 1) < TOL["b"], \
        _errors(e, truth)


def test_the_caller_s_errors_and_interrupts_still_raise(staircase, monkeypatch):
    truth, u, y = staircase
    est = OnlineEstimator(H)
    est.update_block(u[:8000], y[:8000])
    with pytest.raises(DataError):
        est.update("x", 1.0)
    with pytest.raises(DataError):
        est.update_block(u[:3], y[:4])
    _fail_at(monkeypatch, window_module, "sample", {1}, KeyboardInterrupt)
    with pytest.raises(KeyboardInterrupt):
        est.update(u[8000], y[8000])
    assert est.internal_faults == 0


def test_the_counter_is_in_the_estimate_dict_and_resets(staircase, monkeypatch):
    truth, u, y = staircase
    _fail_at(monkeypatch, Scheduler, "after_accept", {2})
    est = OnlineEstimator(H)
    est.update_block(u[:8000], y[:8000])
    d = est.estimate.to_dict()
    assert d["internal_faults"] == 1 and d["events"][0]["kind"] == "internal_fault"
    est.reset()
    assert est.internal_faults == 0 and est.estimate.internal_faults == 0 and est.events == []


@pytest.mark.parametrize("refit", ["window", "recursive"])
def test_the_input_gate_never_loses_duplicates_or_reorders_a_sample(refit):
    """Fuzz: streams with input glitches (runs of 1-5 samples at 50-500x the range) and a first step 100x smaller
    than the next, fed in random mixtures of update(), update_block() chunks and gap(): every sample reaches the
    tracker exactly once, in order (its own count plus the stream's offset plus what is still kept back equals
    ``samples``), none is lost or doubled by the gate's keeping back, and nothing raises or faults."""
    rng = np.random.default_rng(77)
    h, n = 1e-3, 6000
    t = np.arange(n) * h
    y_model = CreepModel.from_resonance(0.2, 40.0, 0.2, 1.0)
    counted = 0
    for _ in range(6):
        levels = rng.uniform(-1, 1, 12) * np.r_[0.01, np.ones(11)]
        u = levels[np.minimum((t / 0.5).astype(int), 11)]
        for _ in range(int(rng.integers(1, 6))):
            k, width = int(rng.integers(100, n - 10)), int(rng.integers(1, 6))
            u[k:k + width] = rng.choice([-1.0, 1.0]) * rng.uniform(50, 500)
        y = simulate(y_model, t, u) + rng.normal(0, 1e-3, n)
        est = OnlineEstimator(h, refit=refit)
        k = 0
        while k < n:
            m = int(rng.integers(1, 400))
            if rng.random() < 0.5:
                for a, b in zip(u[k:k + m].tolist(), y[k:k + m].tolist()):
                    est.update(a, b)
            else:
                est.update_block(u[k:k + m], y[k:k + m])
            if rng.random() < 0.05:
                est.gap(int(rng.integers(1, 5)))
            k += m
        e = est.estimate
        waiting = len(est._held) + len(est._backlog)
        assert e.samples == n + est.gaps and e.internal_faults == 0
        assert est._live is not None and est._n_shift + est._tracker.n + waiting == e.samples
        assert waiting <= est._burst + 2
        counted += e.input_outliers
    assert counted > 0                  # (a glitch before the input's range is known is no glitch: taken)


def test_a_glitch_kept_back_across_the_start_of_tracking_keeps_its_place():
    """A glitch whose samples are kept back while the start-up buffer is replayed into the tracker and the tracker
    goes live: the first live samples must wait behind it (taken at once, they would reach the tracker before the
    glitch's and the model would see the stream out of order). For glitches starting at each of the last samples
    before the tracker takes the stream directly, the tracker's count plus what waits equals the samples fed."""
    h = 1e-3
    t = np.arange(4000) * h
    u = np.where(t >= 0.1, 1.0, 0.0) + np.where(t >= 1.1, -0.6, 0.0)
    y = simulate(CreepModel.from_resonance(0.2, 40.0, 0.2, 1.0), t, u) + np.random.default_rng(5).normal(0, 1e-3, t.size)
    probe = OnlineEstimator(h)
    live_at = next(k for k, (a, b) in enumerate(zip(u.tolist(), y.tolist())) if probe.update(a, b) or probe._live)
    for start in range(live_at - 4, live_at + 2):
        u2 = u.copy()
        u2[start:start + 2] = 500.0           # (burst_s at 1 kHz: 2 samples; a third would make it a move)
        est = OnlineEstimator(h)
        for k, (a, b) in enumerate(zip(u2.tolist(), y.tolist())):
            est.update(a, b)
            if est._live is not None:
                waiting = len(est._held) + len(est._backlog)
                assert est._n_shift + est._tracker.n + waiting == est.samples, (start, k)
        assert est.estimate.input_outliers == 2
