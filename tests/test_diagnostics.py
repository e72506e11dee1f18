"""Model discrepancy: hidden effects are found, ranked first and removed; clean data give ``none``.

The data come from ``hil_sim.hidden_effects`` (staircase with reversals and
several amplitudes; base fit residual 2-12x the noise floor by construction,
checked here against the 1.5-40x band). One seed per effect runs by default,
a different one for each effect so that plants and strengths vary; five more
per effect run with ``-m slow``.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from creep_online import CreepModel, simulate
from creep_online.diagnostics import (autocorrelation, cross_correlation, diagnose, fit_base, fit_extended, prepare,
                                      with_effects)
from creep_online.diagnostics.loading import load_for_diagnosis
from creep_online.diagnostics.locate import input_regimes, spectrum_peaks
from creep_online.effects import EFFECTS, get_effect, simulate_with_effects
from hil_sim.hidden_effects import hidden_dataset, save, staircase


ROOT = Path(__file__).resolve().parents[1]
CASES = [None, *EFFECTS]


def _check_case(effect, seed):
    ds = hidden_dataset(effect, seed)
    base_ratio = None
    d = diagnose((ds.t, ds.u, ds.y))
    base_ratio = d.base.residual_rms / ds.noise_std
    if effect is None:
        assert d.verdict == "none", [(c.effect, c.evidence) for c in d.candidates[:3]]
        assert base_ratio < 1.3
        return d, ds
    assert 1.5 <= base_ratio <= 40.0, f"hidden strength out of the realistic band: {base_ratio:.2f}"
    top = d.candidates[0]
    assert top.effect == effect, [(c.effect, round(c.evidence)) for c in d.candidates[:3]]
    assert d.verdict == effect
    assert top.fit.residual_rms <= 1.3 * ds.noise_std, top.fit.residual_rms / ds.noise_std
    _check_params(effect, top.fit.effect_params[effect], ds)
    return d, ds


def _check_params(effect, p, ds):
    """The reported parameters match the hidden truth where the data pin them down."""
    truth = ds.params
    if effect == "second_mode":
        assert p["fn_hz"] == pytest.approx(truth["fn_hz"], rel=0.05)
    elif effect == "delay":
        assert abs(p["delay_s"] - truth["delay_s"]) < 0.5e-3
    elif effect == "periodic_disturbance":
        assert p["f_hz"] == pytest.approx(truth["f_hz"], rel=2e-3)
        assert p["amplitude"] == pytest.approx(truth["amplitude"], rel=0.2)
    elif effect == "second_creep":
        assert abs(p["alpha2"] - truth["alpha2"]) < 0.15
    elif effect == "drift":
        assert p["rate"] == pytest.approx(truth["rate"], rel=0.35)
    elif effect == "leakage":
        assert p["tau_s"] == pytest.approx(truth["tau_s"], rel=0.5)
    elif effect == "hysteresis":
        assert p["loop_width_rel"] > 0


@pytest.mark.parametrize("effect", CASES, ids=lambda e: e or "clean")
def test_hidden_effect_found_and_removed(effect):
    _check_case(effect, seed=11 + CASES.index(effect))


@pytest.mark.parametrize("effect", EFFECTS)
def test_a_weak_hidden_effect_is_named_and_removed(effect):
    """The weak end of issue 9's strength range: the base model misses by ~1.4x the noise (1.3-3x band;
    the test above draws 2-12x). Each effect is named first and its fit reaches the floor."""
    ds = hidden_dataset(effect, 21, ratio=1.4)
    d = diagnose((ds.t, ds.u, ds.y))
    assert 1.3 <= d.base.residual_rms / ds.noise_std <= 1.5
    assert d.verdict == effect, [(c.effect, round(c.evidence)) for c in d.candidates[:3]]
    assert d.candidates[0].fit.residual_rms <= 1.1 * ds.noise_std


@pytest.mark.slow
@pytest.mark.parametrize("seed", [21, 22, 23, 24, 25])
@pytest.mark.parametrize("effect", CASES, ids=lambda e: e or "clean")
def test_hidden_effect_more_seeds(effect, seed):
    _check_case(effect, seed)


def test_diagnosis_json_schema():
    ds = hidden_dataset("delay", 3)
    out = diagnose((ds.t, ds.u, ds.y)).to_dict()
    for key in ("fit_percent", "residual_rms", "noise_rms", "verdict", "missing_effects"):
        assert key in out
    assert out["verdict"] in (*EFFECTS, "none")
    for item in out["missing_effects"]:
        assert {"effect", "evidence", "fit_percent_after", "residual_rms_after", "params"} <= set(item)
    ev = [m["evidence"] for m in out["missing_effects"]]
    assert ev == sorted(ev, reverse=True)
    json.dumps(out)  # JSON-ready (NaN allowed by Python's json)


def test_extended_fit_forward_consistency():
    """The fitted extended model, simulated again through the catalogue, reproduces its own output."""
    ds = hidden_dataset("hysteresis", 5)
    data = prepare(ds.t, ds.u, ds.y)
    for eff in (("hysteresis",), ("delay", "drift"), ("second_mode",), ("leakage",)):
        fit = fit_extended(data, eff)
        assert np.max(np.abs(fit.simulate(ds.t, ds.u) - fit.y_hat)) < 1e-6 * np.ptp(ds.y)


def _delay_and_drift(noise: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A staircase record (4,000 samples at 1 kHz) with a 3.4 ms delay and a drift hidden together, and white
    noise of std ``noise``."""
    rng = np.random.default_rng(7)
    t, u = staircase(4000, 1e-3, rng)
    model = CreepModel.from_resonance(0.4, 45.0, 0.12, 1.3)
    y = simulate_with_effects(model, t, u, {"delay": {"delay_s": 3.4e-3}, "drift": {"rate": 0.08}})
    return t, u, y + noise * rng.standard_normal(t.size)


