"""A periodic input's lines (effects/input_lines.py), and the effects whose fit on one of them is no evidence.

Checked against inputs whose period is known by construction, and against
random staircases and noise, which must never pass as periodic (a false
"periodic" would make a real disturbance or mode not significant).
"""
from __future__ import annotations

import numpy as np
import pytest

from creep_online.diagnostics.extended import prepare
from creep_online.effects import get_effect
from creep_online.effects.input_lines import harmonic_of_input, input_fundamental
from hil_sim.hidden_effects import staircase

FS = 200.0
T = np.arange(8000) / FS           # 40 s


@pytest.mark.parametrize("shape", ["square", "triangle", "sine"])
@pytest.mark.parametrize("f0", [0.5, 1.0, 7.3])
def test_the_fundamental_of_a_periodic_input_is_found(shape, f0):
    phase = (T * f0) % 1.0
    u = {"square": np.sign(np.sin(2 * np.pi * f0 * T)), "triangle": np.abs(phase - 0.5),
         "sine": np.sin(2 * np.pi * f0 * T)}[shape]
    assert input_fundamental(T, u) == pytest.approx(f0, abs=0.5 / 40.0)


def test_random_staircases_prbs_like_inputs_and_noise_are_not_periodic():
    flagged = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        hold = (0.005, 0.05) if seed % 2 else (0.15, 1.0)       # a controller's output, and slow staircases
        n = int(rng.choice([2000, 6000, 30000]))
        t, u = staircase(n, 1.0 / FS if seed % 3 else 1e-3, rng, hold_s=hold)
        flagged += input_fundamental(t, u) is not None
        flagged += input_fundamental(t, rng.standard_normal(n)) is not None
        flagged += input_fundamental(t, np.sign(rng.standard_normal(n))) is not None   # random binary levels
    assert flagged == 0
    assert input_fundamental(T, np.ones_like(T)) is None and input_fundamental(T, T) is None


def test_a_line_on_a_harmonic_is_locked_and_one_between_harmonics_is_not():
    u = np.sign(np.sin(2 * np.pi * 1.0 * T))
    assert harmonic_of_input(3.0, T, u)[0] == 3
    assert harmonic_of_input(2.0004, T, u)[0] == 2
    assert harmonic_of_input(2.5, T, u) is None
    assert harmonic_of_input(3.0, T, np.sin(2 * np.pi * 0.37 * T) + np.sin(2 * np.pi * 5.11 * T)) is None
    assert harmonic_of_input(50.0, T, u) is None              # mains on a slow drive: past MAX_HARMONIC


def test_a_disturbance_or_a_narrow_mode_on_the_input_harmonic_contradicts_the_effect():
    u = np.sign(np.sin(2 * np.pi * 1.0 * T))
    data = prepare(T, u, u)
    line = get_effect("periodic_disturbance")
    assert "locked to the input" in line.contradiction({"f_hz": 3.0, "amplitude": 1.0, "phase": 0.0}, data)
    assert line.contradiction({"f_hz": 50.0, "amplitude": 1.0, "phase": 0.0}, data) is None
    mode = get_effect("second_mode")
    assert "not a mode" in mode.contradiction({"fn_hz": 1.9995, "zeta": 0.001, "gain": 1.0}, data)
    assert mode.contradiction({"fn_hz": 2.0, "zeta": 0.05, "gain": 1.0}, data) is None     # wider than 1/T: a mode
    assert mode.contradiction({"fn_hz": 2.5, "zeta": 0.001, "gain": 1.0}, data) is None
    assert get_effect("drift").contradiction({}, data) is None


def test_a_second_mode_below_the_first_or_without_a_resonance_peak_is_not_a_mode():
    """The catalogue's second mode is a *higher* structural mode that rings: a fitted one at or below the base
    model's resonance, or damped past 1/sqrt(2), is a path standing in for a slow effect (the pairs bench's
    leakage + drift records: 0.17 Hz beside a 7 Hz first mode; 70.9 Hz at zeta 0.81 beside a base deformed to
    3 Hz at zeta 5.4)."""
    from creep_online import CreepModel
    rng = np.random.default_rng(3)
    t, u = staircase(6000, 1e-3, rng)
    data = prepare(t, u, u)
    first = CreepModel.from_resonance(alpha=0.03, fn=7.0, zeta=0.9, b=1.5)
    mode = get_effect("second_mode")
    assert "not above the first mode" in mode.contradiction({"fn_hz": 0.17, "zeta": 0.26, "gain": -0.04}, data,
                                                            model=first)
    assert "not above the first mode" in mode.contradiction({"fn_hz": 6.9, "zeta": 0.05, "gain": 0.1}, data,
                                                            model=first)
    assert "no resonance peak" in mode.contradiction({"fn_hz": 70.9, "zeta": 0.81, "gain": 1.4}, data, model=first)
    assert mode.contradiction({"fn_hz": 25.0, "zeta": 0.05, "gain": 0.1}, data, model=first) is None
    assert mode.contradiction({"fn_hz": 0.17, "zeta": 0.26, "gain": -0.04}, data) is None   # no base model given
