"""Saved models and compare: every fit's own fit percent comes back through compare, in Python and on the command line.

The records are the bench's (bench/bench_model_compare.py): random plants, fixed seeds, every record class a
user makes (from rest, a plain step at the first sample, a short lead-in, taken in operation with steps or a
dense input, dense from rest, jittered time stamps) and each catalogue effect hidden in the plant.
"""
from __future__ import annotations

import contextlib
import io
import json
import warnings

import numpy as np
import pytest

from creep_online import CreepModel, DataError, FittedModel, compare, identify, load_model, save_model, simulate
from creep_online.cli import main
from creep_online.diagnostics.extended import fit_extended, prepare
from creep_online.effects import EFFECTS, simulate_with_effects
from creep_online.io import save_csv
from creep_online.io.safe_files import REPORT_MARKER

from bench import bench_model_compare as BENCH
TOL = BENCH.TOLERANCE


@pytest.fixture(scope="module", autouse=True)
def quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _cli_json(argv) -> dict:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*map(str, argv), "--json"]) == 0
    return json.loads(buf.getvalue())


@pytest.mark.parametrize("kind", BENCH.PLAIN_CLASSES + tuple(f"effect:{e}" for e in EFFECTS))
def test_identify_and_fit_reproduce_their_fit_percent(kind, tmp_path):
    case = BENCH.run_case(kind, seed=1, cli=False)
    for path in ("identify", "fit"):
        assert abs(case[path]["compare"] - case[path]["fit"]) <= TOL, (path, case[path])
        assert abs(case[path]["file"] - case[path]["fit"]) <= TOL, (path, case[path])
        assert case[path]["simulate"] < 1e-4, (path, case[path])      # the fitted curve again, up to round-off


@pytest.mark.parametrize("kind", ["operation_steps", "effect:delay"])
def test_the_command_line_reproduces_its_fit_percent(kind, tmp_path):
    t, u, y, effect = BENCH.make_record(kind, 2)
    cli = BENCH._cli_case(t, u, y, effect, tmp_path)
    for path in ("identify", "fit"):
        assert abs(cli[path]["compare"] - cli[path]["fit"]) <= TOL, (path, cli)


def _in_operation(seed: int = 0):
    """A record cut out of operation: steps before it, the plant moving at its first sample."""
    rng = np.random.default_rng(seed)
    m = CreepModel.from_resonance(0.2, 40.0, 0.1, 1.5)
    t = np.arange(9000) * 1e-3
    u = np.zeros(t.size)
    for k in range(0, t.size, 700):
        u[k + 50:] = rng.uniform(-1, 1)
    y = simulate(m, t, u) + 0.002 * rng.standard_normal(t.size) + 0.3
    return m, t[3000:] - t[3000], u[3000:], y[3000:]


def test_result_simulate_includes_the_initial_state_terms():
    _, t, u, y = _in_operation()
    res = identify(t, u, y)
    assert res.initial_response is not None
    np.testing.assert_allclose(res.simulate(t, u), res.y_hat, rtol=0, atol=1e-10 * np.ptp(y))
    np.testing.assert_allclose(res.simulate(t + 7.0, u), res.y_hat, rtol=0, atol=1e-10 * np.ptp(y))  # from t[0]
    naive = simulate(res.model, t, u - res.input_offset) + res.offset     # what a user had before: far off
    assert compare(res, (t, u, y)).fit_percent - res.fit_percent == pytest.approx(0.0, abs=1e-9)
    assert np.linalg.norm(naive - y) > 10 * np.linalg.norm(res.y_hat - y)
    zero = res.simulate(t, u, initial="zero")
    np.testing.assert_allclose(zero, simulate(res.model, t, u - res.input_offset) + res.offset, atol=1e-12)


def test_the_free_response_off_the_grid_agrees_with_the_grid():
    _, t, u, y = _in_operation()
    free = identify(t, u, y).initial_response
    tau = t[:500]
    off_grid = free(tau + 0.25 * (tau[1] - tau[0]))             # not a multiple of the step: evaluated at times
    on_grid = np.interp(tau + 0.25 * (tau[1] - tau[0]), tau, free(tau))
    assert np.max(np.abs(off_grid - on_grid)) < 0.02 * np.ptp(free(tau))


