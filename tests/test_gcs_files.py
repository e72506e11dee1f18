"""PI GCS data-recorder files: written by pipython's own writer, read by identify, diagnose and stream."""
from __future__ import annotations

import json
import subprocess
import sys
from collections import OrderedDict

import numpy as np
import pytest

pitools = pytest.importorskip("pipython.pitools", reason="pipython is an optional extra (creep_online[pi])")

from creep_online.cli import main  # noqa: E402
from creep_online.errors import DataError  # noqa: E402
from creep_online.io.csvfile import load_record, save_csv  # noqa: E402
from creep_online.io.gcsfile import is_gcs_file, load_gcs  # noqa: E402
from hil_sim import PlantConfig, generate  # noqa: E402
from hil_sim.plant import parse_params  # noqa: E402

VOLTAGE, POSITION = "Voltage of output channel 1", "Current Position of axis 1"


def random_plant(seed: int, rate: float = 2000.0, duration: float = 3.0):
    """A plant drawn over the issue's ranges (alpha 0.02-0.4, fn 100-800 Hz, zeta 0.03-0.3, b 0.5-5)."""
    rng = np.random.default_rng(seed)
    params = (f"alpha={rng.uniform(0.02, 0.4):.4f},fn={rng.uniform(100, 800):.1f},"
              f"zeta={rng.uniform(0.03, 0.3):.3f},b={rng.uniform(0.5, 5):.3f}")
    cfg = PlantConfig(parse_params(params), rate=rate, duration=duration, t_start=0.2, noise=1e-4, seed=seed,
                      schedule=("step", "staircase", "square")[seed % 3], period=1.0)
    return cfg.model, generate(cfg)


def write_gcs(path, rec, rate, names=(VOLTAGE, POSITION), columns=None):
    """The file exactly as pipython writes it (pipython.pitools.savegcsarray)."""
    header = OrderedDict([("VERSION", 1), ("TYPE", 1), ("SEPARATOR", 32), ("DIM", len(names)),
                          ("SAMPLE_TIME", 1.0 / rate), ("NDATA", rec.u.size)])
    header.update((f"NAME{i}", n) for i, n in enumerate(names))
    pitools.savegcsarray(str(path), header, columns or [rec.u.tolist(), rec.y.tolist()])
    return path


@pytest.mark.parametrize("seed", range(6))
def test_reader_returns_the_written_columns(tmp_path, seed):
    _, rec = random_plant(seed)
    # three columns in another order: output first, a distractor, input last; chosen by name
    path = write_gcs(tmp_path / "rec.dat", rec, 2000.0, names=(POSITION, "Position Error of axis 1", VOLTAGE),
                     columns=[rec.y.tolist(), (rec.u - rec.y).tolist(), rec.u.tolist()])
    assert is_gcs_file(path)
    got = load_record(path, u_column=VOLTAGE.upper(), y_column="NAME0")
    np.testing.assert_allclose(got.u, np.round(rec.u, 6), atol=5e-7)
    np.testing.assert_allclose(got.y, np.round(rec.y, 6), atol=5e-7)
    np.testing.assert_allclose(got.t, np.arange(rec.u.size) / 2000.0, rtol=1e-12, atol=1e-15)


def test_identify_and_stream_read_gcs_like_csv(tmp_path, capsys):
    """The same record as a GCS file and as a CSV gives the same identification (CSV is the reference)."""
    model, rec = random_plant(11)
    rounded_u, rounded_y = np.round(rec.u, 6), np.round(rec.y, 6)
    gcs = write_gcs(tmp_path / "rec.dat", rec, 2000.0)
    csv = tmp_path / "rec.csv"
    save_csv(csv, np.arange(rec.u.size) / 2000.0, rounded_u, rounded_y)
    out = {}
    for name, path in (("gcs", gcs), ("csv", csv)):
        assert main(["identify", str(path), "--json"]) == 0
        out[name] = json.loads(capsys.readouterr().out)
    for key in ("alpha", "a1", "a2", "b"):
        assert out["gcs"][key] == pytest.approx(out["csv"][key], rel=1e-9)
    assert out["gcs"]["alpha"] == pytest.approx(model.alpha, abs=0.01)
    assert main(["stream", "--source", f"csv:{gcs}", "--json", "--u-column", "NAME0",
                 "--y-column", POSITION]) == 0
    streamed = json.loads(capsys.readouterr().out)
    assert streamed["samples"] == rec.u.size


