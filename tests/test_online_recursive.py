"""The recursive tracker (Remark 3's second strategy, ``OnlineEstimator(refit="recursive")``).

Kernels against independent references (the exact closed-form simulator
``creep_online.simulate``): the prediction, its gradient psi = C^T phi, and the
states carried on when the linearization point moves. Then the estimator on
random plants over the issue's ranges (seeds not used while tuning), a payload
change, the outlier gate, missing outputs, and the parameter contract.
Tolerances are the issue's: alpha 2 %, b 3 %, a1 and a2 5 %.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from creep_online.errors import DataError
from creep_online.model import CreepModel
from creep_online.online import OnlineEstimator
from creep_online.online.trackers import recursive as R
from creep_online.online._kernels import window as W
from creep_online.online.soe import SOE_TOP, SoeBasis
from creep_online.simulate import simulate
from hil_sim import scenarios

TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}


def _errors(e, truth: dict) -> dict:
    """Relative errors; inf for a value not yet estimated (None)."""
    return {k: math.inf if getattr(e, k) is None else abs(getattr(e, k) / truth[k] - 1) for k in TOL}


def _within(e, truth: dict) -> bool:
    return all(v < TOL[k] for k, v in _errors(e, truth).items())


# ---------------------------------------------------------------------- kernels against the exact simulator
H = 1e-4
MODEL = CreepModel.from_resonance(0.2, 300.0, 0.1, -1.5)


def _frozen_tracker(model: CreepModel) -> R.RecursiveTracker:
    """A tracker at the model's parameters that never adapts (states and predictions only)."""
    basis = SoeBasis.build(H, horizon_s=10.0, top=SOE_TOP)
    theta = np.array([model.alpha, math.log(model.a1), math.log(model.a2), model.b, 0.0])
    tr = R.RecursiveTracker(basis, theta, window_s=10.0, free=False, gate=0.0, burst=2, stuck=500,
                            alpha_bounds=(0.005, 0.95), refit_every=1000, detect=False, scale=1.0)
    tr.sc[W.SC_ACC] = 0.0
    return tr


