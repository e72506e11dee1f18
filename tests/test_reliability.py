"""Signals, pipes, folders that hold the user's files, every setting validated, the API contract, checkpoints.

Each test reproduces one failure a sweep found (docs/reliability.md has the
categories and the counts) and checks what the user sees now: real files,
real subprocesses and signals, real FIFOs and pipes, a real Dask cluster. The
sweep itself is ``bench/bench_reliability.py``: a sample of it runs here, all
of it under the ``slow`` marker.
"""
from __future__ import annotations

import copy
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from creep_online import CreepModel, CreepOnlineError, identify, simulate
from creep_online.cli import main
from creep_online.errors import DataError
from creep_online.io import save_csv


from bench import bench_reliability as SWEEP

REPO = Path(__file__).resolve().parents[1]
TRUE = CreepModel(0.3, 0.01, 1e-4, 2.0)
CREEP = [sys.executable, "-m", "creep_online"]


def _record(n: int = 3000, h: float = 1e-3, seed: int = 1):
    t = np.arange(n) * h
    u = np.where(t > 0.05, 1.0, 0.0)
    y = simulate(TRUE, t, u) + 1e-4 * np.random.default_rng(seed).standard_normal(n)
    return t, u, y


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("rel")
    t, u, y = _record()
    save_csv(d / "rec.csv", t, u, y)
    return d / "rec.csv"


def _cli(argv, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _one_line_error(code: int, err: str, *words: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip() and ": warning: " not in ln
             and not ln.startswith("creep-online: ")]     # (a stream's events: a source says what it saw)
    assert len(lines) == 1, err
    if lines[0].startswith("{"):                      # --json: the error as one JSON object
        error = json.loads(lines[0])
        assert error["exit_code"] == 2 and error["error"], err
    else:
        assert ": error: " in lines[0], err
    for w in words:
        assert w in lines[0], (w, lines[0])


def _no_default_signals():
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, signal.SIG_DFL)


# ------------------------------------------------------------------ outputs: nothing of the user's destroyed
@pytest.mark.parametrize("spec", ["csv:{m}?realtime=0", "csv:{m}?window=16", "csv:{d}/./m.csv",
                                  "csv:{d}/link.csv", "csv:{d}/hard.csv?realtime=0"])
def test_a_trace_is_never_written_over_the_stream_input(rec, tmp_path, capsys, spec):
    """``stream --source 'csv:m.csv?realtime=0' --trace m.csv`` replaced the measurements with the trace."""
    m = tmp_path / "m.csv"
    m.write_bytes(rec.read_bytes())
    os.symlink(m, tmp_path / "link.csv")
    os.link(m, tmp_path / "hard.csv")
    code, _, err = _cli(["stream", "--source", spec.format(m=m, d=tmp_path), "--trace", m], capsys)
    _one_line_error(code, err, "refusing to overwrite the input file")
    assert m.read_bytes() == rec.read_bytes()


def test_a_trace_is_never_written_over_a_can_log_or_its_dbc(tmp_path, capsys):
    can = pytest.importorskip("can")
    from creep_online.io import can_frames as cf
    log = tmp_path / "session.asc"
    with can.Logger(str(log)) as writer:
        writer(can.Message(timestamp=1.0, arbitration_id=cf.ID_SAMPLE, data=bytes(8), is_extended_id=False))
    dbc = tmp_path / "amp.dbc"
    dbc.write_bytes(cf.dbc_path().read_bytes())
    before = log.read_bytes(), dbc.read_bytes()
    for trace in (log, dbc):
        code, _, err = _cli(["stream", "--source", f"canlog:{log}?rate=2000&dbc={dbc}", "--trace", trace], capsys)
        _one_line_error(code, err, "refusing to overwrite the input file")
    assert (log.read_bytes(), dbc.read_bytes()) == before


def test_a_folder_of_the_users_files_is_never_a_report(rec, tmp_path, capsys):
    """``diagnose --report rep`` replaced a folder holding the user's calibration.json and holiday.png."""
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "calibration.json").write_text("{}")
    (rep / "holiday.png").write_bytes(b"png")
    code, _, err = _cli(["diagnose", rec, "--effects", "delay", "--workers", "1", "--report", rep], capsys)
    _one_line_error(code, err, "not an earlier creep-online report", "calibration.json")
    assert sorted(p.name for p in rep.iterdir()) == ["calibration.json", "holiday.png"]
    for bad in ("", "   "):
        code, _, err = _cli(["diagnose", rec, "--report", bad], capsys)
        _one_line_error(code, err, "must not be empty")


