"""Adversarial inputs: no traceback, one-line errors with exit 2, inputs never destroyed.

Categories (docs/reliability.md, "Measured", has the counts of the sweep over
all of them): files the CSV reader is given, numbers out of range, invalid
settings, outputs that would destroy data, report folders, frame encoders,
streams that end (link lost, Ctrl-C, corrupt CAN log), and below: source
options, spellings of a spec, pipes and `-`, names that would reach a terminal
raw. Signals, FIFOs, checkpoints, the API's number contract, CAN logs of every
format and a sample of the sweep itself (``bench/bench_reliability.py``) are
in test_reliability.py. Real files, real subprocesses and real
pseudo-terminals; the frame parsers themselves are fuzzed in
test_fuzz_frames.py, the read-only install in test_readonly_install.py.
"""
from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
import tty
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from creep_online import CreepModel, CreepOnlineError, identify, simulate
from creep_online.cli import main
from creep_online.errors import DataError, DataWarning
from creep_online.io import load_csv, save_csv
from creep_online.io.frames import AsciiParser, encode_ascii

REPO = Path(__file__).resolve().parents[1]
FEW = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                     HealthCheck.function_scoped_fixture])
PARAMS = "alpha=0.3,a1=0.01,a2=1e-4,b=2"


def _record(n: int = 1500, h: float = 1e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A small step experiment with a little noise."""
    t = np.arange(n) * h
    u = np.where(t > 0.05, 1.0, 0.0)
    y = simulate(CreepModel(0.3, 0.01, 1e-4, 2.0), t, u) + 1e-3 * np.random.default_rng(1).standard_normal(n)
    return t, u, y


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("adv")
    t, u, y = _record()
    out = {}
    for name, (tt, uu, yy) in {"good": (t, u, y), "y_huge": (t, u, y * 1e300), "t_huge": (t * 1e300, u, y),
                               "u_huge": (t, u * 1e300, y), "y_const": (t, u, 0 * y + 1.0),
                               "y_tiny": (t, u, y * 1e-300)}.items():
        save_csv(d / f"{name}.csv", tt, uu, yy)
        out[name] = d / f"{name}.csv"
    (d / "dup.csv").write_text("t,u,y,y\n" + "".join(f"{k * 1e-3},{float(k > 5)},{k},{k}\n" for k in range(50)))
    out["dup"] = d / "dup.csv"
    text = out["good"].read_text()
    (d / "cut.csv").write_text(text[:text.rindex(",")])          # last row cut mid-row, no end-of-line
    out["cut"] = d / "cut.csv"
    (d / "longline.csv").write_text("t,u,y\n" + "1" * 200_000 + "\n")
    out["longline"] = d / "longline.csv"
    out["dir"] = d
    return out


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _assert_one_line_error(code: int, err: str, *words: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip() and ": warning: " not in ln
             and not ln.startswith("creep-online: ")]     # (a stream's events: a source says what it saw)
    assert len(lines) == 1 and ": error: " in lines[0], err
    for w in words:
        assert w in lines[0], (w, lines[0])


# ------------------------------------------------------------------ files
@pytest.mark.parametrize("name, words", [
    ("/dev/zero", ["character device"]), ("/dev/null", ["character device"]), ("dir", ["directory"]),
    ("missing", ["no such file"]), ("dup", ["appears 2 times"]), ("cut", ["incomplete"]),
    ("longline", ["longer than"]),
])
@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_unusable_files_are_one_line_errors(files, capsys, command, name, words):
    path = files.get(name, name if name.startswith("/") else files["dir"] / "missing.csv")
    code, _, err = _cli([command, path], capsys)
    _assert_one_line_error(code, err, *words)


def test_last_line_without_end_of_line_is_reported(tmp_path):
    t, u, y = _record(200)
    save_csv(tmp_path / "a.csv", t, u, y)
    (tmp_path / "b.csv").write_text((tmp_path / "a.csv").read_text().rstrip("\n"))
    with pytest.warns(DataWarning, match="no end-of-line"):
        rec = load_csv(tmp_path / "b.csv")
    assert len(rec) == 200


@FEW
@given(st.binary(max_size=400))
def test_csv_reader_fuzz_raises_only_data_errors(tmp_path_factory, blob):
    path = tmp_path_factory.mktemp("fz") / "f.csv"
    path.write_bytes(b"t,u,y\n" + blob)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        try:
            rec = load_csv(path, min_samples=1)
        except DataError as exc:
            assert "\n" not in str(exc)
            return
    assert np.all(np.isfinite(rec.t)) and np.all(np.diff(rec.t) > 0)


@FEW
@given(st.lists(st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)), min_size=1, max_size=30))
def test_csv_rows_round_trip(tmp_path_factory, rows):
    path = tmp_path_factory.mktemp("rt") / "r.csv"
    t = np.arange(len(rows)) * 0.5
    u = np.array([r[0] for r in rows])
    y = np.array([r[1] for r in rows])
    save_csv(path, t, u, y)
    from creep_online.io.csvfile import read_columns
    cols = read_columns(path)
    assert np.array_equal(cols["u"], u) and np.array_equal(cols["y"], y)


# ------------------------------------------------------------------ numbers
@pytest.mark.parametrize("name, words", [("t_huge", ["time axis out of range"]), ("y_const", ["constant"])])
@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_out_of_range_records_are_refused_with_the_reason(files, capsys, command, name, words):
    code, _, err = _cli([command, files[name]], capsys)
    _assert_one_line_error(code, err, *words)


@pytest.mark.parametrize("name", ["y_huge", "u_huge", "y_tiny"])
def test_identify_rescales_extreme_amplitudes(files, name):
    ref = identify(*(load_csv(files["good"]).__dict__[k] for k in "tuy"))
    rec = load_csv(files[name])
    res = identify(rec.t, rec.u, rec.y)
    factor = {"y_huge": 1e300, "u_huge": 1e-300, "y_tiny": 1e-300}[name]
    assert res.model.alpha == pytest.approx(ref.model.alpha, rel=1e-6)
    assert res.model.b == pytest.approx(ref.model.b * factor, rel=1e-6)
    assert any("rescaled" in w for w in res.warnings)


@pytest.mark.parametrize("name", ["y_huge", "u_huge"])
def test_diagnose_refuses_extreme_amplitudes(files, capsys, name):
    code, _, err = _cli(["diagnose", files[name]], capsys)
    _assert_one_line_error(code, err, "rescale")


@pytest.mark.parametrize("flags, words", [
    (["--t-c", "-1"], ["--t-c"]), (["--t-c", "0"], ["--t-c"]), (["--t-c", "nan"], ["--t-c"]),
    (["--layer1-step", "0"], ["--layer1-step"]), (["--alpha0", "1.5"], ["--alpha0"]),
])
def test_identify_settings_are_checked(files, capsys, flags, words):
    code, _, err = _cli(["identify", files["good"], *flags], capsys)
    _assert_one_line_error(code, err, *words)


def test_api_errors_are_creep_online_errors(files):
    rec = load_csv(files["good"])
    for kw in ({"t_c": -1.0}, {"t_c": 0.0}, {"layer1_step": 0.0}, {"alpha0": 0.0}, {"resonance0": (1.0,)}):
        with pytest.raises(CreepOnlineError):
            identify(rec.t, rec.u, rec.y, **kw)
    for t, u, y in ((rec.t * 1e300, rec.u, rec.y), (rec.t, rec.u, rec.y * 0)):
        with pytest.raises(CreepOnlineError):
            identify(t, u, y)


# ------------------------------------------------------------------ outputs
def test_simulate_refuses_to_overwrite_its_input(files, capsys, tmp_path):
    m = tmp_path / "m.csv"
    m.write_bytes(files["good"].read_bytes())
    before = m.read_bytes()
    for out in (m, tmp_path / "." / "m.csv"):
        code, _, err = _cli(["simulate", "--params", PARAMS, "--input", m, "-o", out], capsys)
        _assert_one_line_error(code, err, "refusing to overwrite the input")
    os.link(m, tmp_path / "hard.csv")
    code, _, err = _cli(["simulate", "--params", PARAMS, "--input", m, "-o", tmp_path / "hard.csv"], capsys)
    _assert_one_line_error(code, err, "input")
    assert m.read_bytes() == before


@pytest.mark.parametrize("target, words", [("nodir/x.csv", ["does not exist"]), (".", ["directory"]),
                                           ("/proc/x.csv", ["x.csv"])])
def test_simulate_bad_output_paths(files, capsys, tmp_path, target, words):
    out = target if target.startswith("/") else tmp_path / target
    code, _, err = _cli(["simulate", "--params", PARAMS, "--input", files["good"], "-o", out], capsys)
    _assert_one_line_error(code, err, *words)


def test_simulate_failure_leaves_the_old_output_intact(files, capsys, tmp_path):
    out = tmp_path / "out.csv"
    out.write_text("precious\n")
    code, _, err = _cli(["simulate", "--params", "alpha=0.3,a1=0.01,a2=1e-4,b=1e300", "--input", files["u_huge"],
                         "-o", out], capsys)
    _assert_one_line_error(code, err, "not finite")
    assert out.read_text() == "precious\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]      # no temporary file left behind


def test_simulate_output_is_replaced_whole(files, capsys, tmp_path):
    out = tmp_path / "out.csv"
    out.write_text("old\n")
    assert _cli(["simulate", "--params", PARAMS, "--input", files["good"], "-o", out], capsys)[0] == 0
    assert len(load_csv(out)) == 1500 and sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]


@pytest.mark.parametrize("params, words", [("alpha=0.3,a1=0.01,a2=1e-4,alpha=0.5", ["twice"]),
                                           ("alpha=2,a1=0.01,a2=1e-4", ["alpha"]),
                                           ("alpha=0.3,a1=x,a2=1e-4", ["not a number"])])
def test_simulate_params_are_checked(files, capsys, tmp_path, params, words):
    code, _, err = _cli(["simulate", "--params", params, "--input", files["good"], "-o", tmp_path / "o.csv"],
                        capsys)
    _assert_one_line_error(code, err, *words)


def test_report_folder_with_other_files_is_refused(files, capsys, tmp_path):
    folder = tmp_path / "rep"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    code, _, err = _cli(["diagnose", files["good"], "--report", folder], capsys)
    _assert_one_line_error(code, err, "not an earlier creep-online report")
    assert (folder / "notes.txt").read_text() == "mine"


def test_report_folder_is_all_or_nothing(tmp_path):
    from creep_online.io.safe_files import report_dir
    folder = tmp_path / "rep"
    with report_dir(folder) as tmp:
        (tmp / "index.html").write_text("old report")
    with pytest.raises(KeyboardInterrupt):
        with report_dir(folder) as tmp:
            (tmp / "index.html").write_text("half")
            raise KeyboardInterrupt
    assert [p.name for p in tmp_path.iterdir()] == ["rep"]
    assert (folder / "index.html").read_text() == "old report"
    with report_dir(folder) as tmp:
        (tmp / "index.html").write_text("new report")
        (tmp / "plot.png").write_bytes(b"png")
    assert sorted(p.name for p in folder.iterdir()) == [".creep-online-report", "index.html", "plot.png"]
    assert (folder / "index.html").read_text() == "new report"
    assert [p.name for p in tmp_path.iterdir()] == ["rep"]


# ------------------------------------------------------------------ encoders
@FEW
@given(st.integers(0, 2**31), st.floats(allow_nan=False, allow_infinity=False),
       st.floats(allow_nan=False, allow_infinity=False), st.floats(allow_nan=False, allow_infinity=False))
def test_encode_ascii_accepts_numpy_scalars(seq, t, u, y):
    line = encode_ascii(np.int64(seq), np.float64(t), np.float64(u), np.float64(y))
    assert b"np." not in line
    (got,) = AsciiParser().feed(line)
    assert (got.seq, got.t, got.u, got.y) == (seq, t, u, y)


# ------------------------------------------------------------------ streams
def test_stream_dt_contradicting_the_file_is_an_error(files, capsys):
    code, _, err = _cli(["stream", "--source", f"csv:{files['good']}", "--dt", "1"], capsys)
    _assert_one_line_error(code, err, "contradicts")


@pytest.mark.parametrize("flags", [["--max-samples", "0"], ["--duration", "-1"]])
def test_stream_limits_are_checked(files, capsys, flags):
    code, _, err = _cli(["stream", "--source", f"csv:{files['good']}", *flags], capsys)
    _assert_one_line_error(code, err)


def test_stream_end_of_file_reports_and_exits_0(files, capsys):
    code, out, _ = _cli(["stream", "--source", f"csv:{files['good']}", "--json"], capsys)
    assert code == 0 and json.loads(out)["end"]["reason"] == "end_of_stream"


def _stream_over_pty(extra_spec: str = "") -> tuple[subprocess.Popen, int]:
    master, slave = os.openpty()
    tty.setraw(slave)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    # SIGINT back to its default in the child: a shell that runs the suite in the background
    # starts it with SIGINT ignored, and Python would then never raise KeyboardInterrupt
    proc = subprocess.Popen([sys.executable, "-m", "creep_online", "stream", "--json", "--source",
                             f"serial:{os.ttyname(slave)}?format=ascii{extra_spec}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    os.close(slave)
    t, u, y = _record(3000)
    os.write(master, b"".join(encode_ascii(k, t[k], u[k], y[k]) for k in range(300)))
    return proc, master


def _send_rest(master: int) -> None:
    t, u, y = _record(3000)
    for k in range(300, 3000, 100):
        os.write(master, b"".join(encode_ascii(j, t[j], u[j], y[j]) for j in range(k, k + 100)))
        time.sleep(0.002)


def _wait_for_samples(proc: subprocess.Popen, master: int, timeout: float = 90.0) -> str:
    """Keep the port open until the stream has consumed the data: its stall message on stderr.

    A fixed sleep raced the stream's start-up (kernel warm-up) on a loaded machine. Returns
    the stderr read so far (``communicate`` returns only the rest).
    """
    _send_rest(master)
    seen = b""
    end = time.monotonic() + timeout
    fd = proc.stderr.fileno()
    while b"stall" not in seen and time.monotonic() < end and proc.poll() is None:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            seen += os.read(fd, 4096)
    return seen.decode(errors="replace")


def test_stream_link_lost_for_good_prints_the_estimate_and_exits_4():
    proc, master = _stream_over_pty("&reconnect=0")
    early = _wait_for_samples(proc, master)
    os.close(master)
    out, err = proc.communicate(timeout=120)
    err = early + err
    assert proc.returncode == 4, err
    assert "Traceback" not in err and "link lost" in err
    report = json.loads(out)
    assert report["samples"] > 1000 and report["end"]["reason"] == "link_lost"
    # the estimate so far is printed (its values None while not yet estimated: this stream joins the record after
    # its step, and a held input shows nothing to estimate)
    assert report["source_stats"]["disconnects"] == 1 and {"alpha", "phase", "quality", "reason"} <= set(report)


def test_stream_ctrl_c_prints_the_estimate_and_exits_130():
    proc, master = _stream_over_pty()
    early = _wait_for_samples(proc, master)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    err = early + err
    os.close(master)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    report = json.loads(out)
    assert report["samples"] > 1000 and report["end"]["reason"] == "interrupted"


def test_canlog_bad_records_are_counted_and_skipped(tmp_path):
    can = pytest.importorskip("can", reason="python-can is an optional extra (creep_online[can])")
    from creep_online.io import can_frames as cf
    from creep_online.io import open_source
    good = tmp_path / "s.asc"
    with can.Logger(str(good)) as log:
        ts = 1000.0
        for k in range(0, 400, 2):
            for fid, data, _fd in (cf.encode_input(0, 1.0), cf.encode_pair(k, 0, 0, 0.1 * k, 0.1 * k + 0.05)):
                log(can.Message(timestamp=ts, arbitration_id=fid, data=data, is_extended_id=False))
                ts += 1e-4
    lines = good.read_text().splitlines(True)
    k = next(i for i, ln in enumerate(lines) if " Rx " in ln and i > len(lines) // 2)
    lines[k] = lines[k].split(" Rx ")[0] + " Rx d 8 GG HH II JJ KK LL MM NN\n"
    bad = tmp_path / "bad.asc"
    bad.write_text("".join(lines))
    src = open_source(f"canlog:{bad}?rate=1000", on_event=None)
    samples = list(src)
    assert src.ended and src.stats.parser.malformed == 1
    assert len(samples) >= 398


# ------------------------------------------------------------------ source options and spellings
HOSTILE = ("nan", "inf", "-1", "1e300", "", "abc")
OPTIONS = {"csv": ("csv:{good}", ("window", "stall", "realtime", "u_column")),
           "canlog": ("canlog:{good}", ("rate", "window", "dbc")),
           "capancdt": ("capancdt:127.0.0.1:9?command={good}", ("rate", "range", "channel", "timeout", "counter0",
                                                              "reconnect_timeout", "idle_timeout")),
           "serial": ("serial:/dev/creep-online-no-port", ("rate", "baud", "scale_u", "window", "stall"))}


@pytest.mark.parametrize("kind, option", [(k, o) for k, (_, opts) in OPTIONS.items() for o in opts])
def test_every_source_option_refuses_hostile_values_in_one_line(files, capsys, kind, option):
    base = OPTIONS[kind][0].format(good=files["good"])
    for value in HOSTILE:
        spec = base + ("&" if "?" in base else "?") + f"{option}={value}"
        code, _, err = _cli(["stream", "--source", spec], capsys)
        assert "Traceback" not in err and "internal error" not in err, err
        if code != 0:                              # (a long stall, a bare ``realtime``: valid)
            _assert_one_line_error(code, err)


@pytest.mark.parametrize("spec", ["CSV:{good}", "Csv:{good}", " csv:{good}", "csv:", "nosuch:{good}", "{good}"])
def test_spec_spellings_that_are_not_a_kind_are_refused(files, capsys, spec):
    code, _, err = _cli(["stream", "--source", spec.format(good=files["good"])], capsys)
    _assert_one_line_error(code, err)


def test_stdin_as_dash_is_read_like_a_file(files):
    res = subprocess.run([sys.executable, "-m", "creep_online", "identify", "-", "--json"], capture_output=True,
                         text=True, stdin=open(files["good"]), timeout=120)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["samples"] == 1500


def test_an_output_name_the_system_cannot_use_is_one_line(files, capsys, tmp_path):
    for name in ("x" * 5000, str(tmp_path / ("y" * 300) / "out.csv")):
        code, _, err = _cli(["simulate", "--params", PARAMS, "--input", files["good"], "-o", name], capsys)
        _assert_one_line_error(code, err)
    code, _, err = _cli(["diagnose", files["good"], "--report", "x" * 5000], capsys)
    _assert_one_line_error(code, err)


def test_every_warning_is_one_line(files, capsys, tmp_path):
    """A numpy RuntimeWarning printed its source line too (two lines beside the error)."""
    code, _, err = _cli(["simulate", "--params", "alpha=0.3,a1=0.01,a2=1e-4,b=1e300", "--input", files["u_huge"],
                         "-o", tmp_path / "o.csv"], capsys)
    assert code == 2
    assert all(ln.startswith("creep-online simulate: ") for ln in err.splitlines() if ln.strip()), err


# ------------------------------------------------------------------ model files, compare reports, simulate formats
@pytest.fixture(scope="module")
def model_file(files, tmp_path_factory) -> Path:
    from creep_online import save_model
    t, u, y = _record()
    path = tmp_path_factory.mktemp("model") / "model.json"
    save_model(identify(t, u, y), path)
    return path


def test_a_model_output_is_never_the_data(files, capsys, tmp_path):
    """identify -o and fit -o compare the model file with the record by identity, whatever the spelling."""
    data = tmp_path / "rec.json"                      # a record named like a model file
    data.write_bytes(files["good"].read_bytes())
    before = data.read_bytes()
    (tmp_path / "link.json").symlink_to(data)
    for out in (data, tmp_path / "." / "rec.json", tmp_path / "link.json"):
        code, _, err = _cli(["identify", data, "-o", out], capsys)
        _assert_one_line_error(code, err, "refusing to overwrite the input")
    code, _, err = _cli(["fit", data, "--effects", "delay", "-o", tmp_path / "link.json"], capsys)
    _assert_one_line_error(code, err, "refusing to overwrite the input")
    for out, words in ((files["good"], [".json"]), ("", ["must not be empty"])):
        code, _, err = _cli(["identify", files["good"], "-o", out], capsys)
        _assert_one_line_error(code, err, *words)
    assert data.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "rec.json"]


def test_simulate_never_writes_over_the_model_it_reads(files, model_file, capsys, tmp_path):
    before = model_file.read_bytes()
    for flag in ("--model", "--params"):
        code, _, err = _cli(["simulate", "--input", files["good"], flag, model_file, "-o", model_file], capsys)
        _assert_one_line_error(code, err, "refusing to overwrite the input")
    code, _, err = _cli(["simulate", "--input", files["good"], "--model", model_file, "-o", tmp_path / "x.xlsx"],
                        capsys)
    _assert_one_line_error(code, err, "unknown output format")
    assert model_file.read_bytes() == before and not list(tmp_path.iterdir())


def test_simulate_parquet_is_written_whole(files, model_file, capsys, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "sim.parquet"
    out.write_text("old")
    assert _cli(["simulate", "--input", files["good"], "--model", model_file, "-o", out], capsys)[0] == 0
    assert pq.read_table(out).num_rows == 1500 and [p.name for p in tmp_path.iterdir()] == ["sim.parquet"]


def test_compare_report_keeps_the_users_folders(files, model_file, capsys, tmp_path):
    """compare --report: a foreign folder, the model file itself and '' are refused; a new folder gets the marker
    and can be replaced by the next compare."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "calibration.json").write_text("{}")
    for target, words in ((mine, ["not an earlier creep-online report"]), (model_file, ["not a folder"]),
                          ("", ["must not be empty"])):
        code, _, err = _cli(["compare", model_file, files["good"], "--report", target], capsys)
        _assert_one_line_error(code, err, *words)
    assert (mine / "calibration.json").read_text() == "{}" and [p.name for p in mine.iterdir()] == ["calibration.json"]
    rep = tmp_path / "rep"
    for _ in range(2):                                 # the second run replaces its own earlier report
        assert _cli(["compare", model_file, files["good"], "--report", rep], capsys)[0] == 0
    from creep_online.io.safe_files import REPORT_MARKER
    assert sorted(p.name for p in rep.iterdir()) == sorted(["compare.json", "compare.png", "report.html",
                                                            REPORT_MARKER])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "rep"]    # no temporary sibling left