def test_two_hidden_effects_need_both():
    """Delay and drift hidden together: each alone leaves a misfit, both bring the residual to the noise."""
    noise = 0.004
    t, u, y = _delay_and_drift(noise)
    data = prepare(t, u, y)
    base = fit_base(data)
    both = fit_extended(data, "delay,drift", base)
    assert both.residual_rms < 1.3 * noise
    for single in ("delay", "drift"):
        assert fit_extended(data, single, base).residual_rms > 1.5 * noise
    assert both.effect_params["delay"]["delay_s"] == pytest.approx(3.4e-3, abs=3e-4)


def test_the_pair_search_names_two_hidden_effects():
    """Delay and drift hidden together, diagnosed: neither explains the record alone, so the search fits the pairs
    round by round and names both, down to the noise (the search's rounds in the default suite: the real records
    that reach them take a minute)."""
    noise = 0.004
    t, u, y = _delay_and_drift(noise)
    stages: list[str] = []
    d = diagnose((t, u, y), candidates=("delay", "drift"), progress=stages.append, workers=1)
    assert any(s.startswith("pair search:") for s in stages), stages
    assert d.combination is not None and d.combination.significant
    assert set(d.combination.fit.effects) == {"delay", "drift"}
    assert d.combination.fit.residual_rms < 1.3 * noise


def test_with_effects_api_matches_catalogue():
    model = CreepModel.from_resonance(0.3, 50.0, 0.1)
    t = np.arange(1000) * 1e-3
    u = (t > 0.1).astype(float)
    ext = with_effects(model, delay={"delay_s": 2e-3}).with_effects(drift={"rate": 0.5})
    ref = simulate_with_effects(model, t, u, {"delay": {"delay_s": 2e-3}, "drift": {"rate": 0.5}})
    assert np.array_equal(ext.simulate(t, u), ref)
    with pytest.raises(Exception, match="unknown effect"):
        with_effects(model, wobble={})


