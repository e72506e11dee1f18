"""Progress on a terminal (issue 9 item 6): shown under a real pseudo-terminal, silent with --json or a pipe."""
import json
import os
import pty
import subprocess
import sys
import time

import pytest

from creep_online.commands._progress import Progress
from creep_online.io import save_csv
from hil_sim.experiments import LOAD_CELL
from ptyio import read_until_closed


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    t, u, y, _ = LOAD_CELL.run(10.0, seed=2)
    path = tmp_path_factory.mktemp("progress") / "lc.csv"
    save_csv(path, t, u, y)
    return path


def _run_in_pty(args: list[str], cwd=None, timeout: float = 120.0) -> tuple[int, str]:
    """Run the CLI with stdout and stderr on a real pseudo-terminal; return (exit code, what it showed)."""
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "creep_online", *args], stdin=subprocess.DEVNULL,
                            stdout=slave, stderr=slave, close_fds=True, cwd=cwd)
    os.close(slave)
    shown = read_until_closed(master, time.monotonic() + timeout)
    os.close(master)
    return proc.wait(timeout=10), shown.decode(errors="replace")


def test_a_stage_is_drawn_in_place_and_erased_on_a_terminal():
    master, slave = pty.openpty()
    with os.fdopen(slave, "w") as term:
        p = Progress(True, stream=term, width=40)
        assert p.tty
        p.stage("fitting drift")
        time.sleep(0.6)                      # the ticker adds the elapsed time
        p.close()
    shown = read_until_closed(master)
    os.close(master)
    text = shown.decode()
    assert text.startswith("\r") and "fitting drift" in text
    assert " s" in text.split("fitting drift", 2)[-1]          # a refresh with the elapsed time
    assert text.endswith("\r" + " " * 40 + "\r")               # erased: the output that follows starts clean


def test_disabled_progress_writes_nothing(tmp_path):
    path = tmp_path / "log"
    with open(path, "w") as log:
        p = Progress(False, stream=log)
        p.stage("anything")
        p.show("anything", force=True)
        p.close()
    assert path.read_text() == ""


def test_diagnose_shows_its_stages_on_a_terminal(record):
    # the file by a short name: the status line (100 columns) would cut a long temporary path's stage off
    code, shown = _run_in_pty(["diagnose", record.name, "--effects", "drift,leakage"], cwd=record.parent)
    assert code == 0, shown
    assert "base model" in shown and "[1/2] fitting the base model + drift" in shown
    assert "[2/2] fitting the base model + leakage" in shown
    assert "verdict:" in shown.split("[2/2]")[-1]             # the table comes after the progress


def test_json_on_a_terminal_shows_no_progress(record):
    code, shown = _run_in_pty(["diagnose", str(record), "--effects", "drift", "--json"])
    assert code == 0, shown
    assert "fitting" not in shown
    assert json.loads(shown)["verdict"]


def test_a_pipe_gets_no_progress(record):
    proc = subprocess.run([sys.executable, "-m", "creep_online", "identify", str(record)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "" and "alpha" in proc.stdout
