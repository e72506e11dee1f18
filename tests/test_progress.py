"""Progress on a terminal: shown under a real pseudo-terminal, fitted to its width, erased at the end; silent with
--json or a pipe. The terminal is emulated (pyte) to check what the user sees: no status lines stacked up."""
import fcntl
import json
import os
import pty
import re
import struct
import subprocess
import sys
import termios
import time

import pyte
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


def _run_in_pty(args: list[str], timeout: float = 120.0, columns: int = 80, cwd=None) -> tuple[int, str]:
    """Run the CLI with stdout and stderr on a real pseudo-terminal ``columns`` wide; (exit code, what it wrote)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen([sys.executable, "-m", "creep_online", *args], stdin=subprocess.DEVNULL,
                            stdout=slave, stderr=slave, close_fds=True, env=env, cwd=cwd)
    os.close(slave)
    shown = read_until_closed(master, time.monotonic() + timeout)
    os.close(master)
    return proc.wait(timeout=10), shown.decode(errors="replace")


def _screen(raw: str, columns: int) -> list[str]:
    """What a terminal ``columns`` wide shows after ``raw`` (its lines, trailing blanks cut; a tall screen so
    that nothing scrolls away)."""
    screen = pyte.Screen(columns, 400)
    pyte.Stream(screen).feed(raw)
    return [line.rstrip() for line in screen.display if line.strip()]


def _drawn_lines(raw: str) -> list[str]:
    """Each line as drawn: the text between carriage returns, newlines and cursor moves, escapes removed."""
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "\r", raw)
    return [seg for seg in re.split(r"[\r\n]", plain) if seg]


def test_a_stage_is_drawn_in_place_and_erased_on_a_terminal():
    master, slave = pty.openpty()
    with os.fdopen(slave, "w") as term:
        p = Progress(True, stream=term, width=40)
        assert p.tty
        p.stage("fitting drift")
        time.sleep(0.8)                      # the live display refreshes the elapsed time
        p.close()
    text = read_until_closed(master).decode()
    os.close(master)
    assert "fitting drift" in text and re.search(r"fitting drift +0\.[5-9] s", text)  # a refresh with the time
    assert all(len(line) <= 40 for line in _drawn_lines(text))
    assert _screen(text, 40) == []                                   # erased: the output that follows starts clean


def test_a_long_line_is_cut_to_the_terminal_width():
    master, slave = pty.openpty()
    with os.fdopen(slave, "w") as term:
        p = Progress(True, stream=term, width=30)
        p.show("x" * 200)
        time.sleep(0.4)
        p.close()
    text = read_until_closed(master).decode()
    os.close(master)
    assert "xxxx" in text and all(len(line) <= 30 for line in _drawn_lines(text))


def test_disabled_progress_writes_nothing(tmp_path):
    path = tmp_path / "log"
    with open(path, "w") as log:
        p = Progress(False, stream=log)
        p.stage("anything")
        p.show("anything", force=True)
        p.close()
    assert path.read_text() == ""


@pytest.mark.parametrize("columns", [80, 120])
def test_diagnose_shows_its_stages_on_a_terminal_and_leaves_only_its_table(record, columns):
    code, shown = _run_in_pty(["diagnose", record.name, "--effects", "drift,leakage"], columns=columns,
                              cwd=record.parent)
    assert code == 0, shown
    assert "base model" in shown and "[1/2] fitting the base model + drift" in shown
    assert "[2/2] fitting the base model + leakage" in shown
    assert "verdict:" in shown.split("[2/2]")[-1]             # the table comes after the progress
    status = shown[:shown.index("verdict:")].rsplit("\x1b[?25h", 1)[0]   # everything the live display drew
    assert all(len(line) <= columns for line in _drawn_lines(status))
    screen = _screen(shown, columns)
    assert not any("fitting" in line or "diagnose " in line for line in screen), screen   # none stacked up
    assert any(line.startswith("verdict:") for line in screen)


def test_a_live_stream_shows_a_status_line_on_a_terminal(tmp_path):
    from hil_sim.experiments import NANOPOSITIONER
    t, u, y, _ = NANOPOSITIONER.run(seed=1)
    path = tmp_path / "live.csv"
    save_csv(path, t[:30000], u[:30000], y[:30000])          # 3 s, replayed in real time
    code, shown = _run_in_pty(["stream", "--source", "csv:live.csv?realtime=1"], timeout=120, columns=80,
                              cwd=tmp_path)
    assert code == 0, shown
    assert re.search(r"stream csv:live.csv\?realtime=1: \d+ samples, t = [0-9.]+ s", shown)   # the live line
    assert all(len(line) <= 80 for line in _drawn_lines(shown.split("\x1b[?25h")[0]))
    screen = _screen(shown, 80)
    assert not any(line.lstrip().startswith(("stream csv:", "\u280b")) for line in screen), screen
    assert any("phase" in line for line in screen)            # the final report, on a clean screen


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