def test_extended_fit_simulates_the_time_vector_fit_accepted():
    rng = np.random.default_rng(3)
    m = CreepModel.from_resonance(0.3, 30.0, 0.1, 1.0)
    t = np.arange(6000) * 1e-3
    u = np.where(t > 0.1, 1.0, 0.0) + np.where(t > 3.0, -0.5, 0.0)
    y = simulate_with_effects(m, t, u, {"drift": {"rate": 0.02, "offset": 0.0}}) + 1e-3 * rng.standard_normal(t.size)
    jittered = t + rng.uniform(-1e-8, 1e-8, t.size)
    fit = fit_extended(prepare(jittered, u, y), ("drift",))
    np.testing.assert_allclose(fit.simulate(jittered, u), fit.y_hat, rtol=0, atol=1e-12 * np.ptp(y))
    assert compare(fit, (jittered, u, y)).fit_percent == pytest.approx(fit.fit_percent, abs=1e-9)


def test_a_model_predicts_another_record_of_the_same_plant():
    m, t, u, y = _in_operation(0)
    res = identify(t, u, y)
    _, t2, u2, y2 = _in_operation(5)                            # other steps, other noise
    other = compare(res, (t2, u2, y2))
    assert other.fit_percent > 99.0 and other.initial["free_response_terms"] > 0
    rest = compare(res, (t2, u2, y2), initial="zero")           # from rest it misses the past steps
    assert rest.fit_percent < other.fit_percent - 5.0 and rest.initial["free_response_terms"] == 0


def test_save_and_load_keep_everything(tmp_path):
    base = CreepModel.from_resonance(0.2, 50.0, 0.1, -2.0)
    fm = FittedModel(base.with_effects(delay={"delay_s": 2e-3}, drift={"rate": 0.1, "offset": 0.0}),
                     input_offset=None, initial_state="reading", units={"t": "s", "u": "V", "y": "um"},
                     fitted={"fit_percent": 97.5})
    path = save_model(fm, tmp_path / "m.json", file="rec.csv")
    loaded = load_model(path)
    assert loaded.base == base and loaded.effects == fm.effects and loaded.input_offset is None
    assert loaded.units == fm.units and loaded.fitted["fit_percent"] == 97.5 and loaded.fitted["file"] == "rec.csv"
    doc = json.loads(path.read_text())
    assert doc["schema"] == "creep_online.model" and doc["schema_version"] == 1 and doc["creep_online_version"]
    t = np.arange(2000) * 1e-3
    u = np.where(t > 0.2, 1.0, 0.0)
    np.testing.assert_array_equal(loaded.simulate(t, u), fm.simulate(t, u))


def _document(**changes) -> dict:
    doc = {"schema": "creep_online.model", "schema_version": 1, "model": {"alpha": 0.2, "a1": 1e-3, "a2": 1e-5, "b": 1.0},
           "effects": {}, "offset": 0.0, "input_offset": 0.0, "initial_state": "free_response"}
    for key, value in changes.items():
        if value is None:
            doc.pop(key)
        else:
            doc[key] = value
    return doc


BAD = {
    "not_json": ("{alpha: 1", "not JSON"),
    "other_schema": (_document(schema="something.else"), "not a creep_online model file"),
    "newer": (_document(schema_version=2), "newer than this creep_online reads"),
    "no_model": (_document(model=None), "missing field model"),
    "bad_alpha": (_document(model={"alpha": 1.5, "a1": 1e-3, "a2": 1e-5, "b": 1.0}), "alpha"),
    "text_number": (_document(offset="0.1"), "offset must be a finite number"),
    "unknown_effect": (_document(effects={"warp": {}}), "unknown effect"),
    "bad_effect_params": (_document(effects={"delay": {"delay": 1}}), "effects.delay"),
    "no_input_offset": (_document(input_offset=None), "input_offset"),
    "bad_method": (_document(initial_state="guess"), "initial_state"),
    "a_list": ([1, 2, 3], "not a creep_online model file"),
}


