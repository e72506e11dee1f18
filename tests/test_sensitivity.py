"""Forward sensitivities of the exact step response against an independent reference.

The reference is central finite differences of ``step_response_grid`` (itself
tested against inverse-Laplace step responses in test_simulators.py). A
central difference has truncation error ~delta^2 and rounding error
~eps/delta, so each derivative is compared with the best of three steps; the
analytic derivative must agree to 1e-6 of its peak (it agrees to ~1e-9).
"""
import math

import numpy as np
import pytest

from creep_online import kernels
from creep_online.identification import creep_asymptote
from creep_online.discretize import (head_sensitivity, head_terms, step_response_grid, step_response_sensitivity,
                                     taylor_moments, taylor_moments_sensitivity)

#: (alpha, fn_hz, zeta, h, samples): light and heavy damping, critical damping, stiff poles
#: (several quadrature panels), alpha near both ends, and records shorter than the head.
CASES = [
    (0.06, 6.0, 0.12, 0.005, 3000),
    (0.02, 350.0, 0.08, 1e-4, 4000),
    (0.3, 100.0, 0.01, 1e-3, 3000),
    (0.5, 10.0, 1.5, 1e-3, 3000),
    (0.3, 50.0, 1.0, 1e-3, 1000),
    (0.8, 300.0, 0.7, 1e-3, 2000),
    (0.001, 400.0, 3.0, 1e-3, 500),
    (0.95, 2000.0, 0.3, 1e-3, 200),
    (0.2, 20.0, 0.1, 1e-3, 10),
]


def _resonance(fn: float, zeta: float) -> tuple[float, float]:
    wn = 2 * math.pi * fn
    return 2 * zeta / wn, 1 / wn**2


def _central(f, p: np.ndarray, k: int, rel: float) -> np.ndarray:
    d = rel * abs(p[k])
    up, down = p.copy(), p.copy()
    up[k] += d
    down[k] -= d
    return (f(up) - f(down)) / (2 * d)


def _best_error(analytic: np.ndarray, f, p: np.ndarray, k: int) -> float:
    errors = []
    for rel in (1e-4, 1e-5, 1e-6):
        fd = _central(f, p, k, rel)
        errors.append(np.max(np.abs(analytic - fd)) / max(np.max(np.abs(fd)), 1e-300))
    return min(errors)


@pytest.mark.parametrize("alpha, fn, zeta, h, n", CASES)
def test_step_response_derivatives_match_finite_differences(alpha, fn, zeta, h, n):
    a1, a2 = _resonance(fn, zeta)
    out = step_response_sensitivity(alpha, a1, a2, h, n)
    assert out.shape == (4, n)
    p = np.array([alpha, a1, a2])
    for k in range(3):
        err = _best_error(out[1 + k], lambda q: step_response_grid(q[0], q[1], q[2], h, n), p, k)
        assert err < 1e-6, (("alpha", "a1", "a2")[k], err)


@pytest.mark.parametrize("alpha, fn, zeta, h, n", CASES)
def test_sensitivity_row_zero_is_the_step_response_bit_for_bit(alpha, fn, zeta, h, n):
    a1, a2 = _resonance(fn, zeta)
    assert np.array_equal(step_response_sensitivity(alpha, a1, a2, h, n)[0], step_response_grid(alpha, a1, a2, h, n))


@pytest.mark.parametrize("alpha, fn, zeta, h, n", CASES[:4])
def test_parts_match_finite_differences(alpha, fn, zeta, h, n):
    """The pieces on their own: Van Loan derivatives of (Phi, M) and the head terms' derivatives."""
    a1, a2 = _resonance(fn, zeta)
    phi, moments, dphi, dmoments = taylor_moments_sensitivity(a1, a2, h)
    ref_phi, ref_moments = taylor_moments(a1, a2, h)
    assert np.array_equal(phi, ref_phi) and np.array_equal(moments, ref_moments)
    p = np.array([a1, a2])
    for k in range(2):
        fd_phi = _central(lambda q: taylor_moments(q[0], q[1], h)[0], p, k, 1e-5)
        fd_m = _central(lambda q: taylor_moments(q[0], q[1], h)[1], p, k, 1e-5)
        np.testing.assert_allclose(dphi[k], fd_phi, rtol=0, atol=1e-7 * np.max(np.abs(fd_phi)))
        np.testing.assert_allclose(dmoments[k], fd_m, rtol=0, atol=1e-7 * np.max(np.abs(fd_m)))
    head, dhead = head_sensitivity(alpha, a1, a2, h, 32)
    assert np.array_equal(head, head_terms(alpha, a1, a2, h, 32))
    q = np.array([alpha, a1, a2])
    for k in range(3):
        err = _best_error(dhead[k], lambda v: head_terms(v[0], v[1], v[2], h, 32), q, k)
        assert err < 1e-7, (k, err)


