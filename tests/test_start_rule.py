"""One start rule for identify, fit, diagnose and compare: from rest for a step experiment, in equilibrium at the
first input otherwise, the other reading only when it fits clearly better."""
from __future__ import annotations

import contextlib
import io
import json
import warnings

import numpy as np
import pytest

from creep_online import CreepModel, identify
from creep_online.cli import main
from creep_online.diagnostics.start import CLEARLY_BETTER, clearly_better, fit_base_by_rule, readings
from creep_online.effects import simulate_with_effects
from creep_online.io import save_csv


def test_readings_follow_identifys_rule():
    steps = np.r_[np.full(300, 1.0), np.full(300, -0.5)]                 # a step experiment, u[0] != 0
    dense = np.random.default_rng(0).uniform(-1, 1, 600)                 # changes at every sample
    assert readings(steps) == [(0.0, None), (None, None)]                # from rest first
    assert readings(dense + 2.0) == [(None, None), (0.0, None)]          # equilibrium at u[0] first
    assert readings(np.r_[0.0, steps]) == [(None, None)]                 # u[0] = 0: both readings agree
    assert readings(np.full(50, 3.0)) == [(0.0, None)]                   # a constant input is a step from rest
    assert readings(steps, u_pre=0.0, t_pre=-1.0) == [(0.0, -1.0)]       # a reading given is kept
    assert clearly_better(CLEARLY_BETTER * 0.99, 1.0) and not clearly_better(CLEARLY_BETTER * 1.01, 1.0)


def _step_at_first_sample(seed: int = 0):
    """Up and down steps from rest, the first at the first sample, with a slow drift; 2 kHz."""
    rng = np.random.default_rng(seed)
    m = CreepModel.from_resonance(0.25, 60.0, 0.12, 1.3)
    t = np.arange(8000) * 5e-4
    u = np.where(t < 1.0, 1.0, np.where(t < 2.5, -0.4, 0.7))
    y = simulate_with_effects(m, t, u, {"drift": {"rate": 0.03, "offset": 0.0}}) + 0.2
    return t, u, y + 1e-3 * rng.standard_normal(t.size)


def _json(argv) -> dict:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main([*map(str, argv), "--json"]) == 0
    return json.loads(buf.getvalue())


def test_fit_and_diagnose_read_a_record_from_rest_alike(tmp_path):
    t, u, y = _step_at_first_sample()
    path = tmp_path / "rec.csv"
    save_csv(path, t, u, y)
    fit = _json(["fit", path, "--effects", "drift"])
    diag = _json(["diagnose", path, "--effects", "drift"])
    drift = next(c for c in diag["missing_effects"] if c["effect"] == "drift")
    assert fit["fit_percent_before"] == pytest.approx(diag["fit_percent"], abs=1e-9)       # the same base fit
    assert fit["fit_percent"] == pytest.approx(drift["fit_percent_after"], abs=0.05)
    assert fit["fit_percent"] > 99.0                                     # read from rest, as identify reads it
    assert any("starts from rest" in n for n in fit["notes"])
    assert identify(t, u, y).fit_percent > 95.0


def test_a_record_in_equilibrium_keeps_that_reading():
    rng = np.random.default_rng(1)
    m = CreepModel.from_resonance(0.2, 60.0, 0.12, 1.0)
    t = np.arange(8000) * 5e-4
    u = np.where(t < 1.0, 2.0, np.where(t < 2.5, 1.2, 2.6))             # at 2.0 long before the record
    y = simulate_with_effects(m, t, u, u_pre=None) + 1e-3 * rng.standard_normal(t.size)
    notes: list[str] = []
    data, base = fit_base_by_rule(t, u, y, warnings=notes)
    assert data.u_pre is None and base.fit_percent > 99.0
    assert any("equilibrium" in n and "clearly better" in n for n in notes)
