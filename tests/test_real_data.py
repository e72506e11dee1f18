"""Diagnosis of real third-party measurements (tests/data/real/, each with its source and licence): known physics turned into assertions.

* both 1 Hz piezo sets: hysteresis, its fitted loop a model (bounded weights,
  invertible, simulate gives the fit again); by default the micromanipulator's
  first 10 s (the tutorial's excerpt), both whole records with ``-m slow``;
* the fine-steering mirror: a second resonance (~0.9 and ~2.1 kHz), from a
  virtual single-input record (the raw t,u,y view has three inputs active);
* the polymer melt creep (log-spaced, repeated time stamps): a single
  power law is a poor fit; a second creep term explains slope 0.6 -> 1.
What the tool says about each is recorded in docs/diagnostics.md.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from creep_online.diagnostics import diagnose
from creep_online.diagnostics.loading import load_for_diagnosis
from creep_online.diagnostics.mimo import virtual_siso
from creep_online.effects import SLOPE_FLOOR, hysteresis_input, invert_hysteresis
from creep_online.effects.hysteresis import flattest_branch
from creep_online.metrics import rms

from conftest import DATA

REAL = DATA / "real"


def _hysteresis_is_a_model(d, record) -> dict:
    """The diagnosis' hysteresis fit: weights bounded, every branch at least SLOPE_FLOOR of the mean, the analytic
    inverse undoing the loop, ``simulate`` giving ``y_hat`` again, at most the opened operators determined."""
    fit = next(c.fit for c in d.candidates if tuple(c.fit.effects) == ("hysteresis",))
    hp = fit.effect_params["hysteresis"]
    w = np.asarray(hp["w"])
    assert np.max(np.abs(w)) <= 1.0 and flattest_branch(hp["r"], w) >= SLOPE_FLOOR * (1 - 1e-9)
    assert rms(fit.simulate(record.t, record.u) - fit.y_hat) <= 1e-6 * fit.residual_rms
    v = hysteresis_input(record.u, hp["r"], w, hp["initial"])
    assert np.max(np.abs(invert_hysteresis(v, hp) - record.u)) <= 1e-12 * np.ptp(record.u)
    assert 0.0 < hp["determined"] <= hp["opened"] + 1e-9
    return {"fit": fit, **hp}


def _diagnose(path):
    inp = load_for_diagnosis(path if isinstance(path, Path) else REAL / path)
    return diagnose(inp.record, u_pre=inp.u_pre, t_pre=inp.t_pre)


def _excerpt(rel: str, rows: int | None, folder: Path) -> Path:
    """The record's header and first ``rows`` samples as a file of its own (the whole record for None)."""
    if rows is None:
        return REAL / rel
    lines = (REAL / rel).read_text().splitlines(keepends=True)
    out = folder / Path(rel).name
    out.write_text("".join(lines[:1 + rows]))
    return out


# a 50,001-sample diagnosis; the micromanipulator test below takes the same path (hysteresis named on a real 1 Hz
# sine record, its loop a model) and the tutorial diagnoses a 2 s excerpt of this record: -m long
@pytest.mark.long
def test_piezo_150v_shows_hysteresis():
    d = _diagnose("piezo-hyst-150V-1Hz/piezo_150V_1Hz.csv")
    assert d.verdict == "hysteresis"
    top = d.candidates[0]
    assert top.fit.fit_percent > d.base.fit_percent + 3.0
    assert 0.01 < top.fit.effect_params["hysteresis"]["loop_width_rel"] < 0.3
    hp = _hysteresis_is_a_model(d, load_for_diagnosis(REAL / "piezo-hyst-150V-1Hz/piezo_150V_1Hz.csv").record)
    assert hp["fit"].fit_percent > 99.2 and d.base.fit_percent < 94.0          # 93.6 % -> 99.27 %


# the tutorial's excerpt (the first 10 s: the loading curve and ten loops) by default, the whole record with -m slow
@pytest.mark.parametrize("rows", [2000, pytest.param(None, marks=pytest.mark.long)], ids=["10s", "whole"])
def test_micromanipulator_shows_hysteresis(rows, tmp_path):
    path = _excerpt("piezo-micromanipulator-1Hz/micromanipulator_1Hz.csv", rows, tmp_path)
    d = _diagnose(path)
    assert d.verdict == "hysteresis"
    assert d.location["input_regimes"]["direction_split"] > 0.5
    # the loop is asymmetric: hysteresis with a nonlinear gain beats either alone
    assert d.combination is not None and set(d.combination.fit.effects) == {"hysteresis", "nonlinear_gain"}
    assert d.combination.significant
    hp = _hysteresis_is_a_model(d, load_for_diagnosis(path).record)
    assert hp["fit"].fit_percent > 97.5


def _fsm(level):
    ins, outs = [], []
    for r in range(3):
        a = np.loadtxt(REAL / "fsm-cubespec-multisine" / f"fsm_{level}mV_test_r{r}.csv.gz", delimiter=",", skiprows=1)
        ins.append(a[:, [1, 3, 4]])
        outs.append(a[:, 2])
    return virtual_siso(ins, outs, fs=6400.0, period=8192, channel=0, periods=2)


@pytest.mark.parametrize("level", [pytest.param(100, marks=pytest.mark.long), pytest.param(300, marks=pytest.mark.long)])
def test_fine_steering_mirror_has_a_second_mode(level):
    t, u, y = _fsm(level)
    d = diagnose((t, u, y))
    assert d.verdict == "second_mode"
    fit = d.candidates[0].fit
    modes = sorted([fit.model.fn, fit.effect_params["second_mode"]["fn_hz"]])
    assert 800 < modes[0] < 1100 and 1900 < modes[1] < 2300, modes


@pytest.fixture(scope="module")
def polymer_creep():
    """The polymer creep record's diagnosis (both tests below read the same one)."""
    return _diagnose("pe-melt-creep-reptate/pe_cm3_creep_10Pa.csv")


@pytest.mark.long
class TestPolymerCreep:
    """Two tests of one diagnosis (fixture ``polymer_creep``): a class, so that a parallel run keeps them on one
    worker."""

    def test_polymer_creep_needs_a_second_power_law(self, polymer_creep):
        d = polymer_creep
        assert d.data.weights is not None  # log-spaced: relative fit
        assert d.verdict == "second_creep"
        fit = d.candidates[0].fit
        lo, hi = sorted([fit.model.alpha, fit.effect_params["second_creep"]["alpha2"]])
        assert lo < 0.7 and hi > 0.8  # short-time slope ~0.6, terminal flow ~1
        assert fit.residual_rms < 0.3 * d.base.residual_rms

    def test_polymer_creep_one_hold_leaves_the_physics_inconclusive_and_the_bic_decides(self, polymer_creep):
        """A creep test is a single hold: whether the extra motion follows the input (second creep) or ignores it
        (drift) cannot be seen in one hold, so the hold physics says so and the verdict rests on the BIC ranking."""
        d = polymer_creep
        assert d.verdict == "second_creep"
        assert d.physics["verdict"] == "inconclusive" and "too few" in d.physics["reason"]
        basis = d.to_dict()["verdict_basis"]
        assert basis["decided_by"] == "bic_ranking" and basis["agrees"] is None
