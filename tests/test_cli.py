"""The identify and simulate commands: stable JSON keys and behaviour."""
import json

import numpy as np
import pytest

from creep_online import CreepModel, simulate
from creep_online.cli import main
from creep_online.io import load_csv, save_csv
from hil_sim.experiments import LOAD_CELL


@pytest.fixture
def loadcell_csv(tmp_path):
    t, u, y, _ = LOAD_CELL.run(40.0, seed=4)
    path = tmp_path / "lc.csv"
    save_csv(path, t, u, y)
    return path


def test_identify_json_has_the_stable_keys(loadcell_csv, capsys):
    assert main(["identify", str(loadcell_csv), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("alpha", "a1", "a2", "b", "fit_percent", "elapsed_s"):
        assert isinstance(out[key], float)
    assert abs(out["alpha"] / LOAD_CELL.model.alpha - 1) < 0.01
    assert out["samples"] == 12000 and out["warnings"] == []


def test_identify_human_output(loadcell_csv, capsys):
    assert main(["identify", str(loadcell_csv)]) == 0
    text = capsys.readouterr().out
    assert "alpha" in text and "fit" in text and "Hz" in text


def test_simulate_writes_t_u_y_for_each_method(tmp_path, capsys):
    t = np.arange(400) * 1e-3
    u = (t > 0.05).astype(float)
    save_csv(tmp_path / "in.csv", t, u, np.zeros_like(t))
    m = CreepModel(0.3, 0.01, 1e-4, 2.0)
    for method in ("exact", "paper", "split"):
        out = tmp_path / f"{method}.csv"
        code = main(["simulate", "--params", "alpha=0.3,a1=0.01,a2=1e-4,b=2", "--input", str(tmp_path / "in.csv"),
                     "-o", str(out), "--method", method])
        assert code == 0
        rec = load_csv(out)
        np.testing.assert_allclose(rec.y, simulate(m, t, u, method=method), rtol=1e-15, atol=0)


def test_simulate_reads_a_file_without_y(tmp_path):
    (tmp_path / "in.csv").write_text("t,u\n" + "".join(f"{k * 0.01},1\n" for k in range(30)))
    assert main(["simulate", "--params", "alpha=0.5,a1=0.1,a2=0.01", "--input", str(tmp_path / "in.csv"),
                 "-o", str(tmp_path / "o.csv")]) == 0


@pytest.mark.parametrize("params, needle", [
    ("alpha=0.3,a1=0.01", "missing a2"), ("alpha=1.5,a1=1,a2=1", "0 < alpha < 1"),
    ("alpha=x,a1=1,a2=1", "not a number"), ("gamma=1", "expected alpha"),
])
def test_simulate_bad_params_exit_2(tmp_path, capsys, params, needle):
    (tmp_path / "in.csv").write_text("t,u\n0,1\n0.1,1\n")
    assert main(["simulate", "--params", params, "--input", str(tmp_path / "in.csv"), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1


def test_simulate_non_uniform_time_is_explained(tmp_path, capsys):
    (tmp_path / "in.csv").write_text("t,u\n0,1\n0.1,1\n0.3,1\n0.4,1\n")
    assert main(["simulate", "--params", "alpha=0.5,a1=0.1,a2=0.01", "--input", str(tmp_path / "in.csv"),
                 "-o", str(tmp_path / "o.csv")]) == 2
    assert "not uniformly sampled" in capsys.readouterr().err


#: A program that runs the command line as ``creep-online`` does, with a SIGINT that lands during the interpreter's
#: shutdown after the command returned (as a Ctrl-C while Dask's cluster closes after ``batch``).
_CTRL_C_AT_EXIT = """
import atexit, os, signal, sys, time
atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(5)))
sys.argv = ["creep-online", "identify", sys.argv[1]]
from creep_online.cli import console
console()
"""


@pytest.mark.parametrize("ignored", [False, True])
def test_a_ctrl_c_while_the_interpreter_exits_is_one_line_and_status_130(tmp_path, ignored):
    import signal
    import subprocess
    import sys
    missing = tmp_path / "missing.csv"
    # the child's Ctrl-C disposition set explicitly: a test run started in the background (nohup, `&`) ignores
    # SIGINT and its children inherit that, which would make the first case the second
    disposition = signal.SIG_IGN if ignored else signal.SIG_DFL
    proc = subprocess.run([sys.executable, "-c", _CTRL_C_AT_EXIT, str(missing)], capture_output=True, text=True,
                          timeout=60, preexec_fn=lambda: signal.signal(signal.SIGINT, disposition))
    lines = proc.stderr.strip().splitlines()
    assert "Traceback" not in proc.stderr and lines[0].startswith("creep-online identify: error:")
    if ignored:     # started with Ctrl-C ignored (a background job): the command's own status
        assert proc.returncode == 2 and len(lines) == 1
    else:           # before, the process died by the signal (status -2) with nothing said
        assert proc.returncode == 130
        assert lines[1:] == ["creep-online: interrupted while exiting (the command had ended, exit status 2)"]


#: The program as ``creep-online identify FILE --json -o MODEL`` runs it, reporting from an exit handler (these run
#: during the interpreter's shutdown, after the command returned) whether the objects the run created are frozen.
_REPORT_AT_EXIT = """
import atexit, gc, sys
atexit.register(lambda: print("frozen at exit:", gc.get_freeze_count() > 0, file=sys.stderr))
sys.argv = ["creep-online", "identify", sys.argv[1], "--json", "-o", sys.argv[2]]
from creep_online.cli import console
console()
"""


def test_the_shutdown_skips_the_collector_and_keeps_the_output_and_exit_handlers(loadcell_csv, tmp_path):
    """After a command, the interpreter's final garbage-collector passes skip what the run loaded (numba's and
    scipy's objects: ~0.1 s of CPU); exit handlers still run, the JSON on stdout and the model file are whole."""
    import subprocess
    import sys
    model_file = tmp_path / "model.json"
    proc = subprocess.run([sys.executable, "-c", _REPORT_AT_EXIT, str(loadcell_csv), str(model_file)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "frozen at exit: True"
    out = json.loads(proc.stdout)
    assert out["model_file"] == str(model_file) and out["samples"] > 0
    saved = json.loads(model_file.read_text())
    assert saved["model"]["alpha"] == out["alpha"] and saved["fitted"]["fit_percent"] == out["fit_percent"]
