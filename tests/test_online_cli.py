"""``creep-online stream``: JSON keys, human output, one-line errors with exit code 2."""
from __future__ import annotations

import json

import numpy as np
import pytest

from creep_online.cli import main
from creep_online.io.csvfile import save_csv
from creep_online.model import CreepModel
from creep_online.simulate import simulate


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    model = CreepModel.from_resonance(0.06, 6.0, 0.1, 0.02)
    h, n = 5e-3, 2400
    t = np.arange(n) * h
    u = np.where(t >= 0.1, 50.0, 0.0)
    y = simulate(model, t, u) + np.random.default_rng(0).normal(0, 0.01, n)
    path = tmp_path_factory.mktemp("stream") / "load.csv"
    save_csv(path, t, u, y)
    return path


def test_stream_json_keys(record, capsys):
    assert main(["stream", "--source", f"csv:{record}", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"alpha", "a1", "a2", "b", "samples", "latency_us", "phase", "quality", "t_c", "skipped"} <= set(out)
    assert set(out["latency_us"]) >= {"p50", "p99", "max"}
    assert out["samples"] == 2400 and out["phase"] == "tracking"
    assert out["alpha"] == pytest.approx(0.06, rel=0.03)


def test_stream_block_and_human_output(record, capsys):
    assert main(["stream", "--source", f"csv:{record}", "--block", "--window", "5"]) == 0
    text = capsys.readouterr().out
    assert "alpha" in text and "samples/s" in text


@pytest.mark.parametrize("spec", ["csv:/nonexistent/x.csv", "csv:", "bogus:thing"])
def test_stream_bad_source_is_one_line_exit_2(spec, capsys):
    assert main(["stream", "--source", spec]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "error" in err


def test_stream_bad_csv_content(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,u,y\n0,1,2\n0.1,1,nan\n" + "".join(f"{0.1 * k},1,2\n" for k in range(2, 40)))
    assert main(["stream", "--source", f"csv:{bad}", "--json"]) == 2
    assert "bad.csv" in capsys.readouterr().err


def test_stream_reports_internal_faults(record, capsys, monkeypatch):
    """A fault injected into the re-fit job (its first call after 5 s of stream raises; the kernels' warm-up runs
    3 s): the stream ends normally, the JSON counts it and lists its event, the human summary names it
    (docs/online.md, "Error contract")."""
    from creep_online.online.trackers.scheduler import Scheduler
    original = Scheduler.after_accept

    def faulty(self, tr, raw):
        if tr.n * tr.h > 5.0 and not getattr(tr, "_injected", False):
            tr._injected = True
            raise ZeroDivisionError("injected")
        return original(self, tr, raw)

    monkeypatch.setattr(Scheduler, "after_accept", faulty)
    assert main(["stream", "--source", f"csv:{record}", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["internal_faults"] == 1 and out["samples"] == 2400
    (ev,) = [ev for ev in out["events"] if ev["kind"] == "internal_fault"]
    assert ev["error"] == "ZeroDivisionError" and ev["recovery"] == "dropped the refit job"
    assert main(["stream", "--source", f"csv:{record}"]) == 0
    text = capsys.readouterr().out
    assert "internal faults: 1" in text and "internal fault at t = " in text and "ZeroDivisionError" in text


@pytest.fixture(scope="module")
def step_record(tmp_path_factory):
    """The paper's experiment: the input at its level from the first sample, the output rising from zero."""
    model = CreepModel.from_resonance(0.02, 300.0, 0.08, 1.8)
    h, n = 1e-4, 30000
    t = np.arange(n) * h
    u = np.ones(n)
    y = simulate(model, t, u) + np.random.default_rng(0).normal(0, 1e-4, n)
    path = tmp_path_factory.mktemp("stream") / "step.csv"
    save_csv(path, t, u, y)
    return path


def test_stream_reads_a_step_at_the_first_sample(step_record, capsys):
    assert main(["stream", "--source", f"csv:{step_record}", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["phase"] == "tracking" and out["start"] == "step" and out["frozen"] is False
    assert out["alpha"] == pytest.approx(0.02, rel=3e-3) and out["b"] == pytest.approx(1.8, rel=3e-3)


def test_unknown_values_are_null_in_the_json_and_empty_in_the_trace(tmp_path, capsys):
    """Not yet estimated is not zero: JSON null, an empty trace cell, "-" in the text."""
    t = np.arange(300) * 1e-4
    short = tmp_path / "short.csv"
    save_csv(short, t, np.ones(t.size), 1e-3 * np.sin(t))      # too short to read the start: nothing estimated
    trace = tmp_path / "trace.csv"
    assert main(["stream", "--source", f"csv:{short}", "--json", "--trace", str(trace)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["phase"] == "buffering" and out["quality"] == "none"
    for key in ("alpha", "a1", "a2", "b", "fn_hz", "zeta", "offset", "t_c", "noise_rms", "residual_rms", "b_rate",
                "alpha_rate"):
        assert out[key] is None, key
    lines = trace.read_text().splitlines()
    header = lines[0].split(",")
    first = lines[1].split(",")
    assert all(first[header.index(k)] == "" for k in ("alpha", "a1", "a2", "b", "fn_hz", "zeta"))
    assert first[header.index("quality")] == "none"
    assert main(["stream", "--source", f"csv:{short}"]) == 0
    assert "alpha  = -" in capsys.readouterr().out