def test_a_fit_step_into_a_degenerate_stiff_resonance_gives_finite_sensitivities():
    """a2 ~ 1.7e-15 at h = 1 ms (a Levenberg-Marquardt trial step of a real fit): the fast pole ~1e13 1/s is
    beyond the head's 64 quadrature panels, so neither S nor its finite differences in a1, a2 are accurate
    there. The sensitivities must still be finite (the trial is then judged on its cost); the alpha derivative
    matches finite differences, and late (t >> a1) the a1 derivative that of the creep asymptote."""
    wn = 2 * math.pi * 3.9e6
    alpha, a1, a2, h, n = 0.35, 2 * 1.6e5 / wn, 1 / wn**2, 1e-3, 600
    out = step_response_sensitivity(alpha, a1, a2, h, n)
    assert np.all(np.isfinite(out))
    p = np.array([alpha, a1, a2])
    assert _best_error(out[1], lambda q: step_response_grid(q[0], q[1], q[2], h, n), p, 0) < 1e-6
    tau = np.arange(300, n) * h
    late = _central(lambda q: creep_asymptote(tau, q[0], q[1], q[2]), p, 1, 1e-5)
    assert np.max(np.abs(out[2, 300:] - late)) < 1e-2 * np.max(np.abs(late))


@pytest.mark.parametrize("changes", [6, 400])   # sparse superposition and the FFT path
def test_model_output_and_projected_residual_jacobians_match_finite_differences(changes):
    """The identification's Jacobians: d model_output / d(alpha, ln a1, ln a2), and that of the residual with
    the gain (and the offset) projected out, against central differences of the same functions."""
    from creep_online.identification import (_projected, _projected_affine, _projected_jacobian, model_output,
                                             model_output_sensitivity)
    rng = np.random.default_rng(changes)
    h, n = 1e-3, 3000
    u = np.repeat(rng.uniform(-1, 1, changes), n // changes + 1)[:n]
    p = np.array([0.15, math.log(2 * 0.2 / (2 * math.pi * 40)), math.log(1 / (2 * math.pi * 40) ** 2)])
    y = 0.8 * model_output(0.17, math.exp(p[1]) * 1.1, math.exp(p[2]) * 0.9, h, u) + 0.3
    y += 1e-3 * rng.standard_normal(n)

    def shape(q):
        return model_output(q[0], math.exp(q[1]), math.exp(q[2]), h, u)

    s, ds, step = model_output_sensitivity(p[0], math.exp(p[1]), math.exp(p[2]), h, u)
    assert np.array_equal(step, step_response_grid(p[0], math.exp(p[1]), math.exp(p[2]), h, n + 1))
    assert np.array_equal(s, shape(p))
    for k in range(3):
        assert _best_error(ds[k], shape, p, k) < 1e-6, k
    for free_offset in (False, True):
        def residual(q):
            sq = shape(q)
            return _projected_affine(y, sq)[2] if free_offset else _projected(y, sq)[1]
        if free_offset:
            b, _, r = _projected_affine(y, s)
        else:
            b, r = _projected(y, s)
        jac = _projected_jacobian(s, ds, r, b, free_offset)
        for k in range(3):
            assert _best_error(jac[k], residual, p, k) < 1e-6, (free_offset, k)
        # the fused kernel the polish uses: the same normal equations without forming J
        a, g = kernels.projected_normal_equations(s, ds, r, b, free_offset)
        np.testing.assert_allclose(a, jac @ jac.T, rtol=1e-10, atol=0)
        np.testing.assert_allclose(g, jac @ r, rtol=0, atol=1e-9 * np.max(np.abs(jac @ r)) + 1e-12 * np.sqrt(np.diag(a) * (r @ r)).max())


@pytest.mark.parametrize("alpha, a1, a2", [(0.21, 0.0, 0.0), (0.05, 0.02, 4e-4), (0.6, 1e-3, 2e-6), (1e-3, 0.05, 1e-3)])
def test_layer1_creep_asymptote_derivative_matches_finite_differences(alpha, a1, a2):
    from creep_online.identification import creep_asymptote_dalpha
    tau = np.geomspace(0.5, 50.0, 400)
    value, d_value = creep_asymptote_dalpha(tau, alpha, a1, a2)
    np.testing.assert_array_equal(value, creep_asymptote(tau, alpha, a1, a2))
    p = np.array([alpha, a1, a2])
    assert _best_error(d_value, lambda q: creep_asymptote(tau, q[0], q[1], q[2]), p, 0) < 1e-8