def test_diagnose_reads_gcs(tmp_path, capsys):
    _, rec = random_plant(3)
    path = write_gcs(tmp_path / "rec.dat", rec, 2000.0)
    assert main(["diagnose", str(path), "--json", "--effects", "drift"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["samples"] == rec.u.size and out["verdict"] == "none"


def test_csv_columns_by_name(tmp_path):
    _, rec = random_plant(4)
    path = tmp_path / "named.csv"
    rows = "\n".join(f"{k / 2000.0!r},{float(rec.y[k])!r},{float(rec.u[k])!r}" for k in range(rec.u.size))
    path.write_text("t,pos_um,volts\n" + rows + "\n")
    got = load_record(path, u_column="volts", y_column="POS_UM")
    np.testing.assert_array_equal(got.u, rec.u)
    np.testing.assert_array_equal(got.y, rec.y)
    with pytest.raises(DataError, match=r"missing column\(s\) u,y in header 't,pos_um,volts' \(need t,u,y\)"):
        load_record(path)


GOOD_HEADER = ("# TYPE = 1 \n# SEPARATOR = 32 \n# DIM = 2 \n# SAMPLE_TIME = 0.001 \n# NDATA = 40 \n"
               f"# NAME0 = {VOLTAGE} \n# NAME1 = {POSITION} \n# END_HEADER \n")
ROWS = "".join(f"{1.0 if k > 2 else 0.0:.6f} {k * 0.01:.6f} \n" for k in range(40))

BAD_FILES = {
    "no_end_header": (GOOD_HEADER.replace("# END_HEADER \n", "") + ROWS, "malformed GCS header: no '# END_HEADER'"),
    "no_sample_time": (GOOD_HEADER.replace("# SAMPLE_TIME = 0.001 \n", "") + ROWS, "no SAMPLE_TIME line"),
    "bad_sample_time": (GOOD_HEADER.replace("0.001", "fast") + ROWS, "SAMPLE_TIME = 'fast' is not a number"),
    "missing_name": (GOOD_HEADER.replace(f"# NAME1 = {POSITION} \n", "") + ROWS, "DIM = 2 but no NAME1 line"),
    "not_a_number": (GOOD_HEADER + ROWS.replace("0.100000", "0.1O0000"), "line 19: not a number: '0.1O0000'"),
    "short_row": (GOOD_HEADER + ROWS.replace("1.000000 0.100000", "1.000000"), "line 19 has 1 value(s), expected 2"),
    "nan": (GOOD_HEADER + ROWS.replace("0.100000", "nan"), "data row 11, output column"),
    "too_short": (GOOD_HEADER + "".join(ROWS.splitlines(True)[:10]), "too few samples"),
}


@pytest.mark.parametrize("case", BAD_FILES)
def test_bad_gcs_file_is_one_line(tmp_path, case):
    text, expected = BAD_FILES[case]
    path = tmp_path / f"{case}.dat"
    path.write_text(text)
    with pytest.raises(DataError) as info:
        load_gcs(path)
    message = str(info.value)
    assert expected in message and str(path) in message and "\n" not in message


def test_unknown_column_lists_the_columns(tmp_path, capsys):
    path = tmp_path / "rec.dat"
    path.write_text(GOOD_HEADER + ROWS)
    assert main(["identify", str(path), "--y-column", "sensor"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"creep-online identify: error: {path}: no output column named 'sensor' "
                   f"(columns: NAME0 = '{VOLTAGE}'; NAME1 = '{POSITION}')")


def test_missing_pipython_is_one_line(tmp_path):
    """With pipython unimportable (sys.modules blocks it), a GCS file and a pi: source each name the extra."""
    path = tmp_path / "rec.dat"
    path.write_text(GOOD_HEADER + ROWS)
    code = ("import sys; sys.modules['pipython'] = None; sys.modules['pipython.pitools'] = None; "
            "from creep_online.cli import main; "
            "codes = [main(['identify', sys.argv[1]]), main(['stream', '--source', 'pi:/dev/ttyUSB0'])]; "
            "print(codes)")
    r = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True)
    assert r.stdout.strip() == "[2, 2]"
    assert r.stderr.strip().splitlines() == [
        "creep-online identify: error: reading GCS data-recorder files needs pipython: pip install 'creep_online[pi]'",
        "creep-online stream: error: pi sources need pipython: pip install 'creep_online[pi]'"]


def test_a_saved_drr_answer_reads_back(tmp_path):
    """The controller's own qDRR answer saved as is (# REM and bare '#' lines, rows ending ' \\n')."""
    from hil_sim.pi_controller import Controller
    _, rec = random_plant(8, rate=5000.0, duration=1.0)
    ctl = Controller(rec, 5000.0, table_points=4000, fast=True, rtr=2)
    ctl.handle("DRT 0 4 0")
    answer = ctl.handle("DRR? 1 2500 1 2")
    assert answer.count(" \n") == answer.count("\n") - 1          # the GCS multi-line convention
    path = tmp_path / "answer.dat"
    path.write_text(answer)
    got = load_record(path)
    np.testing.assert_allclose(got.u, rec.u[0:5000:2], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.y, rec.y[0:5000:2], rtol=1e-9, atol=1e-12)
    assert got.h == pytest.approx(2 / 5000.0)


# ------------------------------------------------------------------ channels chosen by meaning, --dt
E712 = ("Target Position of axis1", "Control Voltage of Output Chan 1", "Current Position of axis1")


@pytest.mark.parametrize("seed", range(4))
def test_an_e712_recording_takes_voltage_in_and_position_out(tmp_path, seed):
    """Three channels, the target first (as an E-712 records them): the input is the voltage, not NAME0."""
    _, rec = random_plant(seed)
    target = 0.8 * rec.u + 0.01                 # a set point that is not what reaches the actuator
    path = write_gcs(tmp_path / "e712.dat", rec, 2000.0, names=E712,
                     columns=[target.tolist(), rec.u.tolist(), rec.y.tolist()])
    got = load_record(path)
    np.testing.assert_allclose(got.u, np.round(rec.u, 6), atol=5e-7)
    np.testing.assert_allclose(got.y, np.round(rec.y, 6), atol=5e-7)
    by_output = load_record(path, y_column="NAME2")           # one named, the other by meaning
    np.testing.assert_array_equal(by_output.u, got.u)


def test_identify_an_e712_file_as_with_the_columns_named(tmp_path, capsys):
    model, rec = random_plant(5)
    path = write_gcs(tmp_path / "e712.dat", rec, 2000.0, names=E712,
                     columns=[(0.5 * rec.u).tolist(), rec.u.tolist(), rec.y.tolist()])
    assert main(["identify", str(path), "--json"]) == 0
    default = json.loads(capsys.readouterr().out)
    assert main(["identify", str(path), "--json", "--u-column", E712[1], "--y-column", E712[2]]) == 0
    named = json.loads(capsys.readouterr().out)
    assert all(default[k] == named[k] for k in ("alpha", "a1", "a2", "b"))
    assert default["alpha"] == pytest.approx(model.alpha, abs=0.01) and default["b"] == pytest.approx(model.b, rel=0.02)


@pytest.mark.parametrize("names", [
    ("Control Voltage of Output Chan 1", "Current Position of axis1", "Control Voltage of Output Chan 2",
     "Current Position of axis2"),                                    # two axes: which pair?
    ("Target Position of axis1", "Position Error of axis1", "Current Position of axis1"),   # no input
])
def test_channels_without_a_single_meaning_are_refused_listing_them(tmp_path, capsys, names):
    _, rec = random_plant(1)
    path = write_gcs(tmp_path / "many.dat", rec, 2000.0, names=names, columns=[rec.u.tolist()] * len(names))
    assert main(["identify", str(path)]) == 2
    listing = "; ".join(f"NAME{i} = {n!r}" for i, n in enumerate(names))
    assert capsys.readouterr().err == (
        f"creep-online identify: error: {path}: {len(names)} channels and no single voltage/command input and "
        f"position/sensor output among their names: choose them with --u-column and --y-column ({listing})\n")


def test_a_file_without_sample_time_takes_dt(tmp_path, capsys):
    """pipython's savegcsarray(path, None, data) writes neither SAMPLE_TIME nor NAMEi lines."""
    model, rec = random_plant(7)
    path = tmp_path / "plain.dat"
    pitools.savegcsarray(str(path), None, [rec.u.tolist(), rec.y.tolist()])
    assert main(["identify", str(path)]) == 2
    assert capsys.readouterr().err == (f"creep-online identify: error: {path}: GCS header has no SAMPLE_TIME line; "
                                       "give the sample time with --dt SECONDS\n")
    got = load_gcs(path, dt=1 / 2000.0)
    np.testing.assert_allclose(got.t, np.arange(rec.u.size) / 2000.0, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got.y, np.round(rec.y, 6), atol=5e-7)
    assert main(["identify", str(path), "--dt", "0.0005", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["alpha"] == pytest.approx(model.alpha, abs=0.01) and out["b"] == pytest.approx(model.b, rel=0.02)
    assert main(["stream", "--source", f"csv:{path}", "--dt", "0.0005", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["dt"] == pytest.approx(0.0005)
    three = tmp_path / "three.dat"
    pitools.savegcsarray(str(three), None, [rec.u.tolist(), rec.u.tolist(), rec.y.tolist()])
    assert main(["diagnose", str(three), "--dt", "0.0005"]) == 2
    assert "(NAME0 = 'NAME0'; NAME1 = 'NAME1'; NAME2 = 'NAME2')" in capsys.readouterr().err
    assert main(["fit", str(three), "--dt", "0.0005", "--u-column", "NAME1", "--y-column", "NAME2",
                 "--effects", "hysteresis", "--json"]) == 0


def test_dt_that_contradicts_the_file_is_refused(tmp_path, capsys):
    _, rec = random_plant(2)
    gcs = write_gcs(tmp_path / "rec.dat", rec, 2000.0)
    assert main(["identify", str(gcs), "--dt", "0.001"]) == 2
    assert capsys.readouterr().err == f"creep-online identify: error: --dt 0.001 contradicts SAMPLE_TIME = 0.0005 of {gcs}; drop --dt\n"
    csv = tmp_path / "rec.csv"
    save_csv(csv, rec.t, rec.u, rec.y)
    assert main(["diagnose", str(csv), "--dt", "0.001"]) == 2
    assert "--dt 0.001 contradicts the time column of" in capsys.readouterr().err
    assert main(["identify", str(csv), "--dt", "0.0005", "--json"]) == 0