def test_residual_whiteness_bounds():
    rng = np.random.default_rng(0)
    n = 5000
    white = rng.standard_normal(n)
    ac = autocorrelation(white)
    assert ac["bound"] == pytest.approx(2.5758 / math.sqrt(n), rel=1e-4)
    assert ac["white"]
    coloured = np.convolve(white, np.ones(5) / 5, mode="same")
    assert not autocorrelation(coloured)["white"]
    u = np.cumsum(rng.standard_normal(n))  # du is white: independent of an unrelated residual
    assert cross_correlation(white, u)["independent"]
    assert not cross_correlation(white + 3 * np.diff(u, prepend=u[0]), u)["independent"]


def test_locate_signatures():
    ds = hidden_dataset("hysteresis", 2)
    base = fit_base(prepare(ds.t, ds.u, ds.y))
    assert input_regimes(ds.u, base.residual)["direction_split"] > 0.5
    ds = hidden_dataset("periodic_disturbance", 2)
    base = fit_base(prepare(ds.t, ds.u, ds.y))
    peaks = spectrum_peaks(ds.t, base.residual)
    assert peaks and peaks[0]["f_hz"] == pytest.approx(ds.params["f_hz"], rel=5e-3)
    rng = np.random.default_rng(3)
    assert spectrum_peaks(np.arange(8000) * 1e-3, rng.standard_normal(8000)) == []


def test_parameter_uncertainty_reported():
    ds = hidden_dataset(None, 4)
    unc = diagnose((ds.t, ds.u, ds.y)).residual_analysis["parameter_uncertainty"]
    for k in ("alpha", "a1", "a2", "b"):
        assert 0 < unc[k]["std"] < math.inf
        assert abs(unc[k]["value"] - getattr(ds.model, k)) < 8 * unc[k]["std"] + 1e-3 * abs(getattr(ds.model, k))


def test_log_spaced_creep_with_a_second_power_law():
    """Non-uniform, log-spaced time, step before the first sample: second_creep found."""
    t = np.geomspace(1e-3, 1e3, 150)
    model = CreepModel(0.3, 1e-5, 1e-10, 1.0)
    y = simulate_with_effects(model, t, np.full(t.size, 2.0), {"second_creep": {"gain": 0.05, "alpha2": 0.9}},
                              u_pre=0.0, t_pre=0.0)
    y *= 1 + 0.002 * np.random.default_rng(1).standard_normal(t.size)
    d = diagnose((t, np.full(t.size, 2.0), y), u_pre=0.0, t_pre=0.0)
    assert d.verdict == "second_creep"
    fit = d.candidates[0].fit  # the two power laws may swap roles: the pair of exponents is what is identified
    pair = sorted([fit.model.alpha, fit.effect_params["second_creep"]["alpha2"]])
    assert pair == pytest.approx([0.3, 0.9], abs=0.05)
    assert "hysteresis" in d.skipped and "delay" in d.skipped


def test_loader_merges_repeated_times_and_reads_a_creep_log(tmp_path):
    p = tmp_path / "creep.csv"
    t = np.array([0.001, 0.001, 0.002, 0.004, 0.008] + list(np.geomspace(0.016, 10, 40)))
    y = np.sqrt(t)
    p.write_text("t,u,y\n" + "\n".join(f"{a},5,{b}" for a, b in zip(t, y)) + "\n")
    inp = load_for_diagnosis(p)
    assert len(inp.record) == t.size - 1
    assert inp.u_pre == 0.0 and inp.t_pre == 0.0
    assert any("merged" in n for n in inp.notes)


# --------------------------------------------------------------------------- CLI
def _cli(*args):
    return subprocess.run([sys.executable, "-m", "creep_online", *args], capture_output=True, text=True,
                          cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, timeout=300)


