"""Streaming kernels of the online estimator against independent references.

References: the closed form t^alpha / Gamma(1+alpha), the exact simulator
(``simulate(method="exact")``, closed-form step response superposed), the
lead's direct truncated sum (``simulate.fractional_integral``), central
differences and brute-force residual sums.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.model import CreepModel
from creep_online.online import kernels as K
from creep_online.online.layer2 import Layer2Job
from creep_online.online.plant import simulate_varying
from creep_online.online.soe import SoeBasis, pack_coefficients, resonance_zoh
from creep_online.simulate import fractional_integral, simulate


def _track(model: CreepModel, h: float, u: np.ndarray, y: np.ndarray | None = None):
    basis = SoeBasis.build(h, top=3000.0)
    p = basis.size + 2
    v, dv = np.empty(p), np.empty(p)
    K.model_coefficients(model.alpha, basis.lam, basis.dx, model.a1, model.a2, v, dv)
    st, S, sy, sc, avg = np.zeros(p), np.zeros((p, p)), np.zeros(p), np.zeros(K.SC_SIZE), np.zeros(p)
    sc[K.SC_G] = sc[K.SC_FORGET] = 1.0
    pred = np.empty(u.size)
    yy = np.zeros(u.size) if y is None else y
    K.track_block(u, yy, st, pack_coefficients(basis, model.a1, model.a2), v * model.b, S, sy, sc, avg, True, pred)
    return basis, pred, S, sy, sc


@pytest.mark.parametrize("alpha, tol", [(0.0133, 2e-6), (0.06, 5e-6), (0.3, 2e-5), (0.7, 5e-5), (0.95, 2e-4)])
def test_soe_step_response_matches_closed_form(alpha, tol):
    basis = SoeBasis.build(1e-4, horizon_s=3600.0)
    t = np.geomspace(1e-4, 3600.0, 800)
    exact = t**alpha / math.gamma(1 + alpha)
    assert np.max(np.abs(basis.step_response(alpha, t) / exact - 1)) < tol


def test_model_coefficient_derivative_matches_central_difference():
    basis = SoeBasis.build(1e-3)
    p = basis.size + 2
    v, dv, vp, vm, tmp = (np.empty(p) for _ in range(5))
    for alpha in (0.02, 0.4, 0.9):
        K.model_coefficients(alpha, basis.lam, basis.dx, 2e-3, 1e-5, v, dv)
        K.model_coefficients(alpha + 1e-6, basis.lam, basis.dx, 2e-3, 1e-5, vp, tmp)
        K.model_coefficients(alpha - 1e-6, basis.lam, basis.dx, 2e-3, 1e-5, vm, tmp)
        assert np.max(np.abs((vp - vm) / 2e-6 - dv)) < 1e-7 * np.max(np.abs(dv))


def test_resonance_zoh_matches_scipy_lsim_of_a_step():
    from scipy.signal import lti
    a1, a2, h = 2e-3, 3e-6, 1e-4
    phi, gam = resonance_zoh(a1, a2, h)
    x = np.zeros(2)
    ys = []
    for _ in range(50):
        ys.append(x[0])
        x = phi @ x + gam
    t = np.arange(50) * h
    _, ref = lti([1.0], [a2, a1, 1.0]).step(T=t)
    assert np.max(np.abs(np.array(ys) - ref)) < 1e-9


@pytest.mark.parametrize("alpha, fn, zeta, h, n", [(0.02, 300.0, 0.05, 1e-4, 6000), (0.06, 6.0, 0.1, 5e-3, 3000),
                                                  (0.7, 10.0, 0.05, 1e-3, 3000)])
def test_tracking_prediction_equals_exact_simulator(alpha, fn, zeta, h, n):
    model = CreepModel.from_resonance(alpha, fn, zeta, 1.7)
    t = np.arange(n) * h
    rng = np.random.default_rng(0)
    u = np.repeat(rng.normal(size=n // 500 + 1), 500)[:n]      # a staircase
    y = simulate(model, t, u)
    _, pred, *_ = _track(model, h, u)
    assert np.max(np.abs(pred - y)) < 2e-5 * np.ptp(y)


def test_truncated_gl_ring_buffer_equals_direct_sum():
    from creep_online.kernels import zoh_integral_weights
    rng = np.random.default_rng(1)
    u = rng.normal(size=700)
    h, alpha, length = 1e-3, 0.3, 64
    c = zoh_integral_weights(alpha, h, math.gamma(1 + alpha), length + 1)
    out = np.empty(u.size)
    K.truncated_gl_block(u, np.zeros(length), np.zeros(1, dtype=np.int64), c, out)
    ref = fractional_integral(u, h, alpha, memory=length)
    assert np.max(np.abs(out - ref)) < 1e-12


def test_window_cost_equals_brute_force_residual():
    model = CreepModel.from_resonance(0.05, 20.0, 0.2, 2.0)
    h, n = 2e-3, 4000
    t = np.arange(n) * h
    u = np.where(t > 0.05, 1.0, 0.0)
    y = simulate(model, t, u) + np.random.default_rng(2).normal(0, 1e-3, n)
    basis, _, S, sy, sc = _track(model, h, u, y)
    for alpha in (0.03, 0.05, 0.08):
        j, b = K.window_cost(alpha, S, sy, sc[K.SC_SYY], basis.lam, basis.dx, model.a1, model.a2)
        shape = simulate(CreepModel(alpha, model.a1, model.a2, 1.0), t, u)
        b_ref = shape @ y / (shape @ shape)
        r = y - b_ref * shape
        assert b == pytest.approx(b_ref, rel=1e-4)
        assert j == pytest.approx(r @ r, rel=1e-3)


def test_gauss_newton_recovers_alpha_and_b_exactly_without_noise():
    model = CreepModel.from_resonance(0.04, 50.0, 0.1, 0.3)
    h, n = 1e-3, 5000
    t = np.arange(n) * h
    u = np.where(t > 0.01, 1.0, 0.0) - np.where(t > 3.0, 0.5, 0.0)
    y = simulate(model, t, u)
    basis, _, S, sy, sc = _track(model, h, u, y)
    out = np.zeros(8)
    K.gauss_newton_alpha(0.06, 0.25, S, sy, sc[K.SC_SYY], basis.lam, basis.dx, model.a1, model.a2, 1e-3, 0.99, 20, out)
    assert out[0] == pytest.approx(0.04, rel=1e-4)
    assert out[1] == pytest.approx(0.3, rel=1e-4)
    assert out[7] == 1.0


def test_rpem_carry_on_converges_on_a_constant_plant():
    model = CreepModel.from_resonance(0.05, 20.0, 0.2, 1.0)
    h, n = 2e-3, 20000
    t = np.arange(n) * h
    u = np.where(((t // 2) % 2) == 0, 1.0, -1.0)
    y = simulate(model, t, u)
    basis = SoeBasis.build(h, top=3000.0)
    st = np.zeros(basis.size + 2)
    theta = np.array([0.08, 0.8])
    P = np.diag([1e-3, 1e-1])
    K.rpem_block(u, y, st, pack_coefficients(basis, model.a1, model.a2), basis.lam, basis.dx, model.a1, model.a2,
                 theta, P, 1.0, 1e-3, 0.99, 1, np.zeros(1, dtype=np.int64), 1e3)
    assert theta[0] == pytest.approx(0.05, rel=0.02)
    assert theta[1] == pytest.approx(1.0, rel=0.02)


def test_layer2_job_recovers_the_resonance():
    model = CreepModel.from_resonance(0.03, 120.0, 0.08, 0.5)
    h, n = 1e-4, 1500
    t = np.arange(n) * h
    u = np.full(n, 2.0)
    y = simulate(model, t, u)
    res = Layer2Job(SoeBasis.build(h, top=3000.0), u, y, 0.03).run()
    assert res.a1 == pytest.approx(model.a1, rel=1e-3)
    assert res.a2 == pytest.approx(model.a2, rel=1e-4)
    assert res.b == pytest.approx(0.5, rel=1e-4)


def test_layer2_job_ignores_lost_samples():
    model = CreepModel.from_resonance(0.03, 120.0, 0.08, 0.5)
    h, n = 1e-4, 1500
    u = np.full(n, 2.0)
    y = simulate(model, np.arange(n) * h, u)
    y[100:140] = np.nan
    y[700] = np.nan
    res = Layer2Job(SoeBasis.build(h, top=3000.0), u, y, 0.03).run()
    assert res.a2 == pytest.approx(model.a2, rel=1e-4)


def test_varying_plant_equals_simulate_when_constant():
    model = CreepModel.from_resonance(0.05, 20.0, 0.2, 1.3)
    h, n = 2e-3, 6000
    t = np.arange(n) * h
    u = np.where(((t // 1.5) % 2) == 0, 1.0, -0.5)
    ref = simulate(model, t, u)
    out = simulate_varying(t, u, model.alpha, model.a1, model.a2, model.b)
    assert np.max(np.abs(out - ref)) < 1e-5 * np.ptp(ref)