def _record(n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * H
    return t, np.where(t >= 0.01, 1.0, 0.0) + np.where(t >= 0.17, -1.7, 0.0)


def _predictions(tr: R.RecursiveTracker, u: np.ndarray) -> np.ndarray:
    """Prediction of each sample (the tracker's output before the sample is applied)."""
    out = np.empty(u.size)
    for k, uk in enumerate(u):
        tr.feed(float(uk), math.nan)
        out[k] = tr.prediction
    return out


def test_prediction_matches_the_exact_simulator():
    t, u = _record()
    pred = _predictions(_frozen_tracker(MODEL), u)
    ref = simulate(MODEL, t, u)          # sample k is predicted before u[k] is applied (zero-order hold)
    assert np.max(np.abs(pred - ref)) < 2e-4 * np.ptp(ref)


@pytest.mark.parametrize("j", [0, 1, 2, 3])
def test_gradient_matches_finite_differences_of_the_exact_simulator(j):
    """psi = C^T phi (the RPEM's gradient) against central differences of the closed-form output."""
    t, u = _record()
    tr = _frozen_tracker(MODEL)
    _predictions(tr, u[:-1])
    psi = tr.CT @ tr.phi
    theta = np.array([MODEL.alpha, math.log(MODEL.a1), math.log(MODEL.a2), MODEL.b])
    d = 1e-4

    def out(th: np.ndarray) -> float:
        m = CreepModel(th[0], math.exp(th[1]), math.exp(th[2]), th[3])
        return float(simulate(m, t[:-1], u[:-1])[-1])
    hi, lo = theta.copy(), theta.copy()
    hi[j] += d
    lo[j] -= d
    fd = (out(hi) - out(lo)) / (2 * d)
    scale = max(abs(fd), 1e-3 * abs(MODEL.b))
    assert psi[j] == pytest.approx(fd, abs=5e-3 * scale)


def test_linear_terms_have_unit_jacobian_rows():
    """The RPEM step reads the linear terms' gradient off their own phi entries (``LINEAR_FROM``): their rows of the
    Jacobian coefficients are unit vectors at ``q + ONE`` on, in a tracker taken in operation (offset and four
    free responses) after it has adapted."""
    from creep_online.online._kernels import recursive as RK
    scen = scenarios.make("mid_operation", 0)
    est = OnlineEstimator(scen.h, refit="recursive")
    est.update_block(scen.u[:30_000], scen.y[:30_000])
    tr = est._tracker
    q, n = tr.basis.size, tr.CT.shape[0]
    assert n > RK.LINEAR_FROM + 1
    for j in range(RK.LINEAR_FROM, n):
        unit = np.zeros(tr.CT.shape[1])
        unit[q + W.ONE + j - RK.LINEAR_FROM] = 1.0
        assert np.array_equal(tr.CT[j], unit)


def test_carried_states_follow_a_moved_resonance():
    """Moving a1, a2 by 0.5 % (the refresh tolerance) mid-record, states carried on to first order, no replay.

    Without the carry the prediction would jump to the full difference of the two models' ringing; with it
    the remaining error is under 15 % of that (measured 9 %; 52 % for a 3 % move, because the sensitivity
    states grow with the cycles rung since the last step: hence small, frequent refreshes), and it decays
    with the resonance: after settling the prediction is the exact simulation of the new model.
    """
    t, u = _record(4000)
    tr = _frozen_tracker(MODEL)
    k0 = 2000                                           # 0.2 s: after both input steps, still ringing
    _predictions(tr, u[:k0])
    new = CreepModel(MODEL.alpha, MODEL.a1 * 1.005, MODEL.a2 * 0.995, MODEL.b)
    tr.theta[1:3] = (math.log(new.a1), math.log(new.a2))
    R.refresh(tr.st, tr.CT)
    assert tr.relinearizations == 1                     # the linearization point moved once
    pred = _predictions(tr, u[k0:])
    ref = simulate(new, t, u)[k0:]
    old = simulate(MODEL, t, u)[k0:]
    gap = np.max(np.abs(old - ref))
    assert np.max(np.abs(pred - ref)[:50]) < 0.15 * gap
    assert np.max(np.abs(pred - ref)[-500:]) < 2e-4 * np.ptp(ref)


# ---------------------------------------------------------------------- the estimator
def _random_plants(count: int, seed: int) -> list[dict]:
    """The issue's ranges: alpha 0.005-0.7, fn 1 Hz..fs/4, zeta 0.01-1, gain of either sign over 3 decades."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        fs = float(rng.choice([2000.0, 10000.0]))
        out.append({"alpha": float(np.exp(rng.uniform(np.log(0.005), np.log(0.7)))),
                    "fn": float(np.exp(rng.uniform(np.log(1.0), np.log(fs / 4)))),
                    "zeta": float(np.exp(rng.uniform(np.log(0.01), np.log(1.0)))),
                    "b": float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-1.5, 1.5)), "fs": fs})
    return out


PLANTS = _random_plants(10, seed=20261123)


def _run_plant(p: dict, refit: str):
    """8 s from rest, a staircase with reversals; returns the final estimate, the truth and the start-up search's
    relative error in fn (where the tracker started)."""
    h = 1 / p["fs"]
    t = np.arange(int(8 / h)) * h
    u = np.where(t < 0.02, 0.0, np.floor(t / 0.5) % 3 - 1.0)
    model = CreepModel.from_resonance(p["alpha"], p["fn"], p["zeta"], p["b"])
    y = simulate(model, t, u)
    y = y + np.random.default_rng(1).normal(0, 0.003 * np.std(y), t.size)
    est = OnlineEstimator(h, refit=refit)
    est.update_block(u, y)
    truth = {"alpha": model.alpha, "a1": model.a1, "a2": model.a2, "b": model.b}
    start = est._startup.search.result
    start_fn_error = abs(math.sqrt(model.a2 / start.a2) - 1)
    return est.estimate, truth, start_fn_error


@pytest.fixture(scope="module")
def random_runs():
    return [_run_plant(p, "recursive") for p in PLANTS]


def test_converges_on_random_plants_from_a_start_in_the_basin(random_runs):
    """The recursion is local: wherever the start-up search's resonance is within 30 % of the truth in fn it
    converges to within the tolerances or says that its model misses the data (measured: 8 of the 10 plants start
    there, the slow 1-6 Hz ones too since a search on the box's edge asks for a longer window; 7 converge, and
    alpha 0.0067 at 5.8 Hz ends 2.7 % off reading "degraded", where the window tracker ends 0.15 % off), and a
    run that starts in a wrong basin never reports "good"."""
    inside = [_within(e, truth) for e, truth, _ in random_runs]
    in_basin = [err < 0.3 for *_, err in random_runs]
    print(f"recursive tracker: {sum(inside)} of {len(inside)} random plants within the tolerances, "
          f"{sum(in_basin)} started within 30 % of fn")
    assert sum(in_basin) >= 6 and sum(ok and basin for ok, basin in zip(inside, in_basin)) >= 6
    for p, (e, truth, err), ok, basin in zip(PLANTS, random_runs, inside, in_basin):
        assert ok or not basin or e.quality == "degraded", (p, err, _errors(e, truth), e.quality)
        assert ok or e.quality != "good", (p, e.quality, _errors(e, truth))


def test_follows_a_payload_change():
    """Payload (mass +25-60 %) at 6-10 s: detected (event at the change, a2 moved), re-converged within 3 s."""
    sc = scenarios.make("payload", 7)
    est = OnlineEstimator(sc.h, refit="recursive")
    chunk = int(0.1 / sc.h)
    back = None
    for k0 in range(0, sc.u.size, chunk):
        est.update_block(sc.u[k0:k0 + chunk], sc.y[k0:k0 + chunk])
        t = min(k0 + chunk, sc.u.size) * sc.h
        ok = _within(est.estimate, sc.final_truth)
        if t > sc.change_time and ok and back is None:
            back = t
        elif not ok:
            back = None
    e = est.estimate
    assert _within(e, sc.final_truth), (sc.params, _errors(e, sc.final_truth))
    assert back is not None and back - sc.change_time <= 3.0
    ev = [v for v in e.events if abs(v["t"] - sc.change_time) < 1.0]
    assert ev and ev[0]["settled"] and "a2" in ev[0]["moved"], e.events
    assert ev[0]["relative_change"]["a2"] == pytest.approx(sc.params["mass_ratio"] - 1, abs=0.05)


@pytest.fixture(scope="module")
def stepping():
    """10 kHz, steps every second, 12 s, and the recursive estimator's reference run on it."""
    h = 1e-4
    t = np.arange(int(12 / h)) * h
    rng = np.random.default_rng(11)
    u = rng.uniform(-1, 1, 13)[np.floor(t).astype(int)]
    model = CreepModel.from_resonance(0.08, 400.0, 0.15, 2.0)
    y = simulate(model, t, u)
    y = y + rng.normal(0, 0.01 * np.std(y), t.size)
    ref = OnlineEstimator(h, refit="recursive")
    ref.update_block(u, y)
    return h, u, y, ref.estimate, model


def test_reference_run_is_accurate_and_good(stepping):
    *_, ref, model = stepping
    truth = {"alpha": model.alpha, "a1": model.a1, "a2": model.a2, "b": model.b}
    assert _within(ref, truth), _errors(ref, truth)
    assert ref.quality == "good", ref.reason
    assert ref.events == [] and ref.b_rate == 0.0 and ref.alpha_rate == 0.0


def test_gate_rejects_an_outlier(stepping):
    h, u, y, ref, _ = stepping
    y2 = y.copy()
    y2[93_217] = 1e6                                  # 9.3 s: tracking, between steps
    est = OnlineEstimator(h, refit="recursive")
    est.update_block(u, y2)
    e = est.estimate
    assert e.outliers >= 1
    for name in ("alpha", "b", "a1", "a2"):
        assert getattr(e, name) == pytest.approx(getattr(ref, name), rel=0.2 * TOL[name])
    assert e.events == [] and e.quality == "good", e.reason


def test_missing_outputs_are_skipped(stepping):
    """NaN outputs: skipped and counted by update(); a lost sample (gap) advances time without an update."""
    h, u, y, ref, _ = stepping
    est = OnlineEstimator(h, refit="recursive")
    n = 100_000
    est.update_block(u[:n], y[:n])
    est.update(u[n], math.nan)
    est.gap(3)
    for k in range(n + 4, n + 2000):
        est.update(u[k], y[k])
    e = est.estimate
    assert e.skipped == 1 and est.gaps == 3 and e.samples == n + 2000 - 1
    assert all(math.isfinite(getattr(e, k)) for k in ("alpha", "a1", "a2", "b"))
    assert e.b == pytest.approx(ref.b, rel=TOL["b"])


def test_stuck_output_is_flagged(stepping):
    h, u, y, _, _ = stepping
    y2 = y.copy()
    y2[100_000:] = y2[100_000]
    est = OnlineEstimator(h, refit="recursive")
    est.update_block(u[:105_000], y2[:105_000])
    assert est.estimate.quality == "degraded" and "frozen" in est.estimate.reason


def test_refit_is_stored_verbatim_and_round_trips():
    est = OnlineEstimator(2e-4, window_s=5.0, refit="recursive", track_drift=False)
    params = est.get_params()
    assert params["refit"] == "recursive"
    clone = OnlineEstimator(**params)
    assert clone.get_params() == params
    assert OnlineEstimator(1e-3).get_params()["refit"] == "window"


@pytest.mark.parametrize("refit", ["rls", "", None, 1])
def test_bad_refit_is_a_one_line_error(refit):
    with pytest.raises(DataError) as info:
        OnlineEstimator(1e-3, refit=refit)
    assert "\n" not in str(info.value) and "refit" in str(info.value)


def test_stream_command_takes_refit(tmp_path, capsys):
    """``creep-online stream --refit recursive`` runs the recursive tracker (same default as the API: window);
    an unknown strategy is an argparse error (exit 2)."""
    from creep_online.cli import main
    from creep_online.io.csvfile import save_csv
    t = np.arange(24_000) * 5e-4
    u = np.where(t >= 0.05, 1.0, 0.0) + np.where(t >= 6.0, -2.0, 0.0)
    model = CreepModel.from_resonance(0.1, 60.0, 0.2, 3.0)
    y = simulate(model, t, u) + np.random.default_rng(0).normal(0, 1e-3, t.size)
    path = tmp_path / "run.csv"
    save_csv(path, t, u, y)
    assert main(["stream", "--source", f"csv:{path}", "--json", "--refit", "recursive"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["phase"] == "tracking" and out["alpha"] == pytest.approx(0.1, rel=TOL["alpha"])
    assert out["b"] == pytest.approx(3.0, rel=TOL["b"])
    assert main(["stream", "--source", f"csv:{path}", "--refit", "rls"]) == 2     # (its one line printed)
    assert "invalid choice: 'rls'" in capsys.readouterr().err


def test_predict_one_freeze_and_reset(stepping):
    """The estimator's API works the same with the recursive tracker: a one-step prediction at the noise
    floor, a frozen estimate that stays, reset() back to buffering."""
    h, u, y, ref, model = stepping
    est = OnlineEstimator(h, refit="recursive")
    n = 110_000
    est.update_block(u[:n], y[:n])
    clean = simulate(model, np.arange(n + 1) * h, u[:n + 1])[-1]
    assert est.predict_one(u[n]) == pytest.approx(clean, abs=3 * est.estimate.noise_rms)
    est.freeze()
    before = est.estimate
    est.update_block(u[n:], 1.1 * y[n:])             # a wrong output while frozen moves nothing
    after = est.estimate
    assert (after.alpha, after.a1, after.a2, after.b) == (before.alpha, before.a1, before.a2, before.b)
    est.reset()
    assert est.phase == "buffering" and est.estimate.samples == 0