def test_cli_diagnose_fit_and_report(tmp_path):
    ds = hidden_dataset("periodic_disturbance", 1)
    csv = tmp_path / "hum.csv"
    save(ds, csv)
    r = _cli("diagnose", str(csv), "--json", "--report", str(tmp_path / "rep"))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["verdict"] == "periodic_disturbance"
    assert out["missing_effects"][0]["params"]["f_hz"] == pytest.approx(ds.params["f_hz"], rel=2e-3)
    for f in ("index.html", "overlay.png", "residuals.png", "spectrum.png"):
        assert (tmp_path / "rep" / f).stat().st_size > 0
    r = _cli("diagnose", str(csv))
    assert r.returncode == 0 and "verdict: periodic_disturbance" in r.stdout and "fit% after" in r.stdout
    r = _cli("fit", str(csv), "--effects", "periodic_disturbance,drift", "--json")
    assert r.returncode == 0, r.stderr
    fit = json.loads(r.stdout)
    assert fit["fit_percent"] > fit["fit_percent_before"]
    assert set(fit["effect_params"]) == {"periodic_disturbance", "drift"}


def test_cli_bad_input_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,u,y\n0,0,0\n1,nan,0\n")
    for args in (("diagnose", str(bad)), ("fit", str(bad), "--effects", "delay"),
                 ("fit", str(tmp_path / "missing.csv"), "--effects", "delay")):
        r = _cli(*args)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    ds = hidden_dataset(None, 1)
    ok = tmp_path / "ok.csv"
    save(ds, ok)
    r = _cli("fit", str(ok), "--effects", "backlash")
    assert r.returncode == 2 and "unknown effect" in r.stderr


def test_noise_free_simulated_data_has_nothing_missing():
    """Rounding-level residuals must not be 'explained' by an effect (BIC on 1e-15 noise)."""
    m = CreepModel.from_resonance(0.3, 5.0, 0.3, 2.5)
    t = np.arange(2000) * 5e-3
    u = np.where(t < 5.0, 1.0, 0.0)
    res = diagnose((t, u, simulate(m, t, u)))
    assert res.verdict == "none"
    assert any("nothing is missing" in w for w in res.warnings)


def _strong_leakage_record(seed: int) -> tuple:
    """Strong leakage (base residual 26x the noise) on a lightly damped, strongly creeping plant."""
    rng = np.random.default_rng(seed)
    t, u = staircase(6000, 1e-3, rng, hold_s=(0.2, 1.0))
    model = CreepModel.from_resonance(0.73, 53.0, 0.02, 1.13)
    y_eff = simulate_with_effects(model, t, u, {"leakage": {"tau_s": 16.0}})
    unexplained = fit_base(prepare(t, u, y_eff)).residual_rms
    noise = unexplained / math.sqrt(26.0 ** 2 - 1)
    return t, u, y_eff + noise * rng.standard_normal(t.size), model, noise


@pytest.mark.parametrize("seed", [5, 6])
def test_a_strong_effect_does_not_trap_the_extended_fit_in_the_base_fits_resonance(seed):
    """The base fit of a strong-leakage record lands on a wrong resonance (damping at its bound); the
    leakage fit warm-started from it stopped at ~3x the noise. A restart over (alpha, fn, zeta) with the
    effect's fitted parameters kept reaches the floor and the true resonance."""
    t, u, y, model, noise = _strong_leakage_record(seed)
    data = prepare(t, u, y)
    base = fit_base(data)
    fit = fit_extended(data, ("leakage",), base)
    assert fit.residual_rms < 1.1 * noise
    assert abs(fit.model.fn / model.fn - 1) < 0.02 and abs(fit.model.alpha - model.alpha) < 0.01
    assert abs(fit.effect_params["leakage"]["tau_s"] / 16.0 - 1) < 0.1


def _record_with(model: CreepModel, effect: str, params: dict, ratio: float, seed: int) -> tuple:
    """A staircase record of ``model`` with one effect, noise set so the base fit misses by ``ratio`` x the noise."""
    rng = np.random.default_rng(seed)
    t, u = staircase(6000, 1e-3, rng, hold_s=(0.2, 1.0))
    y_eff = simulate_with_effects(model, t, u, {effect: params})
    noise = fit_base(prepare(t, u, y_eff)).residual_rms / math.sqrt(ratio ** 2 - 1)
    return t, u, y_eff + noise * rng.standard_normal(t.size), noise