def test_a_report_folder_is_replaced_only_while_its_marker_lists_everything_in_it(tmp_path):
    from creep_online.errors import OutputError
    from creep_online.io.safe_files import REPORT_MARKER, report_dir
    rep = tmp_path / "rep"
    with report_dir(rep) as tmp:
        (tmp / "index.html").write_text("first")
    assert json.loads((rep / REPORT_MARKER).read_text())["files"] == ["index.html"]
    with report_dir(rep) as tmp:                  # an earlier report of ours: replaced
        (tmp / "index.html").write_text("second")
    assert (rep / "index.html").read_text() == "second"
    (rep / "notes.txt").write_text("the user's")  # the user added a file: the folder is theirs now
    with pytest.raises(OutputError, match="notes.txt"):
        with report_dir(rep):
            pass
    assert (rep / "notes.txt").read_text() == "the user's"


def test_the_default_page_of_a_batch_never_replaces_a_file_it_did_not_write(rec, tmp_path, capsys):
    """``batch --out x.csv`` silently replaced an existing x.html it had not written."""
    pytest.importorskip("dask.distributed")
    page = tmp_path / "x.html"
    page.write_text("<p>the user's page</p>")
    code, _, err = _cli(["batch", rec, "--out", tmp_path / "x.csv"], capsys)
    _one_line_error(code, err, "not written by creep-online", "--html")
    assert page.read_text() == "<p>the user's page</p>"
    from creep_online.io.safe_files import WRITTEN_BY, check_default_output
    page.write_text(f"<!doctype html><!-- {WRITTEN_BY} --><p>an earlier page</p>")
    assert check_default_output(page) == page    # one of ours: may be replaced


# ------------------------------------------------------------------ signals as a service manager sends them
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_a_stream_stopped_by_any_signal_prints_its_estimate_and_writes_its_trace(tmp_path, signum):
    """SIGTERM (systemd, Docker, Kubernetes) ended ``stream --trace`` without its estimate and left the old trace.

    The signal is sent some seconds after the command took the signals over; if the stream had not started by
    then (a busy machine: it was still loading its kernels) the answer is one line with nothing to print, and
    the attempt is repeated later in the stream."""
    t, u, y = _record(120000)      # (two minutes in real time: longer than the longest wait below)
    save_csv(tmp_path / "r.csv", t, u, y)
    trace = tmp_path / "trace.csv"
    for delay in (6.0, 15.0, 30.0, 60.0):
        trace.write_text("old trace\n")
        p = subprocess.Popen([*CREEP, "stream", "--source", f"csv:{tmp_path / 'r.csv'}?realtime=1", "--trace", trace],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_no_default_signals)
        _wait_for(lambda: p.poll() is not None or _catches(p.pid, signal.SIGTERM), 120)   # (its handlers are in)
        time.sleep(delay)
        p.send_signal(signum)
        out, err = p.communicate(timeout=60)
        assert p.returncode == 128 + signum, err
        assert "Traceback" not in err
        if out:
            break
        assert err.strip().count("\n") == 0, err      # too early: one line, nothing else
    assert "alpha" in out and f"(exit {128 + signum})" in out, (out, err)
    rows = trace.read_text().splitlines()
    assert rows[0].startswith("t,alpha") and len(rows) > 10
    assert not [q for q in tmp_path.iterdir() if q.name.endswith(".tmp")]


def _catches(pid: int, signum: int) -> bool:
    """Has process ``pid`` installed a handler for ``signum`` (the CLI's ``main`` has started)?"""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = int(next(ln.split()[1] for ln in status.splitlines() if ln.startswith("SigCgt:")), 16)
    return bool(mask & (1 << (signum - 1)))


