"""The extended fits' Jacobian (``Design.jacobian``) against central finite differences of the residual.

Base parameters (alpha, log10 fn, log10 zeta) are differentiated exactly
(forward sensitivities of the march, variable projection): central
differences with step 1e-5, Richardson-extrapolated, agree to ~1e-8 relative or better (plain
central differences' truncation error, step^2, reached 1e-6 for a mode near fs), so 1e-6 still
catches any wrong chain-rule factor or a missing term of the projection (the
Kaufman term alone is off by 4e-3..0.6 here); so is a delay's (a spline's
slope), and so are a parallel path's own parameters (the effect's
``unit_step_derivatives``: a second mode's in fn and zeta, a second creep's
exponent), also in a coupled design (input effects beside parallel paths: the
inner problem is bilinear in the paths' gain ratios and its curvature enters,
``varpro.projected_jacobian``). The effects' other parameters keep forward
differences (step 1e-7, as scipy's ``diff_step``): 1e-3.
"""
from __future__ import annotations

import numpy as np
import pytest

from creep_online.diagnostics import extended as ext
from creep_online.diagnostics.varpro import projected_jacobian
from hil_sim.hidden_effects import hidden_dataset

BASE_RTOL = 1e-6
EFFECT_RTOL = 1e-3
STEP = 1e-5

DESIGNS = [
    (None, ()),
    ("delay", ("delay",)),
    ("hysteresis", ("hysteresis",)),                  # input rows
    ("leakage", ("leakage",)),                        # output filter
    ("second_mode", ("second_mode",)),                # parallel path
    ("second_creep", ("second_creep",)),              # parallel path (exponent)
    ("second_mode", ("second_mode", "second_creep")),  # two parallel paths
    ("leakage", ("second_mode", "leakage")),          # a parallel path, output-filtered
    ("periodic_disturbance", ("periodic_disturbance",)),
    ("drift", ("drift", "nonlinear_gain")),
    ("delay", ("hysteresis", "leakage", "delay")),    # rows, filter and delay at once
    ("second_mode", ("second_mode", "delay")),        # a delayed parallel path: the delay by differences
    ("hysteresis", ("hysteresis", "second_creep")),   # coupled: the path sees the input rows (gain ratio inside)
    ("second_mode", ("second_mode", "nonlinear_gain", "leakage")),   # coupled and output-filtered
    ("second_mode", ("second_mode", "second_creep", "hysteresis")),  # two coupled paths
]


def _central(design: ext.Design, theta: np.ndarray, k: int) -> np.ndarray:
    """Central differences at steps h and h/2, Richardson-extrapolated (truncation error O(h^4)).

    With the second mode allowed up to fs, the drawn frequency can sit far above the base mode, where
    plain central differences' O(h^2) error alone reached 1.1e-6 of the derivative."""
    h = STEP * min(1.0, design.hi[k] - design.lo[k]) * max(1.0, abs(theta[k]))   # a delay's range is 40 samples

    def diff(step: float) -> np.ndarray:
        up, down = theta.copy(), theta.copy()
        up[k] += step
        down[k] -= step
        return (design.residual(up) - design.residual(down)) / (2 * step)

    return (4.0 * diff(h / 2) - diff(h)) / 3.0


