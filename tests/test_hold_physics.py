"""The hold physics check (diagnostics/holds.py) and the verdict's basis (diagnostics/basis.py).

Seeded staircase records (the generator of ``hil_sim.hidden_effects`` and of
bench/bench_diagnose_bands.py: holds 0.2-1 s, 6000 samples at 1 kHz) of
leakage, a second creep and drift at several strengths, the noise set so that
the base model misses by ``ratio`` x the noise (1.5 and 2.5 are the weak band):
the check names the hidden effect. Clean data: ``none`` (or inconclusive);
holds shorter than the resonance's settling: inconclusive, never a guess.
Outcomes only.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from creep_online.diagnostics import diagnose
from creep_online.diagnostics.basis import CONFIRMED, DISAGREE, verdict_basis
from creep_online.diagnostics.extended import fit_base, prepare
from creep_online.diagnostics.holds import EFFECTS, physics_check
from creep_online.effects import simulate_with_effects
from creep_online.model import CreepModel
from hil_sim.hidden_effects import staircase

PLANT = CreepModel.from_resonance(0.3, 40.0, 0.3, 1.0)
PARAMS = {"drift": {"rate": 0.12}, "leakage": {"tau_s": 4.0}, "second_creep": {"gain": 0.3, "alpha2": 0.7}}


def _record(effect: str | None, ratio: float, seed: int, hold_s=(0.2, 1.0), n: int = 6000):
    """t, u, y of PLANT with one effect, noise so that the base model misses by ``ratio`` x the noise."""
    rng = np.random.default_rng(seed)
    t, u = staircase(n, 1e-3, rng, hold_s=hold_s)
    if effect is None:
        y = simulate_with_effects(PLANT, t, u)
        noise = 0.005 * float(np.ptp(y))
    else:
        y = simulate_with_effects(PLANT, t, u, {effect: PARAMS[effect]})
        noise = fit_base(prepare(t, u, y)).residual_rms / math.sqrt(ratio ** 2 - 1.0)
    return t, u, y + noise * rng.standard_normal(n)


def _diagnosed(effect, ratio, seed, **kw):
    t, u, y = _record(effect, ratio, seed, **kw)
    return diagnose((t, u, y), candidates=EFFECTS, workers=1, combine=False)


# the weakest and the strongest by default; the strengths between (the weak band's 2.5, a clear 5.0) with -m slow
@pytest.mark.parametrize("effect", EFFECTS)
@pytest.mark.parametrize("ratio", [1.5, pytest.param(2.5, marks=pytest.mark.slow),
                                   pytest.param(5.0, marks=pytest.mark.slow), 30.0])
def test_the_holds_name_the_hidden_effect_at_every_strength(effect, ratio):
    d = _diagnosed(effect, ratio, 1)
    assert d.physics["verdict"] == effect, d.physics["reason"]
    assert d.physics["evidence"][effect] == max(d.physics["evidence"].values())
    assert d.verdict_basis["decided_by"] == CONFIRMED and d.verdict_basis["agrees"] is True


def test_the_fitted_motion_carries_the_effects_numbers():
    """The leakage's time constant and the drift's rate come out of the holds alone."""
    leak = _diagnosed("leakage", 5.0, 2).physics
    assert leak["verdict"] == "leakage"
    assert leak["params"]["leakage"]["tau_s"] == pytest.approx(4.0, rel=0.15)
    drift = _diagnosed("drift", 5.0, 2).physics
    assert drift["verdict"] == "drift"
    assert drift["params"]["drift"]["rate"] == pytest.approx(0.12, rel=0.05)


@pytest.mark.parametrize("seed", [1, 2])
def test_clean_records_show_no_hold_effect(seed):
    t, u, y = _record(None, 1.0, seed)
    data = prepare(t, u, y)
    assert physics_check(data, fit_base(data))["verdict"] in ("none", "inconclusive")


def test_holds_shorter_than_the_settling_are_inconclusive():
    """Holds of 20-60 ms against a resonance that settles in ~0.5 s: too short to watch, so no guess."""
    t, u, y = _record("leakage", 5.0, 3, hold_s=(0.02, 0.06))
    data = prepare(t, u, y)
    check = physics_check(data, fit_base(data))
    assert check["verdict"] == "inconclusive" and not check["applicable"]
    assert "hold" in check["reason"]


def test_a_non_staircase_input_is_inconclusive():
    t = np.arange(4000) * 1e-3
    u = np.sin(2 * np.pi * 3 * t) + 0.5 * np.sin(2 * np.pi * 11 * t)
    y = simulate_with_effects(PLANT, t, u, {"drift": PARAMS["drift"]})
    y = y + 1e-3 * np.random.default_rng(0).standard_normal(t.size)
    data = prepare(t, u, y)
    check = physics_check(data, fit_base(data))
    assert check["verdict"] == "inconclusive" and "staircase" in check["reason"]


def test_json_gains_the_physics_check_and_the_verdicts_basis():
    t, u, y = _record("drift", 3.0, 4)
    out = diagnose((t, u, y), workers=1).to_dict()
    for key in ("fit_percent", "residual_rms", "noise_rms", "verdict", "missing_effects"):   # stable keys kept
        assert key in out
    assert out["verdict"] == "drift"
    ph, basis = out["physics_check"], out["verdict_basis"]
    assert {"applicable", "verdict", "reason", "evidence", "margin", "holds", "hold_seconds", "params"} <= set(ph)
    assert set(ph["evidence"]) == set(EFFECTS)
    assert {"decided_by", "physics_verdict", "agrees", "text"} <= set(basis)
    assert basis["decided_by"] in ("bic_ranking", "bic_confirmed_by_physics", "bic_over_physics")
    assert basis["physics_verdict"] == ph["verdict"]
    json.loads(json.dumps(out))


def test_a_disagreement_is_said_plainly_and_the_bic_verdict_stands():
    physics = {"verdict": "leakage", "reason": "the output returns toward 0 during holds"}
    basis = verdict_basis("second_creep", {"second_creep": 120.0, "leakage": 100.0}, physics)
    assert basis["decided_by"] == DISAGREE and basis["agrees"] is False
    assert basis["bic_lead"] == pytest.approx(20.0)
    assert "AGAINST" in basis["text"] and "leakage" in basis["text"]
    other = verdict_basis("hysteresis", {"hysteresis": 50.0}, physics)
    assert other["decided_by"] == "bic_ranking" and other["agrees"] is None
    unsure = verdict_basis("drift", {"drift": 50.0}, {"verdict": "inconclusive", "reason": "too few holds"})
    assert unsure["decided_by"] == "bic_ranking" and "too few holds" in unsure["text"]