def _wait_for(cond, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        time.sleep(0.05)


@pytest.mark.long
def test_sigterm_during_a_long_computation_leaves_no_temporary_file_and_the_old_output(tmp_path):
    """``simulate -o`` stopped by SIGTERM left a 27 MB ``.out.csv.*.tmp`` behind."""
    big = tmp_path / "tu.csv"
    big.write_text("t,u\n" + "".join(f"{k * 1e-4!r},{float(k > 10)!r}\n" for k in range(300_000)))
    out = tmp_path / "out.csv"
    out.write_text("old\n")
    p = subprocess.Popen([*CREEP, "simulate", "--input", big, "--params", "alpha=0.3,a1=0.01,a2=1e-4", "--method",
                          "paper", "-o", out], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=_no_default_signals)
    time.sleep(5.0)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 143, err
    assert "Traceback" not in err and err.strip().count("\n") == 0, err
    assert out.read_text() == "old\n"
    assert sorted(q.name for q in tmp_path.iterdir()) == ["out.csv", "tu.csv"]


@pytest.mark.parametrize("mode", ["flagged", "deferred"])
def test_a_signal_the_handler_answered_at_once_is_never_taken_for_a_stuck_computation(mode):
    """The watchdog ended a batch whose first Ctrl-C only set the flag ("... while busy in a computation"):
    the main thread had run the handler before the watchdog thread woke to read the signal, so the watchdog
    waited for an answer that had already come. Here the handler always runs first (the signal is sent to the
    process by its own main thread); the process must outlive the grace time and report the signal itself."""
    code = f"""
import os, signal, time
from creep_online import _signals
with _signals.{mode}() as pressed:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(_signals.GRACE_S + 1.0)
    print("alive", _signals.pending_signal() if pressed is None else pressed(), flush=True)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         preexec_fn=_no_default_signals)
    assert "busy in a computation" not in out.stderr, out.stderr
    assert out.stdout.split() == ["alive", str(int(signal.SIGINT))], (out.returncode, out.stdout, out.stderr)


@pytest.mark.parametrize("marker", ["creep_online._signals", "numpy", "creep_online.model", "creep_online.cli",
                                    "scipy"])
def test_ctrl_c_at_start_up_is_one_line_never_a_traceback(rec, marker):
    """Ctrl-C while the command was still importing printed a KeyboardInterrupt traceback. The signal is sent as
    the import of ``marker`` ends (``-X importtime`` lines); before the package's first line runs, a Ctrl-C is
    the interpreter's own start (Python's "init_import_site" message), not covered."""
    p = subprocess.Popen([sys.executable, "-X", "importtime", "-m", "creep_online", "identify", rec],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_no_default_signals)
    seen = []
    for line in p.stderr:
        seen.append(line)
        if line.rstrip().endswith(f"| {marker}") or line.rstrip().endswith(f"|   {marker}"):
            p.send_signal(signal.SIGINT)
            break
    rest = p.stderr.read()
    p.wait(timeout=60)
    err = "".join(seen) + rest
    assert "Traceback" not in err, err[-2000:]
    assert p.returncode in (0, 130, -signal.SIGINT), err[-500:]


# ------------------------------------------------------------------ pipes, FIFOs, '-'
@pytest.mark.parametrize("how", ["- < {rec}", "/dev/stdin < {rec}", "<(cat {rec})", "<(gzip -c {rec} | zcat)"])
def test_pipes_and_stdin_are_read_as_streams(rec, how):
    """``identify /dev/stdin < x.csv`` and ``identify <(cat x.csv)`` failed: the header was misread."""
    cmd = " ".join(CREEP) + " identify " + how.format(rec=rec) + " --json"
    res = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert abs(json.loads(res.stdout)["alpha"] - 0.3) < 0.01


def test_a_fifo_with_no_writer_gets_an_answer_within_the_timeout(tmp_path):
    """A FIFO input hung ``identify`` and ``diagnose`` (no answer in 60-240 s)."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    res = subprocess.run([*CREEP, "identify", fifo], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "CREEP_ONLINE_READ_TIMEOUT": "2"})
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "nothing to read for 2 s" in res.stderr


def test_a_fifo_with_a_late_writer_is_read(rec, tmp_path, capsys):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    writer = subprocess.Popen(["bash", "-c", f"sleep 1; cat {rec} > {fifo}"])
    code, out, err = _cli(["identify", fifo, "--json"], capsys)
    writer.wait(timeout=30)
    assert code == 0, err
    assert json.loads(out)["samples"] == 3000


@pytest.mark.parametrize("spec", ["capancdt:127.0.0.1:9?command=/dev/zero", "canlog:{rec}?rate=100&dbc=/dev/zero"])
def test_devices_named_as_inputs_are_refused_not_read(rec, capsys, spec):
    """``capancdt:...?command=/dev/zero`` read until memory ran out (23 GB)."""
    code, _, err = _cli(["stream", "--source", spec.format(rec=rec)], capsys)
    _one_line_error(code, err, "is a character device")


# ------------------------------------------------------------------ settings: the internal errors and silent accepts
@pytest.mark.parametrize("header", [{"SEPARATOR": "inf"}, {"SEPARATOR": "1e300"}, {"DIM": "inf"}, {"DIM": "1e300"},
                                    {"SEPARATOR": "0"}, {"DIM": "2.5"}])
