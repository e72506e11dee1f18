"""Global convergence of identify (issue 9): every input family, records taken in operation, the floor test.

The records come from ``hil_sim.validation`` with seeds the bench does
not use (the bench runs seeds 0-29), so nothing here was tuned on. "At the
floor": the fit% within 0.05 points of the true model's on the same noisy
record.
"""
import subprocess
import sys

import numpy as np
import pytest

from creep_online import CreepModel, kernels
from creep_online.discretize import foh_matrices_batch, step_response_grid
from creep_online.global_fit import at_floor
from creep_online.identification import identify
from creep_online.initial_state import free_columns, past_offsets
from creep_online.metrics import fit_percent
from hil_sim.experiments import Experiment
from creep_online.simulate import causal_convolve, simulate
from hil_sim import scenarios
from hil_sim.validation import FAMILIES, make_record


@pytest.mark.parametrize("family", FAMILIES)
def test_every_input_family_reaches_the_floor(family):
    rec = make_record(family, seed=101)
    res = identify(rec.t, rec.u, rec.y)
    assert fit_percent(rec.y, res.y_hat) > fit_percent(rec.y, rec.truth) - 0.05
    assert res.fit_percent == pytest.approx(fit_percent(rec.y, res.y_hat), abs=1e-9)
    # the parameters are right within the reported uncertainty (or the data cannot tell)
    err = abs(res.model.alpha / rec.model.alpha - 1)
    assert err < 0.02 or abs(res.model.alpha - rec.model.alpha) < 5 * res.uncertainty["alpha"], res.model


def test_a_record_taken_five_seconds_into_operation():
    """The issue's case: 5 s of steps first, the record starts with the plant moving and u != 0."""
    m = CreepModel.from_resonance(0.08, 40.0, 0.15, 0.7)
    rng = np.random.default_rng(9)
    fs, hist, n = 2e3, 10000, 12000
    levels = tuple((k * 0.7, float(rng.uniform(-2, 2))) for k in range(int((hist + n) / fs / 0.7) + 1))
    t_all, u_all = Experiment("op", m, fs, (hist + n) / fs, levels).input()
    y_all = simulate(m, t_all, u_all)
    t, u, truth = t_all[:n], u_all[hist:], y_all[hist:]
    y = truth + rng.normal(0, 0.002 * np.std(truth), n)
    assert u[0] != 0
    res = identify(t, u, y)
    assert fit_percent(y, res.y_hat) > fit_percent(y, truth) - 0.05
    for name, tol in (("alpha", 0.02), ("a1", 0.05), ("a2", 0.05), ("b", 0.03)):
        assert abs(getattr(res.model, name) / getattr(m, name) - 1) < tol, (name, res.model)
    assert any("in operation" in w for w in res.warnings)


#: The scenario tolerances (relative to the truth).
TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}


def _within_tolerances(model, truth: dict) -> dict:
    """The parameters outside TOL of the truth, with their relative errors (empty: all within)."""
    return {p: getattr(model, p) / truth[p] - 1 for p, tol in TOL.items() if abs(getattr(model, p) / truth[p] - 1) > tol}


@pytest.mark.parametrize("seed", [pytest.param(5, marks=pytest.mark.long), 15])
def test_records_in_operation_that_settled_on_a_wrong_resonance(seed, monkeypatch):
    """Two scenario records taken 5 s into operation (40 dB) on which the fit used to land on a wrong resonance:
    seed 15 holds its first level for 1.1 s, longer than the starting grid's window (the grid scored nothing and
    the global fit was lost); on seed 5 the layers' resonance (4.6 kHz, the plant's is 325 Hz) reached the noise
    floor inside the free response of the initial state and was kept without being checked."""
    monkeypatch.setattr(scenarios, "SNR_DB", 40.0)
    sc = scenarios.make("mid_operation", seed)
    res = identify(sc.t, sc.u, sc.y)
    assert not _within_tolerances(res.model, sc.final_truth), res.model
    assert any("in operation" in w for w in res.warnings)


@pytest.mark.slow
def test_records_in_operation_of_random_plants_are_identified(monkeypatch):
    """20 scenario records taken in operation (seeds the bench does not run; fn 100-1000 Hz, zeta 0.02-0.5,
    alpha 0.01-0.5, 40 dB): every parameter within the tolerances of the truth, or reported as not determined
    (its 1-sigma wider than the online estimator's "determined" limits) with the truth within 2 of its 1-sigma.
    Measured: 19 of 20 within the tolerances; the 20th (a well-damped mode, zeta 0.46) has a2 8.0 % off with a
    1-sigma of 8.5 %."""
    from creep_online.online.policy.limits import DeterminedLimits
    limits = dict(DeterminedLimits().items())
    monkeypatch.setattr(scenarios, "SNR_DB", 40.0)
    misses = {}
    for seed in range(100, 120):
        sc = scenarios.make("mid_operation", seed)
        res = identify(sc.t, sc.u, sc.y)
        for p, err in _within_tolerances(res.model, sc.final_truth).items():
            sd = res.uncertainty[p] / abs(getattr(res.model, p))
            if not (sd > limits[p] and abs(err) <= 2 * sd):
                misses[(seed, p)] = (err, sd)
    assert not misses, misses