@pytest.mark.parametrize("seed", [1, 2])
def test_a_second_mode_between_nyquist_and_the_sampling_rate_is_fitted_there(seed):
    """A second mode at 790 Hz sampled at 1 kHz rings at its 210 Hz alias; with the mode's frequency capped
    at Nyquist the fit settled on the alias and stopped at 1.4-2.5x the noise (bench diagnose_bands,
    second_mode 3-10x seed 2: this plant and mode). Allowed up to fs, the fit still stopped at the alias
    on noise seed 2 (the image's basin is +-1.5 % wide, the grid's steps 40 %): the image start finds it."""
    model = CreepModel.from_resonance(0.0167, 187.3, 0.086, 0.535)
    mode = {"gain": 0.0568, "fn_hz": 791.5, "zeta": 0.0555}
    t, u, y, noise = _record_with(model, "second_mode", mode, 4.6, seed)
    data = prepare(t, u, y)
    fit = fit_extended(data, ("second_mode",), fit_base(data))
    assert fit.residual_rms < 1.1 * noise
    assert fit.effect_params["second_mode"]["fn_hz"] == pytest.approx(791.5, rel=0.01)


@pytest.mark.parametrize("band, seed, fn_hz", [("3-10x", 46, 779.2), ("3-10x", 88, 775.7), ("10-100x", 75, 60.1)])
def test_an_alias_fit_hands_over_to_the_mode_above_nyquist_through_a_polished_image(band, seed, fn_hz):
    """Bench diagnose_bands second_mode 3-10x seeds 46 and 88 (modes at 779 and 776 Hz, 1 kHz): the two best short
    polishes both sat in the alias' basin (humps at 206-221 Hz), and each one's image across Nyquist, started
    with the alias fit's damping, ranked below it unpolished: 1.55x and 1.34x the noise. Each finalist's cheapest
    image is short-polished too, and reaches the mode. The images compete for the final polish apart: 10-100x
    seed 75's mode at 60 Hz had its polished image (940 Hz, the same sampled poles) crowd it out: 1.51x."""
    from bench import bench_diagnose_bands as bench
    rec = bench.make_record("second_mode", bench.BANDS[band], seed)
    data = prepare(rec["t"], rec["u"], rec["y"])
    fit = fit_extended(data, ("second_mode",), fit_base(data))
    assert fit.residual_rms < 1.05 * rec["noise"]
    assert fit.effect_params["second_mode"]["fn_hz"] == pytest.approx(fn_hz, rel=0.01)


def test_a_strong_second_creep_is_not_left_on_the_wrong_creep_path():
    """A strong second creep (base residual ~90x the noise; bench diagnose_bands second_creep 10-100x seed 0:
    this plant and path): the fit had put the resonance on the alpha2 path (exponents exchanged, fn at its
    bound) and stopped at 10.8x the noise; the restart also searches with the two exponents exchanged."""
    model = CreepModel.from_resonance(0.7826, 43.79, 0.0274, -1.812)
    t, u, y, noise = _record_with(model, "second_creep", {"gain": -0.844, "alpha2": 0.3998}, 92.0, 0)
    d = diagnose((t, u, y), candidates=("second_creep", "second_mode", "delay"), combine=False)
    assert d.verdict == "second_creep"
    fit = d.candidates[0].fit
    assert fit.residual_rms < 1.1 * noise
    assert abs(fit.model.alpha - 0.7826) < 0.01 and abs(fit.effect_params["second_creep"]["alpha2"] - 0.3998) < 0.01
    assert fit.model.fn == pytest.approx(43.79, rel=0.01)