@pytest.mark.parametrize("name", BAD)
def test_a_bad_model_file_is_one_line_and_exit_2(name, tmp_path, capsys):
    content, needle = BAD[name]
    path = tmp_path / "m.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(DataError) as err:
        load_model(path)
    assert needle in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)
    data = tmp_path / "d.csv"
    save_csv(data, np.arange(100) * 1e-3, np.ones(100), np.linspace(0, 1, 100))
    assert main(["compare", str(path), str(data)]) == 2
    err_text = capsys.readouterr().err
    assert len(err_text.strip().splitlines()) == 1 and needle in err_text


def test_model_outputs_are_checked_before_the_work(tmp_path, capsys):
    data = tmp_path / "d.csv"
    save_csv(data, np.arange(100) * 1e-3, np.ones(100), np.linspace(0, 1, 100))
    assert main(["identify", str(data), "-o", str(tmp_path / "model.txt")]) == 2
    assert "ending in .json" in capsys.readouterr().err
    named_json = tmp_path / "d.json"                          # a CSV record under a .json name: never overwritten
    named_json.write_bytes(data.read_bytes())
    assert main(["fit", str(named_json), "--effects", "drift", "-o", str(named_json)]) == 2
    assert "refusing to overwrite the input" in capsys.readouterr().err
    assert named_json.read_bytes() == data.read_bytes()


def test_compare_command_and_report(tmp_path):
    _, t, u, y = _in_operation()
    data = tmp_path / "rec.csv"
    with open(data, "w") as fh:
        fh.write("time [ms];u [V];y [um]\n")
        for a, b, c in zip(t * 1e3, u, y):
            fh.write(f"{float(a)!r};{float(b)!r};{float(c)!r}\n")
    ident = _cli_json(["identify", data, "-o", tmp_path / "m.json"])
    model = load_model(tmp_path / "m.json")
    assert model.units == {"t": "s", "u": "V", "y": "um"}                  # from the header, time in seconds
    out = _cli_json(["compare", tmp_path / "m.json", data, "--report", tmp_path / "rep"])
    assert out["fit_percent"] == pytest.approx(ident["fit_percent"], abs=TOL)
    assert out["initial"]["free_response_terms"] > 0 and out["residual"]["white"] in (True, False)
    assert {p.name for p in (tmp_path / "rep").iterdir()} == {"report.html", "compare.png", "compare.json",
                                                              REPORT_MARKER}
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert main(["compare", str(tmp_path / "m.json"), str(data)]) == 0
    assert f"{ident['fit_percent']:.2f} %" in text.getvalue() and "um" in text.getvalue()


