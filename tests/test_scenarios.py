"""The scenario test bed (hil_sim.scenarios): its simulator against independent references, its families' contracts."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from creep_online.model import CreepModel
from creep_online.online.soe import SoeBasis
from creep_online.simulate import simulate
from hil_sim import scenarios as S

H = 1e-4
T = np.arange(15_000) * H


@pytest.mark.parametrize("alpha", [0.01, 0.1, 0.4, 0.7])
@pytest.mark.parametrize("fn, zeta", [(2500.0, 0.01), (300.0, 0.1), (5.0, 1.0)])
@pytest.mark.parametrize("make_input", [S.steps, S.prbs])
def test_constant_parameters_match_exact_simulator(alpha, fn, zeta, make_input):
    """Constant parameters: within 1e-5 of the output range of the exact (closed-form) simulator."""
    u = make_input(T, np.random.default_rng(3))
    model = CreepModel.from_resonance(alpha, fn, zeta, -2.5)
    ref = simulate(model, T, u)
    y = S.simulate_tv(H, u, alpha, model.a1, model.a2, model.b)
    assert np.max(np.abs(y - ref)) < 1e-5 * np.ptp(ref)


def test_extra_modes_add_their_own_creep_response():
    """A parallel mode (r, a1k, a2k) adds exactly r times the creep model with that resonance."""
    u = S.steps(T, np.random.default_rng(4))
    main = CreepModel.from_resonance(0.2, 400.0, 0.05, 1.5)
    extra = CreepModel.from_resonance(0.2, 900.0, 0.1, 1.5)
    y = S.simulate_tv(H, u, 0.2, main.a1, main.a2, 1.5, modes=[(0.3, extra.a1, extra.a2)])
    ref = simulate(main, T, u) + 0.3 * simulate(extra, T, u)
    assert np.max(np.abs(y - ref)) < 1e-5 * np.ptp(ref)


def test_parameter_change_continues_the_state():
    """One step of u, then a1, a2 and b switch at t_c: matches an ODE solver with the state carried over.

    The forcing of a2 y'' + a1 y' + y = b z is the closed-form creep of a step,
    z = (t - t_s)^alpha / Gamma(1 + alpha).
    """
    alpha, t_s, n_c = 0.3, 0.01, 1000
    before = CreepModel.from_resonance(alpha, 200.0, 0.05, 2.0)
    after = CreepModel.from_resonance(alpha, 140.0, 0.2, 1.2)
    t = T[:3000]
    u = np.where(t >= t_s - H / 2, 1.0, 0.0)
    on = np.arange(t.size) >= n_c
    pick = {k: np.where(on, getattr(after, k), getattr(before, k)) for k in ("a1", "a2", "b")}
    y = S.simulate_tv(H, u, alpha, **pick)

    def rhs(m: CreepModel):
        def f(tt, x):
            z = max(tt - t_s, 0.0) ** alpha / math.gamma(1 + alpha)
            return [x[1], (m.b * z - x[0] - m.a1 * x[1]) / m.a2]
        return f

    i_s = int(round(t_s / H))
    first = solve_ivp(rhs(before), (t[i_s], t[n_c]), [0.0, 0.0], t_eval=t[i_s:n_c + 1],
                      method="DOP853", rtol=1e-11, atol=1e-13)
    second = solve_ivp(rhs(after), (t[n_c], t[-1]), first.y[:, -1], t_eval=t[n_c:],
                       method="DOP853", rtol=1e-11, atol=1e-13)
    ref = np.concatenate((np.zeros(i_s), first.y[0, :-1], second.y[0]))
    assert np.max(np.abs(y - ref)) < 1e-5 * np.ptp(ref)


@pytest.mark.parametrize("alpha", [0.005, 0.3, 0.9])
def test_compiled_weights_equal_soe_basis(alpha):
    basis = SoeBasis.build(H, horizon_s=100.0, dx=S.SOE_DX, top=S.SOE_TOP)
    w = np.empty(basis.size)
    d = S._soe_weights(alpha, basis.lam, basis.dx, w)
    w_ref, d_ref = basis.weights(alpha)
    np.testing.assert_allclose(w, w_ref, rtol=1e-13)
    assert d == pytest.approx(d_ref, rel=1e-13)


@pytest.mark.parametrize("family", sorted(S.FAMILIES))
def test_family_contract(family, tmp_path):
    """Deterministic per seed, finite, consistent lengths; change time inside the record; npz round trip."""
    scen = S.make(family, 0)
    again = S.make(family, 0)
    assert np.array_equal(scen.y, again.y)
    n = scen.t.size
    assert all(getattr(scen, k).shape == (n,) for k in ("u", "y", "alpha", "a1", "a2", "b"))
    assert np.all(np.isfinite(scen.y)) and np.ptp(scen.y) > 0
    assert scen.t[0] == 0.0 and scen.t[1] == pytest.approx(scen.h)
    if scen.change_time is not None:
        k = int(round(scen.change_time / scen.h))
        assert 0 < k < n and any(getattr(scen, p)[k] != getattr(scen, p)[k - 1] for p in ("a1", "a2", "b"))
    if family == "mid_operation":
        assert scen.u[0] != 0.0 and scen.u_history.size > 0
    if family == "close_modes":
        assert set(scen.truth_best) == {"alpha", "a1", "a2", "b"}
        assert scen.final_truth == scen.truth_best
    if family == "drift":
        assert scen.alpha[-1] > 1.09 * scen.alpha[0] and scen.b[-1] / scen.b[0] > 1.04
    scen.save(tmp_path / "s.npz")
    back = S.Scenario.load(tmp_path / "s.npz")
    assert np.array_equal(back.y, scen.y) and back.params == scen.params and back.final_truth == scen.final_truth
    assert (back.u_history is None) == (scen.u_history is None)
    if scen.u_history is not None:
        assert np.array_equal(back.u_history, scen.u_history)


@pytest.mark.parametrize("family", sorted(S.FAMILIES))
def test_the_clean_output_is_the_record_without_its_noise(family):
    """``Scenario.clean()`` (the bench's reference for its bounds and its oracle) is the record less its noise:
    the difference has the noise's std (within the chi-square spread of >= 100,000 samples), for a record
    taken mid-operation too (its history simulated first; started from rest its output is far off, which is what
    the bounds of mid_operation had taken before). Scaling a parameter by 1 changes nothing."""
    scen = S.make(family, 0)
    std = scen.params["noise_std"]
    assert np.std(scen.y - scen.clean()) == pytest.approx(std, rel=0.02)
    assert np.array_equal(scen.clean(alpha=1.0), scen.clean())
    if family == "mid_operation":
        from_rest = S.simulate_tv(scen.h, scen.u, scen.alpha, scen.a1, scen.a2, scen.b)
        assert np.std(scen.y - from_rest) > 3 * std


def test_strong_creep_spans_the_ranges():
    """Over 300 draws: alpha covers 0.005-0.7 at both ends, both gain signs, fn ~1 Hz to fs/4, every input."""
    draws = [S._strong_creep_plant(np.random.default_rng([seed, 1])) for seed in range(300)]
    alpha = np.array([d["alpha"] for d in draws])
    assert alpha.min() < 0.008 and alpha.max() > 0.55 and np.all((alpha >= 0.005) & (alpha <= 0.7))
    assert {np.sign(d["b"]) for d in draws} == {-1.0, 1.0}
    fn_ratio = np.array([d["fn"] * 4 / d["fs"] for d in draws])
    assert min(d["fn"] for d in draws) < 2.0 and fn_ratio.max() > 0.9 and fn_ratio.max() <= 1.0
    assert {d["input"] for d in draws} == set(S.INPUTS)
    assert {d["fs"] for d in draws} == {1000.0, 2000.0, 10_000.0}


@pytest.mark.parametrize("family, rest", [pytest.param(f, 0, marks=pytest.mark.long) if f == "close_modes" else (f, 0)
                                          for f in S.FROM_REST] + [("controller", 1), ("payload", 10)])
def test_a_family_record_can_start_with_the_step(family, rest):
    """``make(family, seed, rest=k)``: the same plant and input levels, the input's first change after k samples of
    rest (0: the input at its first level from the first sample); the output at rest (zero) until it."""
    base, scen = S.make(family, 3), S.make(family, 3, rest)
    assert scen.params["rest_samples"] == rest
    assert all(np.array_equal(getattr(base, k), getattr(scen, k)) for k in ("alpha", "a1", "a2", "b"))
    moves = np.flatnonzero(np.diff(scen.u, prepend=0.0) != 0.0)
    assert moves[0] == rest or family == "strong_creep" and scen.params["input"] == "triangle"
    assert np.all(scen.u[:rest] == 0.0)
    assert np.all(scen.clean()[:rest + 1] == 0.0)
    levels = lambda u: set(np.unique(u).tolist()) - {0.0}      # noqa: E731 - the held levels
    if scen.params.get("input") in ("steps", "staircase", "random_staircase", "prbs"):
        assert levels(base.u) <= levels(scen.u)     # (starting earlier, it reaches at least as many)


def test_mid_operation_has_no_rest_to_set():
    with pytest.raises(ValueError, match="in operation"):
        S.make("mid_operation", 0, 0)
