"""Effects as plug-ins: a ninth effect, declared as an entry point by a separate package, is simulated,
fitted by the extended fit, compensated online and tried by the diagnosis, with no change to creep_online.

The toy effect lives in its own module (written to a temporary folder with a ``*.dist-info`` that
declares it in the ``creep_online.effects`` entry-point group, the way a pip-installed plug-in does).
"""
from __future__ import annotations

import math
import sys
import textwrap

import numpy as np
import pytest

from creep_online import CreepModel, simulate
from creep_online.diagnostics import diagnose
from creep_online.diagnostics.extended import Design, fit_base, fit_extended, prepare
from creep_online.diagnostics.online import EffectCompensator
from creep_online.effects import (EFFECTS, ENTRY_POINT_GROUP, discover_entry_points, effect_names, get_effect,
                                  register_effect, simulate_with_effects, unregister_effect)
from creep_online.errors import ModelError
from creep_online.model import with_effects
from hil_sim.hidden_effects import hidden_dataset

NAME = "thermal_settling"

TOY_MODULE = '''
"""A toy plug-in effect: the output settles thermally, A (1 - exp(-(t - t0) / tau)) added to it."""
import math

import numpy as np

from creep_online.effects import AdditiveEffect, FitView, OutputCompensator, ParamSpec

TAU = "thermal_settling.log10_tau"


class _Compensator(OutputCompensator):
    def __init__(self, params):
        self.amplitude, self.tau = float(params["amplitude"]), float(params["tau_s"])

    def output(self, y, v, n, t):
        return y - self.amplitude * -math.expm1(-t / self.tau)


class ThermalSettling(AdditiveEffect):
    name = "thermal_settling"
    term = "A (1 - exp(-(t - t0) / tau)) added to the output"

    def add_to_output(self, t, y, params):
        return y + float(params["amplitude"]) * -np.expm1(-(t - t[0]) / float(params["tau_s"]))

    def output_columns(self, t, theta, harmonics):
        return [-np.expm1(-(t - t[0]) / 10 ** theta[TAU])], ["thermal_settling.amplitude"]

    def nonlinear_params(self, data):
        dur = data.t[-1] - data.t[0]
        return [ParamSpec(TAU, math.log10(dur / 100), math.log10(dur * 10))]

    def start_values(self, data, peaks):
        spec = self.nonlinear_params(data)[0]
        return [(list(np.linspace(spec.lo, spec.hi, 7)), [])]

    def fitted_params(self, fit: FitView):
        return {"amplitude": fit.coef["thermal_settling.amplitude"], "tau_s": 10 ** fit.theta[TAU]}

    def compensator(self, dt, params):
        return _Compensator(params)

    def signature(self, params, fit, base, where, data):
        return f"output settles with tau {params.get('tau_s', float('nan')):.3g} s"

    def contradiction(self, params, data):      # the signature before the base model was passed: still called
        return None if params.get("tau_s", 1.0) > 0 else "a negative time constant"

    def example_params(self, model, t, u, y_base, rng):
        return {"amplitude": float(np.ptp(y_base)) * rng.uniform(0.1, 0.2), "tau_s": (t[-1] - t[0]) * rng.uniform(0.1, 0.3)}
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The toy effect installed as a plug-in package (module + dist-info with the entry point)."""
    (tmp_path / "toy_creep_effects.py").write_text(textwrap.dedent(TOY_MODULE))
    info = tmp_path / "toy_creep_effects-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-creep-effects\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{NAME} = toy_creep_effects:ThermalSettling\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    discover_entry_points()
    yield get_effect(NAME)
    unregister_effect(NAME)
    monkeypatch.undo()
    sys.modules.pop("toy_creep_effects", None)
    discover_entry_points()


@pytest.fixture(scope="module")
def plant():
    model = CreepModel.from_resonance(0.3, 40.0, 0.1, 1.0)
    t = np.arange(4000) * 1e-3
    u = np.zeros(t.size)
    for i, level in ((200, 2.0), (1200, 5.0), (2000, 1.0), (3000, 4.0)):
        u[i:] = level
    return model, t, u


def test_the_entry_point_adds_a_ninth_effect(plugin):
    assert effect_names() == (*EFFECTS, NAME)
    assert EFFECTS == tuple(effect_names()[:8])          # the built-in catalogue is unchanged
    assert plugin.name == NAME and plugin.stage.value == "additive"


def test_the_plugin_is_simulated(plugin, plant):
    model, t, u = plant
    y = simulate_with_effects(model, t, u, {NAME: {"amplitude": 0.3, "tau_s": 0.5}, "drift": {"rate": 0.1}})
    expected = simulate(model, t, u) + 0.3 * (1 - np.exp(-t / 0.5)) + 0.1 * t
    assert np.max(np.abs(y - expected)) < 1e-10
    ext = with_effects(model, **{NAME: {"amplitude": 0.3, "tau_s": 0.5}})
    assert np.max(np.abs(ext.simulate(t, u) - (simulate(model, t, u) + 0.3 * (1 - np.exp(-t / 0.5))))) < 1e-10


def test_the_plugin_is_fitted_and_compensated(plugin, plant):
    model, t, u = plant
    truth = {"amplitude": 0.4, "tau_s": 0.7}
    y = simulate_with_effects(model, t, u, {NAME: truth}, u_pre=None)
    y = y + 1e-4 * np.random.default_rng(3).standard_normal(t.size)
    data = prepare(t, u, y)
    base = fit_base(data)
    fit = fit_extended(data, (NAME,), base)
    got = fit.effect_params[NAME]
    assert got["tau_s"] == pytest.approx(truth["tau_s"], rel=0.02)
    assert got["amplitude"] == pytest.approx(truth["amplitude"], rel=0.02)
    assert fit.residual_rms < 1.2e-4 < 0.05 * base.residual_rms
    assert Design(data, (NAME, "delay")).names[3:] == [f"{NAME}.log10_tau", "delay.d"]
    comp = EffectCompensator(1e-3, {NAME: truth})
    out = np.array([comp.step(a, b) for a, b in zip(u, y)])
    assert np.max(np.abs(out[:, 1] - (y - 0.4 * (1 - np.exp(-t / 0.7))))) < 1e-12


def test_the_diagnosis_tries_the_plugin_and_names_it(plugin):
    ds = hidden_dataset(NAME, 1)                       # the effect's own example_params hide it
    d = diagnose((ds.t, ds.u, ds.y))
    assert NAME in [c.effect for c in d.candidates]
    assert d.verdict == NAME, [(c.effect, round(c.evidence, 1)) for c in d.candidates]
    assert "settles with tau" in d.candidates[0].signature


def test_registry_call_without_entry_point(plant, tmp_path, monkeypatch):
    (tmp_path / "toy_creep_effects_direct.py").write_text(textwrap.dedent(TOY_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    from toy_creep_effects_direct import ThermalSettling
    try:
        register_effect(ThermalSettling)
        assert effect_names()[-1] == NAME
        with pytest.raises(ModelError, match="already registered"):
            register_effect(ThermalSettling())
        model, t, u = plant
        y = simulate_with_effects(model, t, u, {NAME: {"amplitude": 1.0, "tau_s": 1.0}})
        assert y[-1] - simulate(model, t, u)[-1] == pytest.approx(-math.expm1(-t[-1]))
    finally:
        unregister_effect(NAME)
    assert NAME not in effect_names()
    with pytest.raises(ModelError, match="unknown effect"):
        simulate_with_effects(plant[0], plant[1], plant[2], {NAME: {}})


def test_builtins_cannot_be_removed_and_bad_plugins_fail_in_one_line():
    with pytest.raises(ModelError, match="built-in"):
        unregister_effect("delay")
    with pytest.raises(ModelError, match="not an Effect"):
        register_effect(object())
    with pytest.raises(ModelError, match="cannot load effect"):
        register_effect("no_such_module_xyz:Effect")


def test_second_creep_example_is_a_valid_creep_for_any_alpha():
    """example_params gave alpha2 = alpha + 0.35 > 1 for alpha 0.77 (the diagnosis-bands bench crashed)."""
    import numpy as np
    from creep_online.effects import get_effect
    from creep_online.model import CreepModel
    eff = get_effect("second_creep")
    for alpha in np.linspace(0.005, 0.8, 41):
        m = CreepModel.from_resonance(float(alpha), 50.0, 0.1, 1.0)
        for seed in range(5):
            p = eff.example_params(m, None, None, None, np.random.default_rng(seed))
            assert 0.1 <= p["alpha2"] <= 0.95 and abs(p["alpha2"] - alpha) >= 0.3 - 1e-12