def _theta(design: ext.Design, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tail = design.lo[3:] + (design.hi[3:] - design.lo[3:]) * rng.uniform(0.3, 0.7, len(design.names) - 3)
    return np.concatenate([[0.3, np.log10(60.0), np.log10(0.2)], tail])


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("kind, effects", DESIGNS, ids=["+".join(e) or "base" for _, e in DESIGNS])
def test_design_jacobian_matches_central_differences(kind, effects):
    ds = hidden_dataset(kind, 1, n=4000)
    design = ext.Design(ext.prepare(ds.t, ds.u, ds.y), effects)
    assert design.analytic
    theta = _theta(design, 0)
    jac = design.jacobian(theta)
    assert jac.shape == (ds.t.size, theta.size)
    for k, name in enumerate(design.names):
        err = _relative(jac[:, k], _central(design, theta, k))
        assert err < (BASE_RTOL if k in design.exact else EFFECT_RTOL), (name, err)
    assert design.exact[:3] == [0, 1, 2]


def test_delay_is_differentiated_exactly_unless_a_parallel_path_is_delayed_too():
    ds = hidden_dataset("delay", 3, n=3000)
    data = ext.prepare(ds.t, ds.u, ds.y)
    assert ext.Design(data, ("delay",)).exact == [0, 1, 2, 3]
    assert ext.Design(data, ("second_mode", "delay")).exact == [0, 1, 2, 3, 4]     # the mode's, not the delay
    design = ext.Design(data, ("delay",))
    theta = np.array([0.3, np.log10(60.0), np.log10(0.2), 0.0])     # the delay switched off: its lower bound
    jac = design.jacobian(theta)
    up = theta.copy()
    up[3] += 1e-6
    forward = (design.residual(up) - design.residual(theta)) / 1e-6
    assert _relative(jac[:, 3], forward) < EFFECT_RTOL


def test_weighted_design_jacobian_matches_central_differences():
    ds = hidden_dataset("leakage", 2, n=3000)
    w = np.linspace(0.5, 2.0, ds.t.size)
    design = ext.Design(ext.prepare(ds.t, ds.u, ds.y, weights=w), ("leakage",))
    theta = _theta(design, 1)
    jac = design.jacobian(theta)
    for k in range(3):
        assert _relative(jac[:, k], _central(design, theta, k)) < BASE_RTOL


def test_jacobian_leaves_the_projection_of_theta_in_place():
    """scipy asks for fun(x) then jac(x): the Jacobian's own differences must not change what x projects to."""
    ds = hidden_dataset("delay", 1, n=3000)
    design = ext.Design(ext.prepare(ds.t, ds.u, ds.y), ("delay",))
    theta = _theta(design, 2)
    r = design.residual(theta)
    design.jacobian(theta)
    assert np.array_equal(design.residual(theta), r)


@pytest.mark.parametrize("rank_deficient", [False, True])
def test_projected_jacobian_of_a_small_separable_problem(rank_deficient):
    """y ~ A(p) c with A's columns exp(-p_k t) (and a duplicate column): exact linear algebra, tight tolerance."""
    t = np.linspace(0.0, 3.0, 200)
    y = 2.0 * np.exp(-0.7 * t) - np.exp(-2.5 * t) + 0.1 * np.sin(5 * t)

    def design(p):
        cols = [np.exp(-p[0] * t), np.exp(-p[1] * t), np.ones_like(t)]
        if rank_deficient:
            cols.append(2.0 * cols[0])
        return np.array(cols).T

    def residual(p):
        a = design(p)
        return y - a @ np.linalg.lstsq(a, y, rcond=1e-10)[0]

    p = np.array([0.9, 2.0])
    a = design(p)
    coef = np.linalg.lstsq(a, y, rcond=1e-10)[0]
    r = y - a @ coef
    d0 = -t * np.exp(-p[0] * t)
    ders = [(np.array([0, 3]), np.array([d0, 2.0 * d0]).T) if rank_deficient else (np.array([0]), d0[:, None]),
            (np.array([1]), (-t * np.exp(-p[1] * t))[:, None])]
    jac = projected_jacobian(a, np.array([d @ coef[c] for c, d in ders]),
                             np.array([np.zeros(a.shape[1]) + np.bincount(c, d.T @ r, a.shape[1]) for c, d in ders]))
    for k in range(2):
        up, down = p.copy(), p.copy()
        up[k] += 1e-6
        down[k] -= 1e-6
        assert _relative(jac[:, k], (residual(up) - residual(down)) / 2e-6) < 1e-7


@pytest.mark.parametrize("fn, zeta", [(60.0, 0.05), (30.0, 1.0), (30.0, 1.0 + 1e-7), (10.0, 3.0), (400.0, 0.7)])
def test_resonance_step_derivatives_match_central_differences(fn, zeta):
    """Light to heavy damping, repeated poles included (the self-convolution's series branch)."""
    from creep_online.effects.responses import resonance_step, resonance_step_derivatives
    tau = np.arange(-5, 3000) * 1e-3
    der = resonance_step_derivatives(fn, zeta, tau)
    lf, lz = np.log10(fn), np.log10(zeta)
    up_f, down_f = resonance_step(10 ** (lf + STEP), zeta, tau), resonance_step(10 ** (lf - STEP), zeta, tau)
    up_z, down_z = resonance_step(fn, 10 ** (lz + STEP), tau), resonance_step(fn, 10 ** (lz - STEP), tau)
    central = [(up_f - down_f) / (2 * STEP), (up_z - down_z) / (2 * STEP)]
    for k in range(2):
        assert _relative(der[k], central[k]) < BASE_RTOL
    assert not der[:, :6].any()                                     # nothing before the step


@pytest.mark.parametrize("alpha", [0.01, 0.4, 1.0])
def test_creep_step_derivative_matches_central_differences(alpha):
    from creep_online.effects.responses import creep_step, creep_step_derivative
    tau = np.arange(-5, 3000) * 1e-3
    h = 1e-6
    central = (creep_step(alpha + h, tau) - creep_step(alpha - h, tau)) / (2 * h)
    assert _relative(creep_step_derivative(alpha, tau), central) < BASE_RTOL


@pytest.mark.parametrize("rows, k", [(1, 3), (4, 2)])
def test_superposer_products_equal_the_columns_products(rows, k):
    """Both ways of Superposer.products (a correlation per input row, or per response) against apply()."""
    from creep_online.effects.responses import Superposer
    rng = np.random.default_rng(3)
    n = 500
    x = np.cumsum(rng.standard_normal((rows, n)) * (rng.uniform(size=(rows, n)) < 0.05), axis=1)
    sup = Superposer(np.arange(n) * 1e-3, x)
    steps = rng.standard_normal((k, n)).cumsum(axis=1)
    w, v = rng.standard_normal(rows), rng.standard_normal(n)
    summed, pulled = sup.products(steps, w, v)
    cols = sup.apply(steps)                                        # (k, rows, n)
    assert np.allclose(summed, np.einsum("krn,r->kn", cols, w), rtol=0, atol=1e-10 * np.abs(cols).max())
    assert np.allclose(pulled, cols @ v, rtol=1e-10)


def test_parallel_effect_without_derivatives_keeps_differences():
    """A plug-in parallel effect without ``unit_step_derivatives`` (the contract's default) is differenced."""
    from creep_online.effects import ParallelEffect, register_effect, unregister_effect
    from creep_online.effects.second_mode import SecondMode

    class PlainMode(SecondMode):
        name = "plain_mode_test"
        unit_step_derivatives = ParallelEffect.unit_step_derivatives

    register_effect(PlainMode)
    try:
        ds = hidden_dataset("second_mode", 1, n=3000)
        design = ext.Design(ext.prepare(ds.t, ds.u, ds.y), ("plain_mode_test",))
        assert design.exact == [0, 1, 2]
        theta = _theta(design, 0)
        jac = design.jacobian(theta)
        for k in range(theta.size):
            assert _relative(jac[:, k], _central(design, theta, k)) < (BASE_RTOL if k < 3 else EFFECT_RTOL)
    finally:
        unregister_effect("plain_mode_test")
