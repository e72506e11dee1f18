"""Online with an extended model: the per-sample compensation is exact, and the live error falls."""
from __future__ import annotations

import numpy as np
import pytest

from creep_online import CreepModel, simulate
from creep_online.diagnostics.online import EffectCompensator, format_live_error, live_error
from creep_online.effects import simulate_with_effects

EFFECTS = {
    "periodic_disturbance": {"f_hz": 50.0, "amplitude": [0.02, 0.005], "phase": [0.3, 1.0]},
    "delay": {"delay_s": 3e-3},
    "drift": {"rate": 0.01},
    "leakage": {"tau_s": 2.0},
    "second_mode": {"gain": 0.1, "fn_hz": 150.0, "zeta": 0.03},
    "second_creep": {"gain": 0.3, "alpha2": 0.8},
    "nonlinear_gain": {"k2": 0.05, "k3": -0.002},
    "hysteresis": {"r": [0.5, 1.0], "w": [0.2, 0.1], "initial": "ascending"},
}


@pytest.mark.parametrize("name", list(EFFECTS))
def test_compensator_inverts_the_forward_model(name):
    """Compensating the catalogue's output sample by sample leaves exactly the base model's response."""
    model = CreepModel.from_resonance(0.3, 40.0, 0.1, 1.0)
    t = np.arange(3000) * 1e-3
    u = np.zeros(t.size)
    u[200:], u[1200:], u[2000:] = 2.0, 5.0, 1.0
    eff = {name: EFFECTS[name]}
    y = simulate_with_effects(model, t, u, eff)
    comp = EffectCompensator(1e-3, eff)
    out = np.array([comp.step(a, b) for a, b in zip(u, y)])
    ref = simulate(model, t, out[:, 0])
    tol = 1e-6 if name == "leakage" else 1e-12  # leakage: trapezoid integral vs the exact FOH filter
    assert np.max(np.abs(out[:, 1] - ref)) < tol * np.ptp(ref)


def test_live_error_falls_with_the_extended_model():
    """A leaking sensor: the plain online estimator's error grows during the hold, the extended one's does not."""
    model = CreepModel.from_resonance(0.3, 40.0, 0.1, 1.0)
    h, n, noise = 1e-3, 8000, 0.002
    t = np.arange(n) * h
    u = np.zeros(n)
    u[200:] = 2.0
    eff = {"leakage": {"tau_s": 20.0}}
    y = simulate_with_effects(model, t, u, eff) + noise * np.random.default_rng(0).standard_normal(n)
    table = live_error(t, u, y, eff, window_s=1.0)
    base, ext = np.array(table["base"][-3:]), np.array(table["extended"][-3:])
    assert np.all(np.isfinite(base)) and np.all(np.isfinite(ext))
    assert ext.mean() < 0.5 * base.mean()
    assert "extended" in format_live_error(table, noise)


def test_fractional_delay_is_compensated_to_second_order():
    """A delay of 2.4 samples: the split of each held sample between two neighbours (not rounding to 2)."""
    model = CreepModel.from_resonance(0.3, 40.0, 0.1, 1.0)
    t = np.arange(3000) * 1e-3
    u = np.zeros(t.size)
    u[200:], u[1200:], u[2000:] = 2.0, 5.0, 1.0
    eff = {"delay": {"delay_s": 2.4e-3}}
    y = simulate_with_effects(model, t, u, eff)
    comp = EffectCompensator(1e-3, eff)
    out = np.array([comp.step(a, b) for a, b in zip(u, y)])
    err = np.max(np.abs(out[:, 1] - simulate(model, t, out[:, 0])))
    rounded = EffectCompensator(1e-3, {"delay": {"delay_s": 2e-3}})
    out2 = np.array([rounded.step(a, b) for a, b in zip(u, y)])
    err2 = np.max(np.abs(out2[:, 1] - simulate(model, t, out2[:, 0])))
    assert err < 0.1 * err2
    assert err < 2e-3 * np.ptp(y)


def test_warm_start_follows_the_batch_fit():
    from creep_online.diagnostics.online import warm_start
    m = CreepModel.from_resonance(0.4, 40.0, 0.1, 1.0)
    kw = warm_start(m, 1e-3)
    assert kw["alpha0"] == pytest.approx(0.4)
    assert "t_c" not in kw          # the estimator chooses its own search window
    assert warm_start(None, 1e-3) == {}


# Hidden-effect records (hil_sim, realistic strengths: base residual 2-12x the noise), 6 s at 1 kHz,
# a seed the measurement table in docs/diagnostics.md does not use. Both online estimators start
# with their own batch fit's alpha as a hint (alpha0). The compensated live error over the last quarter must be
# within 2.5x the noise floor (measured 0.98-2.2x on seeds 5 and 6; drift is the worst, the online
# layer-2 resonance fit on the short t_c buffer, not the compensation) and well below the plain one.
ONLINE_SEED, ONLINE_N = 5, 6000


@pytest.mark.parametrize("name", list(EFFECTS))
def test_online_live_error_falls_to_the_noise_floor(name):
    from hil_sim.online_table import measure
    row = measure(name, ONLINE_SEED, ONLINE_N)
    assert row["online_extended"] < 2.5, row
    assert row["online_extended"] < 0.6 * row["online_plain"], row


def test_online_clean_data_is_at_the_noise_floor():
    from hil_sim.online_table import measure
    row = measure(None, ONLINE_SEED, ONLINE_N)
    assert row["online_plain"] < 1.3 and row["online_extended"] == row["online_plain"], row