def test_gcs_headers_out_of_range_are_one_line_errors(tmp_path, capsys, header):
    """GCS headers with SEPARATOR/DIM inf or huge: OverflowError, chr() out of range (internal errors)."""
    t, u, y = _record(500)
    path = tmp_path / "rec.gcs"
    path.write_text(SWEEP.gcs_text(u, y, 1e-3, header))
    for argv in (["identify", path], ["stream", "--source", f"csv:{path}"]):
        code, _, err = _cli(argv, capsys)
        _one_line_error(code, err, "GCS header")


@pytest.mark.parametrize("argv, words", [
    (["identify", "{rec}", "--layer1-step", "1e300"], ["--layer1-step"]),
    (["simulate", "--input", "{rec}", "--params", "alpha=0.3,fn=1e300,zeta=0.1", "-o", "{out}"], ["fn"]),
    (["simulate", "--input", "{rec}", "--params", "alpha=0.3,fn=1e-300,zeta=0.1", "-o", "{out}"], ["fn"]),
    (["fit", "{rec}", "--effects", "delay", "--window", "nan"], ["--window"]),
    (["fit", "{rec}", "--effects", "delay", "--window", "inf"], ["--window"]),
    (["demo", "--period", "0"], ["--period"]), (["demo", "--bandwidth", "0"], ["--bandwidth"]),
    (["stream", "--source", "capancdt:127.0.0.1:9?command={rec}&timeout=nan"], ["timeout"]),
    (["stream", "--source", "capancdt:127.0.0.1:9?command={rec}&timeout=-1"], ["timeout"]),
])
def test_what_were_internal_errors_are_one_line_errors(rec, tmp_path, capsys, argv, words):
    code, _, err = _cli([a.format(rec=rec, out=tmp_path / "o.csv") for a in argv], capsys)
    _one_line_error(code, err, *words)


@pytest.mark.parametrize("argv, words", [
    (["stream", "--source", "csv:{rec}", "--t-c", "1e300"], ["--t-c"]),
    (["stream", "--source", "csv:{rec}", "--window", "1e-300"], ["window"]),
    (["stream", "--source", "csv:{rec}", "--alpha0", "1e-300"], ["alpha0"]),
    (["simulate", "--input", "{rec}", "--params", "alpha=0.3,a1=0.01,a2=1e-4", "--method", "paper", "--memory", "0",
      "-o", "{out}"], ["--memory"]),
    (["simulate", "--input", "{rec}", "--params", "alpha=0.3,a1=0.01,a2=1e-4", "--method", "paper", "--memory", "-1",
      "-o", "{out}"], ["--memory"]),
    (["fit", "{rec}", "--effects", "delay", "--window", "0"], ["--window"]),
    (["fit", "{rec}", "--effects", "delay", "--window", "-1"], ["--window"]),
    (["diagnose", "{rec}", "--effects", ""], ["--effects"]),
    (["stream", "--source", "csv:{rec}?window=-5"], ["window"]),
    (["stream", "--source", "csv:{rec}?stall=nan"], ["stall"]),
    (["stream", "--source", "CSV:{rec}"], ["lower case"]),
    (["stream", "--source", ""], ["--source"]),
])
def test_what_was_silently_accepted_is_refused(rec, tmp_path, capsys, argv, words):
    code, _, err = _cli([a.format(rec=rec, out=tmp_path / "o.csv") for a in argv], capsys)
    _one_line_error(code, err, *words)


