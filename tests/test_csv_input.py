"""CSV input: every malformed file gives one line naming file and problem (docs/reliability.md)."""
import gzip
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from creep_online import DataError
from creep_online.io import load_csv, save_csv

GOOD = "t,u,y\n" + "".join(f"{k / 100:g},{1 if k else 0},{k / 10:g}\n" for k in range(50))
ROW = "\n0.3,1,3\n"  # data row k = 30, on line 32


def write(tmp_path, text, name="data.csv"):
    p = tmp_path / name
    p.write_text(text) if isinstance(text, str) else p.write_bytes(text)
    return p


CASES = {
    "nan": (GOOD.replace(ROW, "\n0.3,1,nan\n"), "line 32, column y"),
    "inf": (GOOD.replace(ROW, "\n0.3,inf,3\n"), "line 32, column u"),
    "missing_column": (GOOD.replace("t,u,y", "t,u,z"), "missing column(s) y"),
    "garbage": (GOOD.replace(ROW, "\n0.3,1,abc\n"), "not a number: 'abc'"),
    "short_row": (GOOD.replace(ROW, "\n0.3,1\n"), "line 32 has 2 field(s)"),
    "non_increasing": (GOOD.replace(ROW, "\n0.28,1,3\n"), "not strictly increasing at data row 31"),
    "duplicate_time": (GOOD.replace(ROW, "\n0.29,1,3\n"), "not strictly increasing"),
    "empty": ("", "empty file"),
    "header_only": ("t,u,y\n", "no data rows"),
    "too_short": ("t,u,y\n0,1,0\n0.1,1,1\n", "too few samples"),
    "no_excitation": (GOOD.replace(",1,", ",0,"), "no excitation"),
    "binary": (b"\x89PNG\r\n\x1a\n\xff\xfe", "not a text file"),
    "gzip_cut_short": (gzip.compress(GOOD.encode())[:40], "a gzip file that cannot be decompressed"),
    "gzip_of_binary": (gzip.compress(b"\xff\xfe\x00garbage"), "not a text file"),
}


@pytest.mark.parametrize("name", CASES)
def test_bad_file_gives_one_line_naming_file_and_problem(tmp_path, name):
    text, needle = CASES[name]
    path = write(tmp_path, text)
    with pytest.raises(DataError) as err:
        load_csv(path)
    msg = str(err.value)
    assert str(path) in msg and needle in msg and "\n" not in msg


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        load_csv(tmp_path / "absent.csv")
    with pytest.raises(DataError, match="is a directory"):
        load_csv(tmp_path)


def test_extra_columns_any_order_and_bom_are_accepted(tmp_path):
    text = "\ufeffy, note ,t,u\n" + "".join(f"{0.1 * k},x{k},{k * 0.01},1\n" for k in range(30))
    rec = load_csv(write(tmp_path, text))
    assert len(rec) == 30 and rec.t[-1] == pytest.approx(0.29) and rec.y[3] == pytest.approx(0.3)


def test_a_gzipped_csv_reads_as_the_csv_it_holds_within_the_input_bound(tmp_path, monkeypatch):
    """``x.csv.gz`` is read like ``x.csv`` (identify and stream share the reader); its decompressed size is bounded
    like any input, so a small file that inflates to gigabytes is refused, not read."""
    plain = load_csv(write(tmp_path, GOOD))
    packed = load_csv(write(tmp_path, gzip.compress(GOOD.encode()), "data.csv.gz"))
    for column in ("t", "u", "y"):
        np.testing.assert_array_equal(getattr(plain, column), getattr(packed, column))
    monkeypatch.setenv("CREEP_ONLINE_MAX_INPUT_BYTES", "5000")
    bomb = write(tmp_path, gzip.compress(GOOD.encode() + b"0,0,0\n" * 100_000), "bomb.csv.gz")
    assert bomb.stat().st_size < 5000
    with pytest.raises(DataError, match="decompresses to more than the 5000 bytes"):
        load_csv(bomb)


def test_round_trip_keeps_full_precision(tmp_path):
    t = np.arange(40) * 1e-3
    u = np.ones(40) / 3
    y = np.sqrt(t + 0.1) * np.pi
    save_csv(tmp_path / "r.csv", t, u, y)
    rec = load_csv(tmp_path / "r.csv")
    assert np.array_equal(rec.t, t) and np.array_equal(rec.u, u) and np.array_equal(rec.y, y)


@pytest.mark.parametrize("name", ["nan", "garbage", "empty", "no_excitation", "missing_column"])
def test_cli_exit_code_2_and_no_traceback(tmp_path, name):
    path = write(tmp_path, CASES[name][0])
    proc = subprocess.run([sys.executable, "-m", "creep_online", "identify", str(path), "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr and str(path) in lines[0]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=400) | st.text(alphabet="tuy,.-+e0123456789nai\n \t\"", max_size=400))
def test_fuzz_loader_raises_only_data_errors(tmp_path, blob):
    path = write(tmp_path, blob, "fuzz.csv")
    try:
        rec = load_csv(path)
    except DataError as exc:
        assert "\n" not in str(exc)
        return
    # anything accepted is clean
    assert len(rec) >= 20 and np.all(np.isfinite(rec.t)) and np.all(np.diff(rec.t) > 0)