def test_a_model_file_that_is_a_fifo_is_not_waited_on(files, capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("CREEP_ONLINE_READ_TIMEOUT", "0.5")
    fifo = tmp_path / "model.json"
    os.mkfifo(fifo)
    for argv in (["compare", fifo, files["good"]],
                 ["simulate", "--input", files["good"], "--model", fifo, "-o", tmp_path / "o.csv"]):
        code, _, err = _cli(argv, capsys)
        _assert_one_line_error(code, err, "nothing to read")


def test_parameter_text_too_long_for_a_file_name_is_parameter_text(files, capsys, tmp_path):
    code, _, err = _cli(["simulate", "--input", files["good"], "--params", "alpha=" + "x" * 5000,
                         "-o", tmp_path / "o.csv"], capsys)
    _assert_one_line_error(code, err, "not a number")


def test_a_json_usage_error_is_one_json_object(capsys):
    code, out, err = _cli(["identify", "--json", "--t-c", "nan", "x.csv"], capsys)
    assert code == 2 and not out
    error = json.loads(err)
    assert error["type"] == "UsageError" and "--t-c" in error["error"] and error["exit_code"] == 2


def test_the_status_line_escapes_what_it_shows():
    from creep_online.commands._progress import Progress
    progress = Progress(False)
    progress._text = "diagnose rec\x1b]0;pwned\x07.csv: loading"
    assert "\x1b" not in progress.line() and "\\x1b" in progress.line()


# ------------------------------------------------------------------ the sweep: categories and counts
SWEEP = REPO / "bench" / "results" / "reliability.json"
#: Outcomes the recorded sweep must not contain (bench/bench_reliability.py's classes besides "clean").
NONE_OF = ("traceback", "outside_contract", "internal_error", "hang", "file_lost", "silently_wrong",
           "valid_refused", "injection", "messy_error", "no_estimate", "temp_left")


def test_the_recorded_sweep_meets_its_numbers():
    """At least 800 attempts over every category; not one traceback, exception outside the contract, internal
    error, hang, lost file, silently wrong answer, injection, or signalled stream without its estimate."""
    report = json.loads(SWEEP.read_text())
    assert report["attempts"] >= 800
    assert set(report["categories"]) == {"flags", "specs", "files", "outputs", "signals", "pipes", "api", "pickle",
                                         "canlog", "security", "scheduler", "hil_sim", "bounded"}
    assert {k: report["totals"][k] for k in NONE_OF if report["totals"][k]} == {}, report["failures"]
    # a Ctrl-C inside the interpreter's own start-up (before the package's first line) is Python's; it is
    # counted apart and only start-up attempts may end that way
    startup = [f for f in report["failures"] if f["outcome"] == "python_startup"]
    assert all(f["category"] == "signals" and "start-up" in f["case"] for f in startup), startup
    assert sum(per["clean"] for per in report["categories"].values()) + len(startup) == report["attempts"]


def test_the_guide_shows_the_recorded_counts():
    """docs/reliability.md's table has one row per category with the recorded sweep's numbers."""
    report = json.loads(SWEEP.read_text())
    page = (REPO / "docs" / "reliability.md").read_text()
    for name, per in report["categories"].items():
        attempts = sum(per.values())
        assert re.search(rf"^\| {name} +\| +{attempts} +\| +{per['clean']} +\|", page, re.MULTILINE), name
    assert re.search(rf"^\| \*\*all\*\* +\| +\*\*{report['attempts']}\*\* +\|", page, re.MULTILINE)
