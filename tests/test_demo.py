"""``creep-online demo`` end to end: a real plant process, a real pty, the estimator, the report."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_demo_runs_without_a_tty_and_writes_a_report(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    report = tmp_path / "rep"
    proc = subprocess.run([sys.executable, "-m", "creep_online", "demo", "--duration", "3", "--report", str(report),
                           "--faults", "drop=2,bitflip=2,garbage=2"],
                          capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "creep-online demo: summary" in proc.stdout
    assert "alpha" in proc.stdout and "report" in proc.stdout
    assert "kS/s" in proc.stderr                      # progress lines, written as plain lines (no TTY)
    assert "\r" not in proc.stderr
    summary = json.loads((report / "summary.json").read_text())
    assert summary["samples_received"] == summary["samples_sent_by_plant"] - 4
    s = summary["source_stats"]
    assert s["missing"] == 4 and s["crc_errors"] == 2 and s["garbage_bytes"] == summary["plant_ledger"]["garbage_bytes"]
    e = summary["errors"]
    assert abs(e["alpha_abs"]) < 0.01 and abs(e["fn_rel"]) < 0.03 and abs(e["b_rel"]) < 0.03
    for name in ("report.html", "fit.png", "convergence.png", "latency.png"):
        assert (report / name).is_file(), name


def test_demo_json_summary(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "creep_online", "demo", "--duration", "1.5", "--json",
                           "--transport", "serial-ascii", "--report", str(tmp_path / "r")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    assert "demo:" not in proc.stderr                 # --json: no live progress, even without --quiet
    assert out["samples_received"] == 15000 and out["source_stats"]["missing"] == 0
    assert set(out["latency_us"]) == {"p50", "p99", "max"}
