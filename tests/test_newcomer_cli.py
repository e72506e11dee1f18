"""The small things a newcomer meets first: --version, errors as JSON with --json, CSV files as they come
(semicolons, tabs, decimal commas, units in the header, other column names), time in milliseconds."""
from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys

import numpy as np
import pytest

from creep_online import CreepModel, DataError, simulate
from creep_online.cli import main
from creep_online.io.csvfile import load_csv, load_record, sniff_delimiter, split_name


def test_version():
    proc = subprocess.run([sys.executable, "-m", "creep_online", "--version"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip().startswith("creep-online ")
    from importlib.metadata import version
    assert proc.stdout.split()[1] == version("creep_online")


@pytest.mark.parametrize("argv, kind", [
    (["identify", "/nonexistent/x.csv"], "DataError"),
    (["compare", "/nonexistent/m.json", "/nonexistent/x.csv"], "DataError"),
    (["identify", "x.csv", "--no-such-flag"], "UsageError"),
    (["simulate", "--params", "alpha=2,a1=1,a2=1", "--input", "/nonexistent/in.csv", "-o", "o.csv"], "ModelError"),
])
def test_with_json_an_error_is_one_json_object_on_stderr(argv, kind):
    proc = subprocess.run([sys.executable, "-m", "creep_online", *argv, "--json"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    err = json.loads(lines[0])
    assert err["type"] == kind and err["exit_code"] == 2 and err["command"] == argv[0] and err["error"]


def test_without_json_an_error_stays_one_line_of_text(capsys):
    assert main(["identify", "/nonexistent/x.csv"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("creep-online identify: error: ") and len(err.strip().splitlines()) == 1


ROWS = [(k * 1e-3, 0.0 if k < 30 else 1.0, 0.01 * k) for k in range(200)]


def _write(path, header: str, sep: str, decimal: str = ".") -> None:
    body = "".join(sep.join(f"{v:.6g}".replace(".", decimal) for v in row) + "\n" for row in ROWS)
    path.write_text(header + "\n" + body)


@pytest.mark.parametrize("header, sep, decimal", [
    ("t,u,y", ",", "."), ("t;u;y", ";", "."), ("t;u;y", ";", ","), ("t\tu\ty", "\t", "."),
    ("t [s],u [V],y [um]", ",", "."), ("time (s);input (V);output (um)", ";", ","), ("T / s\tU / V\tY / um", "\t", "."),
])
def test_delimiters_decimal_commas_aliases_and_units(tmp_path, header, sep, decimal):
    path = tmp_path / "rec.csv"
    _write(path, header, sep, decimal)
    rec = load_csv(path)
    np.testing.assert_allclose(rec.t, [r[0] for r in ROWS])
    np.testing.assert_allclose(rec.y, [r[2] for r in ROWS])
    if "[" in header or "(" in header or "/" in header:
        assert rec.units == {"t": "s", "u": "V", "y": "um"}


def test_time_in_milliseconds_named_in_the_header_is_converted(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("t [ms],u,y\n" + "".join(f"{k * 0.1:.6g},{1 if k > 5 else 0},{k}\n" for k in range(50)))
    rec = load_csv(path)
    assert rec.t[1] == pytest.approx(1e-4) and rec.units == {"t": "s"}
    path.write_text("t [weeks],u,y\n" + "".join(f"{k},{1 if k > 5 else 0},{k}\n" for k in range(50)))
    with pytest.raises(DataError, match="time unit 'weeks'"):
        load_csv(path)


def test_other_column_names_by_flag(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("zeit;spannung [V];weg [um]\n" + "".join(f"{k * 1e-3};{1 if k > 5 else 0};{k}\n"
                                                             for k in range(50)))
    with pytest.raises(DataError) as err:
        load_csv(path)
    msg = str(err.value)
    assert "missing column(s) t,u,y" in msg and "semicolon-separated" in msg and "--t-column" in msg
    rec = load_record(path, "spannung", "weg", t_column="zeit")
    assert len(rec) == 50 and rec.units == {"u": "V", "y": "um"}
    m = CreepModel.from_resonance(0.2, 40.0, 0.1, 1.0)
    t = np.arange(3000) * 1e-3
    u = np.where(t > 0.1, 1.0, 0.0)
    y = simulate(m, t, u) + 1e-4 * np.random.default_rng(1).standard_normal(t.size)
    path.write_text("zeit;spannung [V];weg [um]\n" + "".join(f"{a!r};{b!r};{c!r}\n" for a, b, c in
                                                             zip(t.tolist(), u.tolist(), y.tolist())))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["identify", str(path), "--t-column", "zeit", "--u-column", "spannung", "--y-column", "weg",
                     "--json", "-o", str(tmp_path / "m.json")]) == 0
    assert json.loads(out.getvalue())["fn_hz"] == pytest.approx(40.0, rel=0.01)
    assert json.loads((tmp_path / "m.json").read_text())["units"] == {"u": "V", "y": "um"}


def test_sniffing_and_header_names():
    assert sniff_delimiter("t,u,y") == "," and sniff_delimiter("t;u;y") == ";" and sniff_delimiter("t\tu\ty") == "\t"
    assert sniff_delimiter("t") == ","
    assert split_name("t [ms]") == ("t", "ms") and split_name("Y (um)") == ("y", "um")
    assert split_name("u / V") == ("u", "V") and split_name("time") == ("time", "")


def _ms_record(path, header: str) -> None:
    """A 10 kHz record (resonance 490 Hz) whose time column is written in milliseconds."""
    m = CreepModel.from_resonance(0.1, 490.0, 0.1, 1.0)
    t = np.arange(6000) * 1e-4
    u = np.where(t > 0.02, 1.0, 0.0) - np.where(t > 0.3, 0.5, 0.0)
    y = simulate(m, t, u) + 1e-4 * np.random.default_rng(0).standard_normal(t.size)
    path.write_text(header + "\n" + "".join(f"{a * 1e3:.6g},{b:g},{c!r}\n" for a, b, c in zip(t, u, y.tolist())))


def test_time_that_looks_like_milliseconds_is_warned_about(tmp_path):
    path = tmp_path / "ms.csv"
    _ms_record(path, "t,u,y")
    proc = subprocess.run([sys.executable, "-m", "creep_online", "identify", str(path), "--json"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["fn_hz"] < 1.0
    assert "milliseconds" in proc.stderr and "t [ms]" in proc.stderr
    _ms_record(path, "t [ms],u,y")
    proc = subprocess.run([sys.executable, "-m", "creep_online", "identify", str(path), "--json"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "milliseconds" not in proc.stderr
    assert json.loads(proc.stdout)["fn_hz"] == pytest.approx(490.0, rel=0.01)