def test_simulate_reads_model_files_and_the_fits_json(tmp_path):
    rng = np.random.default_rng(4)
    m = CreepModel.from_resonance(0.25, 30.0, 0.15, 1.2)
    t = np.arange(5000) * 1e-3
    u = np.where(t > 0.2, 1.0, 0.0) - np.where(t > 2.5, 0.6, 0.0)
    y = simulate_with_effects(m, t, u, {"delay": {"delay_s": 4e-3}}) + 0.5 + 1e-3 * rng.standard_normal(t.size)
    data = tmp_path / "rec.csv"
    save_csv(data, t, u, y)
    (tmp_path / "in.csv").write_text("t,u\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), u.tolist())))
    fit = _cli_json(["fit", data, "--effects", "delay", "-o", tmp_path / "f.json"])
    _cli_json(["simulate", "--model", tmp_path / "f.json", "--input", tmp_path / "in.csv", "-o", tmp_path / "s.csv"])
    from creep_online.io import load_csv
    from creep_online.metrics import fit_percent
    simulated = load_csv(tmp_path / "s.csv")
    assert fit_percent(y, simulated.y) == pytest.approx(fit["fit_percent"], abs=TOL)   # effects and offset in
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    _cli_json(["simulate", "--params", tmp_path / "fit.json", "--input", tmp_path / "in.csv", "-o", tmp_path / "p.tsv"])
    assert (tmp_path / "p.tsv").read_text().startswith("t\tu\ty\n")
    ident = _cli_json(["identify", data])
    (tmp_path / "id.json").write_text(json.dumps(ident))
    out = _cli_json(["simulate", "--params", tmp_path / "id.json", "--input", tmp_path / "in.csv", "-o",
                     tmp_path / "i.parquet"])
    import pyarrow.parquet as pq
    table = pq.read_table(tmp_path / "i.parquet")
    assert table.column_names == ["t", "u", "y"] and out["offset"] == pytest.approx(ident["offset"])
    np.testing.assert_allclose(table.column("y").to_numpy(),
                               simulate(CreepModel(ident["alpha"], ident["a1"], ident["a2"], ident["b"]), t, u)
                               + ident["offset"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("suffix", [".xlsx", ".json", ".h5"])
def test_simulate_refuses_an_output_format_it_cannot_write(tmp_path, capsys, suffix):
    (tmp_path / "in.csv").write_text("t,u\n" + "".join(f"{k * 0.01},1\n" for k in range(30)))
    assert main(["simulate", "--params", "alpha=0.5,a1=0.1,a2=0.01", "--input", str(tmp_path / "in.csv"),
                 "-o", str(tmp_path / f"out{suffix}")]) == 2
    assert "unknown output format" in capsys.readouterr().err and not (tmp_path / f"out{suffix}").exists()


COMBINATIONS = [c.split(":", 1)[1] for c in BENCH.COMBINATIONS]


@pytest.mark.parametrize("combination", COMBINATIONS)
def test_a_combination_simulates_its_own_design(combination):
    """Every pair and triple of effects: the fitted model's forward simulation is the design's output, at any
    parameters (here the start of the fit), the input effects side by side as the fit estimates them."""
    from creep_online.diagnostics.extended import Design, _default_tail, _result, base_theta
    from creep_online.diagnostics.start import readings
    effects = tuple(combination.split("+"))
    t, u, y = BENCH.combination_record(effects, seed=0)
    data = prepare(t, u, y, u_pre=readings(u)[0][0])
    design = Design(data, effects)
    theta = np.clip(np.concatenate([base_theta(CreepModel.from_resonance(0.3, 40.0, 0.1, 1.0)),
                                    _default_tail(design)]), design.lo, design.hi)
    fit = _result(design, theta)
    assert np.max(np.abs(fit.simulate(t, u) - fit.y_hat)) <= 1e-9 * np.ptp(y)


def test_input_effects_add_their_terms_side_by_side():
    from creep_online.effects.forward import transformed_input
    from creep_online.effects.hysteresis import hysteresis_input
    u = np.array([0.0, 1.0, 2.0, 1.5, 0.5, 1.0])
    hyst = {"r": [0.2, 0.6], "w": [0.3, -0.1]}
    v, pre = transformed_input({"hysteresis": hyst, "nonlinear_gain": {"k2": 0.1, "k3": -0.02}}, u, 0.5)
    assert v == pytest.approx(hysteresis_input(u, hyst["r"], hyst["w"]) + 0.1 * u**2 - 0.02 * u**3, abs=1e-14)
    assert pre == pytest.approx(0.5 * 1.2 + 0.1 * 0.25 - 0.02 * 0.125, abs=1e-14)


@pytest.mark.parametrize("kind", ["effects:hysteresis+nonlinear_gain", "effects:hysteresis+periodic_disturbance",
                                  "effects:nonlinear_gain+second_mode+drift"])
def test_combinations_reproduce_their_fit_percent(kind):
    case = BENCH.run_case(kind, seed=0, cli=False)
    assert case["worst"] <= TOL, case
    assert case["fit"]["simulate"] < 1e-9, case["fit"]


@pytest.mark.slow
@pytest.mark.parametrize("kind", BENCH.COMBINATIONS)
def test_every_combination_reproduces_its_fit_percent(kind):
    case = BENCH.run_case(kind, seed=1, cli=False)
    assert case["worst"] <= TOL, case


@pytest.mark.slow
def test_the_micromanipulator_excerpt_round_trips_through_the_command_line(tmp_path):
    """The real record's first 10 s, fitted with hysteresis and nonlinear gain, saved and compared."""
    t, u, y, effects = BENCH.real_excerpt("real:micromanipulator", 0)
    data = tmp_path / "micro.csv"
    save_csv(data, t, u, y)
    fit = _cli_json(["fit", data, "--effects", effects, "-o", tmp_path / "micro.json"])
    assert abs(_cli_json(["compare", tmp_path / "micro.json", data])["fit_percent"] - fit["fit_percent"]) <= TOL
