"""The effect catalogue's forward model against independent references (closed forms, scipy, slow loops)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from creep_online import CreepModel, simulate
from creep_online.effects import (EFFECTS, base_step_at, creep_step, hysteresis_input, leakage_filter, loop_width,
                                  play_operators, resonance_step, simulate_with_effects)
from creep_online.effects.hysteresis import initial_plays
from creep_online.errors import ModelError

H = 1e-3
N = 3000


@pytest.fixture(scope="module")
def case():
    model = CreepModel.from_resonance(0.35, 40.0, 0.1, 2.0)
    t = np.arange(N) * H
    u = np.zeros(N)
    for i, level in ((100, 1.0), (900, 3.0), (1700, -1.0), (2400, 2.0)):
        u[i:] = level
    return model, t, u, simulate(model, t, u)


def test_catalogue_names_are_stable():
    assert EFFECTS == ("hysteresis", "nonlinear_gain", "second_mode", "drift", "leakage", "delay",
                       "periodic_disturbance", "second_creep")


def test_no_effect_equals_simulate(case):
    model, t, u, y0 = case
    assert np.max(np.abs(simulate_with_effects(model, t, u) - y0)) < 1e-12 * np.max(np.abs(y0)) + 1e-13


def test_integer_delay_is_a_shift(case):
    model, t, u, y0 = case
    y = simulate_with_effects(model, t, u, {"delay": {"delay_s": 7 * H}})
    assert np.max(np.abs(y[7:] - y0[:-7])) < 1e-11
    assert np.max(np.abs(y[:7])) < 1e-12


def test_fractional_delay_against_a_half_step_grid(case):
    """A 2.5-sample delay equals a 5-sample shift on a grid twice as fine (exact simulator there)."""
    model, t, u, _ = case
    y = simulate_with_effects(model, t, u, {"delay": {"delay_s": 2.5 * H}})
    fine = simulate(model, np.arange(2 * N) * H / 2, np.repeat(u, 2))
    k = np.arange(3, N)
    assert np.max(np.abs(y[k] - fine[2 * k - 5])) < 2e-4 * np.max(np.abs(fine))


def test_non_uniform_time_matches_uniform(case):
    model, t, u, y0 = case
    idx = np.unique(np.concatenate([np.arange(0, N, 7), np.arange(1, N, 13), [100, 900, 1700, 2400]]))
    y = simulate_with_effects(model, t[idx], u[idx])
    assert np.max(np.abs(y - y0[idx])) < 1e-8 * np.max(np.abs(y0))


def test_base_step_at_log_spaced_times():
    """Multi-resolution evaluation against the exact grid response at a few points."""
    from creep_online.discretize import step_response_grid
    alpha, a1, a2 = 0.6, 1e-3, 1e-6
    tau = np.geomspace(1e-3, 100.0, 200)
    s = base_step_at(alpha, a1, a2, tau)
    for target in (1e-3 * 37, 0.5, 99.0):
        h = target / 1000
        exact = step_response_grid(alpha, a1, a2, h, 1001)[-1]
        assert abs(base_step_at(alpha, a1, a2, np.array([target]))[0] - exact) < 1e-7 * abs(exact)
    assert np.all(np.diff(s) > 0)


@pytest.mark.parametrize("fn,zeta", [(40.0, 0.1), (1 / (2 * math.pi), 1.0), (1 / (2 * math.pi), 10.0)])
def test_resonance_step_against_scipy(fn, zeta):
    wn = 2 * math.pi * fn
    t = np.linspace(0, 20 / fn, 2000)
    _, ref = signal.step(signal.lti([1.0], [1 / wn**2, 2 * zeta / wn, 1.0]), T=t)
    assert np.max(np.abs(resonance_step(fn, zeta, t) - ref)) < 1e-9


def test_leakage_against_scipy_lsim():
    t = np.arange(2000) * 1e-3
    y = np.sin(20 * t) * t + (t > 0.5)
    y[0] = 0.0
    tau = 0.3
    _, ref, _ = signal.lsim(signal.lti([tau, 0.0], [tau, 1.0]), y, t, interp=True)
    assert np.max(np.abs(leakage_filter(t, y, tau) - ref)) < 1e-9


def test_leakage_non_uniform_matches_uniform_on_linear_signal():
    """For a piecewise-linear signal the FOH recursion is exact, whatever the steps."""
    t = np.arange(3001) * 1e-3
    y = np.interp(t, [0, 0.4, 1.2, 3.0], [0, 2.0, -1.0, 0.5])
    idx = np.unique(np.concatenate([[0, 400, 1200, 3000], np.arange(0, 3001, 37)]))
    full = leakage_filter(t, y, 0.7)
    assert np.max(np.abs(leakage_filter(t[idx], y[idx], 0.7) - full[idx])) < 1e-12


def test_play_operator_against_slow_loop():
    rng = np.random.default_rng(1)
    u = np.round(rng.normal(size=800).cumsum(), 1)  # repeated values: the change-only path is exercised
    r = np.array([0.0, 0.5, 2.0])
    ref = np.zeros((r.size, u.size))
    for i, ri in enumerate(r):
        p = u[0]
        for n in range(u.size):
            p = max(u[n] - ri, min(u[n] + ri, p))
            ref[i, n] = p
    assert np.array_equal(play_operators(u, r), ref)


@pytest.mark.parametrize("seed", range(6))
def test_play_operators_from_each_initial_state_against_slow_loop(seed):
    """Random thresholds, inputs that change at every sample or hold (staircases), each initial state: the
    compiled operator gives the slow loop's values bit for bit."""
    rng = np.random.default_rng([seed, 17])
    n = int(rng.integers(2, 1500))
    u = (rng.normal(size=n).cumsum() if seed % 2 else np.repeat(rng.normal(size=n // 7 + 1), 7)[:n]) * 10 ** rng.uniform(-3, 3)
    r = np.sort(rng.uniform(0.0, 1.0, int(rng.integers(1, 30)))) * np.ptp(u)
    state = ("centred", "ascending", "descending")[seed % 3]
    start = initial_plays(u[0], r, state)
    ref = np.zeros((r.size, u.size))
    for i, ri in enumerate(r):
        p = start[i]
        for k in range(u.size):
            p = max(u[k] - ri, min(u[k] + ri, p))
            ref[i, k] = p
    assert np.array_equal(play_operators(u, r, initial=start), ref)


def test_loop_width_of_a_single_operator():
    """One play operator of weight w cycled over the full range opens a loop 2 r w / (1 + w) high."""
    u = np.concatenate([np.linspace(0, 10, 200), np.linspace(10, 0, 200), np.linspace(0, 10, 200)])
    v = hysteresis_input(u, [1.5], [0.5])
    up, down = v[400:], v[200:400][::-1]
    numeric = np.max(np.interp(u[400:], u[200:400][::-1], down) - up) / 1.5
    assert loop_width([1.5], [0.5], 10.0) == pytest.approx(numeric, rel=1e-6)
    assert loop_width([1.5], [0.5], 10.0) == pytest.approx(2 * 1.5 * 0.5 / 1.5)


def test_hysteresis_initial_states_differ_only_before_the_operators_move():
    u = np.concatenate([np.full(10, 5.0), np.linspace(5, 10, 50), np.linspace(10, 0, 100)])
    a = hysteresis_input(u, [1.0, 2.0], [0.3, 0.2], "centred")
    b = hysteresis_input(u, [1.0, 2.0], [0.3, 0.2], "ascending")
    assert np.all(a[:10] != b[:10])
    assert np.allclose(a[-60:], b[-60:])
    with pytest.raises(ModelError):
        hysteresis_input(u, [1.0], [0.1], "sideways")


def test_second_creep_single_step_closed_form():
    model = CreepModel(0.3, 1e-4, 1e-8, 1.0)
    t = np.arange(2000) * 1e-3
    u = np.ones(2000)
    both = simulate_with_effects(model, t, u, {"second_creep": {"gain": 0.5, "alpha2": 0.8}})
    assert np.max(np.abs(both - simulate(model, t, u) - 0.5 * creep_step(0.8, t))) < 1e-12


def test_additive_and_input_effects(case):
    model, t, u, y0 = case
    y = simulate_with_effects(model, t, u, {"drift": {"rate": 0.2, "offset": 1.0},
                                            "periodic_disturbance": {"f_hz": 50.0, "amplitude": [0.1, 0.02],
                                                                     "phase": [0.3, 0.0]}}, offset=0.5)
    extra = 1.5 + 0.2 * t + 0.1 * np.sin(2 * np.pi * 50 * t + 0.3) + 0.02 * np.sin(2 * np.pi * 100 * t)
    assert np.max(np.abs(y - y0 - extra)) < 1e-12
    y2 = simulate_with_effects(model, t, u, {"nonlinear_gain": {"k2": 0.1, "k3": -0.01}})
    assert np.max(np.abs(y2 - simulate(model, t, u + 0.1 * u**2 - 0.01 * u**3))) < 1e-10
    y3 = simulate_with_effects(model, t, u, {"second_mode": {"gain": 0.3, "fn_hz": 150.0, "zeta": 0.05}})
    step = np.concatenate([[0.0], np.diff(u)])
    ref = sum(du * np.where(t >= t[i], resonance_step(150.0, 0.05, t - t[i]), 0.0)
              for i, du in enumerate(step) if du)
    assert np.max(np.abs(y3 - y0 - 0.3 * ref)) < 1e-10


def test_unknown_effect_is_a_one_line_error(case):
    model, t, u, _ = case
    with pytest.raises(ModelError, match="unknown effect"):
        simulate_with_effects(model, t, u, {"backlash": {}})


def test_second_mode_image_across_nyquist_has_the_same_sampled_poles():
    """The image start of a mode (``SecondMode.polished_starts``, the unscaled one) has the same discrete-time
    poles exp(s h) as the mode itself (independent reference: the roots of 1 + 2 zeta s / wn + s^2 / wn^2)."""
    from types import SimpleNamespace

    from creep_online.effects.second_mode import IMAGE_STEPS, SecondMode

    fs = 1000.0
    data = SimpleNamespace(uniform=True, fs=fs)

    def sampled_poles(fn, zeta):
        wn = 2 * np.pi * fn
        s = np.roots([1 / wn**2, 2 * zeta / wn, 1.0])
        return np.sort_complex(np.exp(s / fs))

    for fn, zeta in ((230.0, 0.19), (791.5, 0.0555), (120.0, 0.02)):
        theta = np.array([0.3, 2.0, -1.0, np.log10(fn), np.log10(zeta)])
        image = SecondMode().polished_starts(theta, [3, 4], data)[IMAGE_STEPS.index(1.0)]
        f2, z2 = 10 ** image[3], 10 ** image[4]
        assert abs(f2 - fn) > 1.0
        np.testing.assert_allclose(sampled_poles(f2, z2), sampled_poles(fn, zeta), rtol=0, atol=1e-12)