def test_stream_honours_max_samples_and_duration_on_a_file(rec, capsys):
    """``stream --max-samples 10`` on a CSV processed all 4000 samples with exit 0."""
    code, out, err = _cli(["stream", "--source", f"csv:{rec}", "--max-samples", "10", "--json"], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["samples"] == 10 and report["end"]["reason"] == "limit"
    code, out, _ = _cli(["stream", "--source", f"csv:{rec}", "--max-samples", "100000", "--json"], capsys)
    assert json.loads(out)["samples"] == 3000 and json.loads(out)["end"]["reason"] == "end_of_stream"


def test_fit_of_more_effects_than_a_record_determines_is_refused_at_once(rec, capsys):
    """``fit --effects`` with all eight effects gave no answer in 900 s."""
    from creep_online.effects import effect_names
    code, _, err = _cli(["fit", rec, "--effects", ",".join(effect_names())], capsys)
    _one_line_error(code, err, "at most 4", "diagnose")


def test_hil_sim_settings_are_one_line_errors():
    """hil_sim: tracebacks for an unknown effect or rate 0, hangs for noise=nan, adc_bits=0, period=0."""
    from hil_sim.__main__ import main as plant
    for argv in (["--effects", "bogus"], ["--rate", "0"], ["--rate", "-5"], ["--noise", "nan"], ["--adc-bits", "0"],
                 ["--period", "0"], ["--duration", "0"], ["--transport", "capancdt", "--command-rate", "0"],
                 ["--transport", "capancdt", "--frames-per-packet", "0"], ["--faults", "drop=nan"],
                 ["--payload", "x"], ["--link", "/no/such/folder/amp"]):
        assert plant(["--fast", "--linger", "0", *argv]) == 2, argv


# ------------------------------------------------------------------ the API contract
NUMBERS = [np.float32(0.5), np.float16(0.5), np.int8(1), np.uint64(2), 1, Fraction(1, 3), np.float64(0.5)]
NOT_NUMBERS = ["1.0", True, None, b"1", 1 + 2j, 10 ** 400, np.datetime64(1, "s"), [1.0], {"u": 1}, object(),
               np.bool_(True), ""]


def test_update_takes_numbers_of_every_width_and_refuses_everything_else():
    """``update("1.0", 0.5)``, bools, bytes, None were accepted; a huge int raised OverflowError."""
    from creep_online.online import OnlineEstimator
    est = OnlineEstimator(np.float32(1e-3))          # a float32 dt was refused
    for v in NUMBERS:
        est.update(v, 0.5)
        est.update(0.5, v)
    assert est.samples == 2 * len(NUMBERS)
    for v in NOT_NUMBERS:
        for args in ((v, 0.5), (0.5, v)):
            with pytest.raises(DataError) as raised:
                est.update(*args)
            assert "\n" not in str(raised.value)
    assert est.samples == 2 * len(NUMBERS)


@pytest.mark.parametrize("bad", [["1"] * 5, np.ones(5, bool), np.ones(5, complex), np.arange(5).astype("datetime64[s]"),
                                 None, np.ones((5, 2)), "1,2", [10 ** 400] * 5])
def test_update_block_refuses_what_is_not_a_real_1d_array(bad):
    from creep_online.online import OnlineEstimator
    with pytest.raises(DataError):
        OnlineEstimator(1e-3).update_block(bad, np.zeros(5))


@pytest.mark.parametrize("n", ["3", float("nan"), float("inf"), -1, 1.5, None, True, 10 ** 400])
def test_gap_refuses_what_is_not_a_count(n):
    from creep_online.online import OnlineEstimator
    with pytest.raises(DataError):
        OnlineEstimator(1e-3).gap(n)


def test_a_long_outage_is_a_restart_in_constant_work_keeping_the_estimate():
    """``gap(10**9)`` (a day's outage at 10 kHz) replayed every lost sample: ~20 min blocking the loop."""
    from creep_online.online import OnlineEstimator
    from creep_online.online.settings import RecoverySettings
    GAP_REPLAY_MAX = RecoverySettings().gap_replay_max
    t, u, y = _record(4000)
    est = OnlineEstimator(1e-3)
    est.update_block(u[:3000], y[:3000])
    before = est.estimate
    assert before.phase == "tracking"
    est.gap(10 ** 9)
    after = est.estimate
    assert est.samples == 3000 + 10 ** 9 and est.gaps == 10 ** 9
    assert after.phase == "buffering" and after.quality == "provisional" and "restarting" in after.reason
    assert (after.alpha, after.a1, after.a2, after.b) == (before.alpha, before.a1, before.a2, before.b)
    est.gap(GAP_REPLAY_MAX)                           # a short outage is still replayed
    assert est.gaps == 10 ** 9 + GAP_REPLAY_MAX


@pytest.mark.parametrize("call", [
    lambda t, u, y: simulate(TRUE, t, u, method="bogus"), lambda t, u, y: simulate(TRUE, t, u, method="paper", memory=-5),
    lambda t, u, y: simulate(dict(alpha=0.3), t, u), lambda t, u, y: identify(t, u.astype(complex), y),
    lambda t, u, y: identify(t.astype("datetime64[ms]"), u, y), lambda t, u, y: identify([str(v) for v in t], u, y),
    lambda t, u, y: identify(t, u, y, layer1_step=1e300), lambda t, u, y: identify(t, u, y, t_c=10 ** 400),
    lambda t, u, y: CreepModel(10 ** 400, 0.01, 1e-4), lambda t, u, y: CreepModel.from_resonance(0.3, 1e300, 0.1),
])
def test_the_api_raises_data_errors_only(call):
    t, u, y = _record(500)
    with pytest.raises(CreepOnlineError) as raised:
        call(t, u, y)
    assert "\n" not in str(raised.value)


def test_the_compensator_takes_numbers_and_refuses_the_rest():
    from creep_online.online import CreepCompensator
    c = CreepCompensator(np.float32(1e-3), CreepModel(0.1, 1e-3, 1e-6, 1.0), u_min=np.float32(-1.0), u_max=1)
    for v in NUMBERS:
        assert np.isfinite(c.command(v))
    for v in NOT_NUMBERS:
        with pytest.raises(DataError):
            c.command(v)
    with pytest.raises(DataError):
        c.command_block(np.ones((3, 3)))             # numba's TypingError before


# ------------------------------------------------------------------ checkpoints: pickle and deepcopy at any moment
def _data(n: int = 8000):
    h = 1e-3
    t = np.arange(n) * h
    u = np.where((t % 2) > 1, 1.0, 0.0)
    y = simulate(TRUE, t, u)
    y[n // 2:] = simulate(CreepModel(0.3, 0.01, 2e-4, 2.0), t, u)[n // 2:]     # a payload: the plant changes
    return h, u, y + 1e-4 * np.random.default_rng(1).standard_normal(n)


@pytest.mark.parametrize("refit", ["window", "recursive"])
@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_the_estimator_round_trips_at_every_phase_and_the_copy_continues_bit_for_bit(refit, how):
    """``pickle.dumps(est)`` mid-stream raised "cannot pickle 'generator' object"."""
    from creep_online.online import OnlineEstimator
    h, u, y = _data()
    est = OnlineEstimator(h, refit=refit)
    seen = set()
    for k in range(u.size):
        est.update(u[k], y[k])
        if k in (20, 60) or k % 701 == 0 or (est.phase == "searching" and "searching" not in seen):
            seen.add(est.phase)
            twin = pickle.loads(pickle.dumps(est)) if how == "pickle" else copy.deepcopy(est)
            for j in range(k + 1, min(k + 400, u.size)):
                est.update(u[j], y[j])
                twin.update(u[j], y[j])
            a, b = est.estimate, twin.estimate
            assert (a.alpha, a.a1, a.a2, a.b, a.quality, a.phase) == (b.alpha, b.a1, b.a2, b.b, b.quality, b.phase), k
            est = twin                                 # the copy carries on from here
    assert seen >= {"buffering", "searching", "tracking"}
    assert np.isfinite(est.estimate.alpha) and est.internal_faults == 0


def test_the_compensator_and_a_tracker_round_trip():
    from creep_online.online import CreepCompensator, OnlineEstimator
    c = CreepCompensator(1e-3, CreepModel(0.3, 0.01, 1e-4, 2.0), u_min=-5, u_max=5)
    r = np.sin(np.arange(1000) * 0.01)
    for v in r[:500]:
        c.command(v)
    twin = copy.deepcopy(c)
    assert [c.command(v) for v in r[500:]] == [twin.command(v) for v in r[500:]]
    h, u, y = _data(3000)
    est = OnlineEstimator(h)
    est.update_block(u, y)
    tr = est._tracker
    tr2 = pickle.loads(pickle.dumps(tr))
    for j in range(200):
        tr.feed(1.0, float(y[-1]))
        tr2.feed(1.0, float(y[-1]))
    assert (tr.alpha, tr.a1, tr.a2, tr.b) == (tr2.alpha, tr2.a1, tr2.a2, tr2.b)


def test_a_checkpoint_laid_out_by_another_version_is_refused_in_one_line(monkeypatch):
    """The kernels index the state without bounds checks: a checkpoint whose state layout differs (an operator
    block two entries longer, say) or is not recorded must not be read into them."""
    from creep_online import DataError, OnlineEstimator
    from creep_online.online import checkpoint
    from creep_online.online._kernels import hysteresis
    h, u, y = _data(3000)
    est = OnlineEstimator(h, effects=("hysteresis",))
    est.update_block(u, y)
    saved = pickle.dumps(est)
    assert pickle.loads(saved).estimate.alpha == est.estimate.alpha
    monkeypatch.setattr(hysteresis, "HEAD", hysteresis.HEAD + 2)       # this version's layout, another block size
    checkpoint.state_layout.cache_clear()
    try:
        with pytest.raises(DataError, match="laid out otherwise .*resume it with the version that wrote it") as err:
            pickle.loads(saved)
    finally:
        monkeypatch.undo()
        checkpoint.state_layout.cache_clear()
    assert "\n" not in str(err.value)
    with pytest.raises(DataError, match="not recorded"):
        checkpoint._loads(checkpoint.dumps(est))                      # the form without a layout
    assert pickle.loads(saved).estimate.alpha == est.estimate.alpha


# ------------------------------------------------------------------ CAN logs: one bad record never ends the replay
@pytest.mark.parametrize("suffix", [".log", ".csv", ".asc", ".blf"])
def test_an_unreadable_can_log_record_is_skipped_and_counted(tmp_path, suffix):
    """One bad record in a .log or CAN-CSV log dropped the rest of the log; a flipped byte ended a .blf."""
    pytest.importorskip("can")
    from creep_online.io.registry import open_source
    clean = SWEEP.write_canlogs(tmp_path)[suffix]
    CAN_RATE = SWEEP.CAN_RATE
    reference = list(open_source(f"canlog:{clean}?rate={CAN_RATE:g}", on_event=None))
    raw = clean.read_bytes()
    if suffix == ".blf":
        k = len(raw) // 2
        bad = raw[:k] + bytes([raw[k] ^ 0xFF]) + raw[k + 1:]
    else:
        lines = raw.split(b"\n")
        lines[len(lines) // 2] = b"\x00\xff garbage record ### zz"
        bad = b"\n".join(lines)
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(bad)
    src = open_source(f"canlog:{path}?rate={CAN_RATE:g}", on_event=None)
    samples = list(src)
    assert src.ended
    assert samples[-1].seq == reference[-1].seq                # read to the end
    assert len(samples) >= (0.5 if suffix == ".blf" else 0.9) * len(reference), (len(samples), len(reference))
    if suffix != ".asc":                               # (python-can's .asc reader skips lines it does not know)
        assert src.stats.parser.malformed >= 1


# ------------------------------------------------------------------ untrusted text stays text
def test_record_names_are_neutral_in_the_batch_table(tmp_path):
    """Names such as ``=cmd|' /C calc'!A0`` went unneutralised into the batch CSV (formula injection)."""
    import csv
    from creep_online.fleet import write_table
    from creep_online.fleet.row import empty_row
    from creep_online.io.fleet_records import RecordJob
    names = ["=cmd|' /C calc'!A0", "@SUM(1+1)", "+1+1", "-2+3", "\tx", "\rx", "plain", "-1.5"]
    rows = [empty_row(RecordJob(n, n)) for n in names]
    out = write_table(rows, tmp_path / "t.csv")
    with open(out, newline="") as fh:
        got = [r["id"] for r in csv.DictReader(fh)]
    assert got == ["'=cmd|' /C calc'!A0", "'@SUM(1+1)", "'+1+1", "'-2+3", "'\tx", "\\x0dx", "plain", "-1.5"]


def test_escape_sequences_in_names_reach_the_terminal_escaped(tmp_path, capsys):
    """Escape sequences in a file name or a CSV header reached the terminal raw (window title set, screen cleared)."""
    name = tmp_path / "rec\x1b]0;pwned\x07\x1b[2J.csv"
    code, out, err = _cli(["identify", name], capsys)
    assert code == 2 and "\x1b" not in err and "\\x1b]0;pwned\\x07" in err
    head = tmp_path / "head.csv"
    head.write_text("t,u\x1b[2J,z\n0,1,2\n")
    code, out, err = _cli(["identify", head], capsys)
    assert code == 2 and "\x1b" not in err


def test_a_scheduler_address_that_does_not_answer_as_dask_is_one_line(monkeypatch):
    """``batch --scheduler`` at an HTTP or echo service: internal errors; at a silent port: a hang."""
    pytest.importorskip("dask.distributed")
    import socket
    import threading
    from creep_online.fleet import runner
    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 1.0)
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)
    held = []
    threading.Thread(target=lambda: held.append(silent.accept()), daemon=True).start()
    start = time.monotonic()
    with pytest.raises(CreepOnlineError, match="no Dask scheduler answered"):
        with runner.dask_client(f"tcp://127.0.0.1:{silent.getsockname()[1]}"):
            pass
    assert time.monotonic() - start < 30
    silent.close()


# ------------------------------------------------------------------ one bad record never fails its neighbours
def _killer(job, **_):
    """A record that kills its worker (as one too large for its memory does); the others are rows."""
    from creep_online.fleet.row import empty_row
    if job.id == "killer":
        os._exit(1)
    time.sleep(0.3)
    row = empty_row(job)
    row["samples"] = 1
    return row


def test_a_record_that_kills_its_worker_does_not_fail_the_records_queued_behind_it():
    """A Dask worker killed by one huge record also marked the healthy record queued behind it KilledWorker."""
    pytest.importorskip("dask.distributed")
    import cloudpickle
    from creep_online.fleet.runner import dask_client, run_on_dask
    from creep_online.io.fleet_records import RecordJob
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    jobs = [RecordJob(name, name, samples=(np.zeros(2),) * 3) for name in ("a", "killer", "b", "c", "d")]
    with dask_client(None, 1) as client:
        rows = {r["id"]: r for r in run_on_dask(jobs, client, task=_killer)}
    assert set(rows) == {"a", "killer", "b", "c", "d"}
    assert all(rows[k]["error"] == "" and rows[k]["samples"] == 1 for k in "abcd"), rows
    assert "KilledWorker" in rows["killer"]["error"]


# ------------------------------------------------------------------ every flag with hostile values
HOSTILE = ("nan", "inf", "-inf", "0", "-1", "1e300", "1e-300", "", "x" * 5000, "abc")
FLAGS = {"identify": ["--t-c", "--alpha0", "--layer1-step", "--u-column"],
         "stream": ["--t-c", "--alpha0", "--window", "--dt", "--max-samples", "--duration", "--trace"],
         "simulate": ["--memory", "--method", "--params", "-o"],
         "fit": ["--window", "--effects"], "diagnose": ["--effects", "--workers", "--report"],
         "demo": ["--duration", "--rate", "--bandwidth", "--period", "--amplitude", "--u-min", "--seed"],
         "batch": ["--workers", "--scheduler", "--out", "--html"]}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.too_slow])
