"""``demo --scenario``: errors measured against the plant valid at each moment, the changes marked."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from creep_online.commands.demo import DRIFT, PAYLOAD_MASS, scenario_plan
from creep_online.reports.demo_report import plant_truth

REPO = Path(__file__).resolve().parents[1]
START = {"alpha": 0.12, "a1": 4e-4, "a2": 1.4e-7, "b": 2.5}


def test_the_plant_at_each_moment():
    payload = scenario_plan("payload", START, 10.0, 9.9999)
    assert plant_truth(payload, 4.99) == START
    assert plant_truth(payload, 5.0)["a2"] == pytest.approx(START["a2"] * (1 + PAYLOAD_MASS))
    assert payload["changes"][0]["t"] == 5.0 and "payload" in payload["changes"][0]["what"]
    drift = scenario_plan("drift", START, 10.0, 10.0)
    assert plant_truth(drift, 0.0) == START
    half = plant_truth(drift, 5.0)
    assert half["alpha"] == pytest.approx(START["alpha"] * (1 + DRIFT[0] / 2))
    assert half["b"] == pytest.approx(START["b"] * (1 + DRIFT[1] / 2)) and half["a2"] == START["a2"]
    assert plant_truth(scenario_plan("stationary", START, 10.0, 10.0), 7.0) == START


@pytest.mark.long
def test_payload_demo_judges_the_estimate_against_the_plant_of_the_moment(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "creep_online", "demo", "--scenario", "payload", "--duration", "7",
                           "--report", str(tmp_path / "rep")], capture_output=True, text=True, env=env, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    live = [(float(m.group(1)), float(m.group(2))) for m in
            re.finditer(r"t=\s*([0-9.]+)s .*?fn=[0-9.]+Hz \(([-+0-9.]+)%\)", proc.stderr)]
    before = [err for t, err in live if 1.5 < t < 3.4]       # settled, before the payload at 3.5 s
    assert before and all(abs(err) < 2.0 for err in before), proc.stderr   # not the +22 % of the final plant
    assert "change  : at t = 3.5 s, payload" in proc.stdout
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["scenario"]["changes"][0]["t"] == 3.5
    assert summary["truth"]["fn_hz"] == pytest.approx(
        plant_truth(summary["scenario"], 7.0)["a2"] ** -0.5 / (2 * 3.141592653589793), rel=1e-9)
    assert abs(summary["errors"]["fn_rel"]) < 0.02            # the final estimate, against the plant at the end
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "payload" in html and "valid at its moment" in html