def test_the_free_mode_grid_scores_a_window_without_an_input_change():
    """A window in which the input holds its first level: the forced column is zero, and each grid point's cost is
    the data's projection onto the two free modes alone (a direct least squares; it used to be 0/0)."""
    h, n = 1e-4, 400
    fn, zeta = np.array([150.0, 900.0]), np.array([0.05, 0.7])
    wn = 2 * np.pi * fn
    phi, g0, g1 = foh_matrices_batch(2 * zeta / wn, 1 / wn**2, h)
    y = np.random.default_rng(3).normal(size=n)
    q = np.ones((n, 1)) / np.sqrt(n)
    y_perp = y - q @ (q.T @ y)
    costs = kernels.foh_grid_costs_free(np.zeros(n), y_perp, q, phi, g0, g1, h)
    for k in range(fn.size):
        modes = np.zeros((n, 2))
        for c in range(2):
            x = np.eye(2)[c]
            for i in range(n):
                modes[i, c] = x[0]
                x = phi[k] @ x
        modes -= q @ (q.T @ modes)
        coef, *_ = np.linalg.lstsq(modes, y_perp, rcond=None)
        direct = float(y_perp @ y_perp - y_perp @ (modes @ coef))
        assert costs[k] == pytest.approx(direct, rel=1e-6)


def test_free_response_columns_span_a_step_between_grid_instants():
    """A step at an instant off the geometric grid, long before or just before the record,
    is reproduced by the free-response columns to far below any noise."""
    alpha, a1, a2, h, n = 0.2, 2e-3, 1e-5, 1e-3, 3000
    long = step_response_grid(alpha, a1, a2, h, n + int(past_offsets(n)[-1]) + 10 * n)
    cols = np.column_stack((np.ones(n), free_columns(long, a1, a2, h, n)))
    for m in (2, 17, 450, 5000, 12 * n):
        target = long[m:m + n]
        coef, *_ = np.linalg.lstsq(cols, target, rcond=1e-13)
        assert np.max(np.abs(cols @ coef - target)) < 1e-5 * np.ptp(long[:n]), m


def test_floor_test_accepts_white_noise_and_rejects_a_small_smooth_misfit():
    rng = np.random.default_rng(4)
    hits = sum(at_floor(rng.normal(0, 1, 10000)) for _ in range(50))
    assert hits >= 49
    ramp = 0.1 * np.sin(np.linspace(0, 3, 10000))  # 0.5 % of the noise power, all at low frequency
    assert not at_floor(rng.normal(0, 1, 10000) + ramp)


def test_causal_convolution_matches_direct():
    rng = np.random.default_rng(1)
    for n, k in ((7, 7), (1000, 1000), (999, 40)):
        x, c = rng.normal(size=n), rng.normal(size=k)
        assert np.allclose(causal_convolve(x, c), np.convolve(x, c)[:n], atol=1e-12)


def test_help_imports_no_command_and_lists_them_all():
    code = ("import sys, io, contextlib; from creep_online.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try: main(['--help'])\n"
            "    except SystemExit: pass\n"
            "print(sorted(m for m in ('scipy', 'numba', 'creep_online.identification') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_static_summaries_match_the_commands():
    from creep_online.cli import SUMMARIES, build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    helps = {c.dest: c.help for c in sub._choices_actions}
    assert helps == SUMMARIES


def test_asynchronous_input_changes_are_warned_and_synchronous_ones_not():
    from hil_sim.validation import make_async_record
    for seed in (50, 51):
        warn = identify(*_arrays(make_async_record(seed))).warnings
        assert any("asynchronous" in w for w in warn), warn
        ok = identify(*_arrays(make_async_record(seed, synchronous=True)))
        assert not any("asynchronous" in w for w in ok.warnings), ok.warnings


def _arrays(rec):
    return rec.t, rec.u, rec.y


def test_timing_check_recovers_a_known_sub_sample_shift():
    """Residual = exact response to steps 0.3 sample earlier minus the on-grid one: the per-change
    shift comes out near 0.3 (first order in the shift) and is flagged; pure noise is not."""
    from creep_online.timing import check_timing
    m, h, n = CreepModel.from_resonance(0.1, 30.0, 0.3), 1e-3, 4000
    fine = step_response_grid(m.alpha, m.a1, m.a2, h / 10, 10 * n + 10)
    step = fine[::10][:n + 1]
    idx = np.array([100, 900, 1700, 2600, 3300])
    size = np.array([1.0, -0.5, 2.0, -1.0, 0.7])
    late = np.zeros(n)
    for i0, a in zip(idx, size):
        late[i0:] += a * (fine[3:3 + 10 * (n - i0):10] - step[:n - i0])
    noise = 1e-5
    rng = np.random.default_rng(0)
    chk = check_timing(step, idx, size, late + rng.normal(0, noise, n), noise)
    assert chk.flagged and np.allclose(chk.shift, 0.3, atol=0.05)
    assert not check_timing(step, idx, size, rng.normal(0, noise, n), noise).flagged


def test_long_run_variance_factor_is_one_for_white_and_1_plus_rho_over_1_minus_rho_for_ar1():
    from creep_online.metrics import long_run_variance_factor
    rng = np.random.default_rng(3)
    n = 50000
    assert long_run_variance_factor(rng.normal(size=n)) < 1.3
    e, ar, acc = rng.normal(size=n), np.empty(n), 0.0
    for i in range(n):
        acc = 0.9 * acc + e[i]
        ar[i] = acc
    assert long_run_variance_factor(ar) == pytest.approx(19.0, rel=0.3)