@given(st.sampled_from(sorted((c, f) for c, fs in FLAGS.items() for f in fs)), st.sampled_from(HOSTILE))
def test_every_flag_with_a_hostile_value_is_exit_0_right_or_exit_2_one_line(rec, tmp_path, capsys, monkeypatch,
                                                                          flag, value):
    command, name = flag
    monkeypatch.chdir(tmp_path)       # (a value taken as a file name, e.g. batch --html 0, is written here)
    base = {"identify": ["identify", rec, "--json"], "stream": ["stream", "--source", f"csv:{rec}", "--json"],
            "simulate": ["simulate", "--input", rec, "--params", "alpha=0.3,a1=0.01,a2=1e-4", "--method", "paper",
                         "-o", tmp_path / "o.csv"],
            "fit": ["fit", rec, "--effects", "delay", "--json"],
            "diagnose": ["diagnose", rec, "--effects", "delay", "--workers", "1", "--json"],
            "demo": ["demo", "--duration", "0.2", "--rate", "2000", "--quiet", "--json"],
            "batch": ["batch", rec, "--workers", "1", "--json"]}[command]
    argv = list(base)
    if name in argv:
        argv[argv.index(name) + 1] = value
    else:
        argv += [name, value]
    if command in ("demo", "batch") and _is_accepted_number(value):
        return                                      # (a run of the plant or a cluster: the sweep covers those)
    code, out, err = _cli(argv, capsys)
    assert "Traceback" not in err and "internal error" not in err, err
    if code == 0:
        report = json.loads(out) if out.strip().startswith("{") else {}
        if command in ("identify", "stream") and report.get("quality") != "none" and report.get("alpha") is not None:
            assert abs(report["alpha"] - 0.3) < 0.05, (argv, report)
    else:
        _one_line_error(code, err)


def _is_accepted_number(text: str) -> bool:
    try:
        return 0 < float(text) < 1e6
    except ValueError:
        return False


# ------------------------------------------------------------------ the sweep
def _sweep(only: str, sample: int) -> dict:
    res = subprocess.run([sys.executable, str(REPO / "bench" / "bench_reliability.py"), "--only", only,
                          "--sample", str(sample), "--list", "--out", os.devnull], capture_output=True, text=True,
                         timeout=3600)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout)


def test_a_sample_of_the_sweep_is_clean():
    """A representative sample of bench/bench_reliability.py (every 20th attempt of its fast categories)."""
    report = _sweep("specs,files,api,canlog", 20)
    assert report["attempts"] >= 25
    assert report["totals"]["clean"] == report["attempts"], report["failures"]


@pytest.mark.slow
def test_the_whole_sweep_is_clean():
    """All of bench/bench_reliability.py (over 1000 attempts; ~40 min on two busy cores)."""
    report = _sweep(",".join(("flags", "specs", "files", "outputs", "signals", "pipes", "api", "pickle", "canlog",
                              "security", "scheduler", "hil_sim", "bounded")), 1)
    assert report["attempts"] >= 800
    assert report["totals"]["clean"] == report["attempts"], report["failures"]