def test_the_exchanged_creep_exponents_are_polished_even_when_the_grid_around_the_fit_ranks_first():
    """bench diagnose_bands second_creep 10-100x seed 95 (the bench's own record; this plant and path on the
    tests' staircases does not reproduce it): the second-creep fit put the resonance on the alpha2 path
    (alpha 0.19, alpha2 0.59; true 0.61 and 0.26) at 22.6x the noise. The restart ranked the exchanged starts
    with the grid around that fit, which always costs less, and polished only the two cheapest; the best
    exchanged start is now polished too."""
    from bench import bench_diagnose_bands as bench
    rec = bench.make_record("second_creep", bench.BANDS["10-100x"], 95)
    d = diagnose((rec["t"], rec["u"], rec["y"]), candidates=("second_creep",), combine=False)
    fit = d.candidates[0].fit
    assert d.base.residual_rms > 70 * rec["noise"]
    assert fit.residual_rms < 1.1 * rec["noise"]
    assert abs(fit.model.alpha - rec["plant"]["alpha"]) < 0.01
    assert abs(fit.effect_params["second_creep"]["alpha2"] - 0.2638) < 0.01
    assert fit.model.fn == pytest.approx(rec["plant"]["fn"], rel=0.02)


@pytest.mark.parametrize("seed", [2, 3])
def test_a_base_fit_on_its_bounds_restarts_the_extended_fit(seed):
    """Strong leakage on a creeping, well-damped plant (bench diagnose_bands leakage 10-100x seed 23: this plant
    and tau): the base fit cancels creep and high-pass with alpha at 0.001 and zeta at 20 (both bounds); the
    leakage fit warm-started there explained nothing (23x the noise) and the verdict was hysteresis (here:
    19-23x on noise seeds 2-5)."""
    model = CreepModel.from_resonance(0.517, 5.142, 0.615, 0.758)
    t, u, y, noise = _record_with(model, "leakage", {"tau_s": 3.164}, 23.0, seed)
    data = prepare(t, u, y)
    base = fit_base(data)
    assert base.model.alpha < 0.002 and base.model.zeta > 19.0      # the distorted base this test is about
    fit = fit_extended(data, ("leakage",), base)
    assert fit.residual_rms < 1.1 * noise
    assert abs(fit.model.alpha - 0.517) < 0.01 and fit.effect_params["leakage"]["tau_s"] == pytest.approx(3.164, rel=0.05)


@pytest.mark.parametrize("seed, pair, params", [
    (13, ("nonlinear_gain", "second_creep"),
     {"second_creep": {"gain": -0.3, "alpha2": 0.55}, "nonlinear_gain": {"k2": 0.03, "k3": -0.002}}),
    (12, ("second_mode", "hysteresis"), {"second_mode": {"gain": 0.02, "fn_hz": 160.0, "zeta": 0.04}}),
])
def test_a_parallel_path_beside_an_input_effect_sees_the_transformed_input(seed, pair, params):
    """The forward model feeds every path the transformed input: the fit does too (``Design.coupled``), so the
    pair reaches the noise floor and the fitted model simulates to its own output. (Fitted on the plain input,
    a hysteresis + second creep pair stopped at 1.5-3x the noise from the true parameters and simulated to
    ~500x the noise off its own fit: bench pairs 10-100x.)"""
    rng = np.random.default_rng(seed)
    t, u = staircase(6000, 1e-3, rng)
    model = CreepModel.from_resonance(0.2, 45.0, 0.15, 1.1)
    if "hysteresis" in pair:
        params["hysteresis"] = get_effect("hysteresis").example_params(model, t, u, None, rng)
    y0 = simulate_with_effects(model, t, u, params)
    noise = 2e-3 * np.ptp(y0)
    data = prepare(t, u, y0 + noise * rng.standard_normal(t.size))
    base = fit_base(data)
    fit = fit_extended(data, pair, base)
    assert base.residual_rms > 4 * noise and fit.residual_rms < 1.05 * noise
    assert np.max(np.abs(fit.simulate(t, u) - fit.y_hat)) < 1e-9 * np.ptp(y0)
    if "nonlinear_gain" in pair:             # no threshold grid between the truth and the fit: the values return
        for name, truth in params.items():
            for key, value in truth.items():
                assert fit.effect_params[name][key] == pytest.approx(value, rel=0.03), (name, key)
