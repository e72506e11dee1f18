"""End-to-end across processes: hil_sim injects each fault, the serial source counts it exactly.

The plant runs in its own process (``python -m hil_sim``) on a real
pseudo-terminal; the source opens it with pyserial here. For every fault kind
and both frame formats: no crash, every counter equals the plant's ledger,
every delivered sample is exactly what the plant produced, and the online
estimator fed with the delivered samples still converges to the true model.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from creep_online.io import open_source
from hil_sim.harness import PlantProcess
from hil_sim.plant import PlantConfig, generate, parse_params

RATE = 10_000.0
DURATION = 2.0
T_START = 0.1
SEED = 3


def truth_record(duration=DURATION):
    return generate(PlantConfig(parse_params(""), rate=RATE, duration=duration, t_start=T_START, seed=SEED))


def stream(fmt: str, faults: str, extra: list[str] | None = None, fast: bool = True, stall: float = 0.75,
           duration: float = DURATION):
    args = ["--rate", str(RATE), "--duration", str(duration), "--t-start", str(T_START), "--seed", str(SEED),
            "--transport", f"serial-{fmt}", "--wait-start", "--faults", faults, "--linger", "5"]
    if fast:
        args.append("--fast")
    n = int(RATE * duration)
    samples = []
    with PlantProcess(args + (extra or [])) as plant:
        src = open_source(f"serial:{plant.port}?rate={RATE:g}&start=S&stall={stall}", on_event=None)
        try:
            deadline = time.monotonic() + 180
            while time.monotonic() < deadline:
                got = src.read(0.05)
                samples += got
                if samples and samples[-1].seq == n - 1:
                    break
            else:
                pytest.fail(f"stream did not finish: {src.stats.summary()}")
            ledger = plant.wait_event("end", timeout=60)["ledger"]
        finally:
            src.close()
    return samples, src.stats, ledger


def check_samples(fmt, samples, rec):
    seq = np.array([s.seq for s in samples])
    assert np.all(np.diff(seq) > 0), "delivered out of order or twice"
    u = np.array([s.u for s in samples])
    y = np.array([s.y for s in samples])
    tol = 0.0 if fmt == "ascii" else 5.1e-7
    assert np.max(np.abs(u - rec.u[seq])) <= tol
    assert np.max(np.abs(y - rec.y[seq])) <= tol
    return u, y, seq


def check_converges(u, y, seq, rec):
    """The estimator fed as the feed loop feeds it: each run of delivered samples, gap(n) for the lost ones."""
    from creep_online.online import OnlineEstimator
    est = OnlineEstimator(1.0 / RATE)
    breaks = np.flatnonzero(np.diff(seq) > 1) + 1
    for a, b in zip(np.r_[0, breaks], np.r_[breaks, seq.size]):
        if a:
            est.gap(int(seq[a] - seq[a - 1] - 1))
        est.update_block(u[a:b], y[a:b])
    m = est.model
    assert m is not None, est.estimate
    true = parse_params("")
    assert abs(m.alpha - true.alpha) < 0.01
    assert abs(m.fn / true.fn - 1) < 0.03
    assert abs(m.b / true.b - 1) < 0.03


def expected_zero(stats, except_: set[str]):
    d = stats.as_dict()
    for k in ("crc_errors", "malformed", "garbage_bytes", "missing", "gaps", "duplicates", "reordered",
              "late", "resets", "disconnects", "reconnects", "stalls"):
        if k not in except_:
            assert d[k] == 0, (k, d)


@pytest.fixture(scope="module")
def rec():
    return truth_record()


@pytest.mark.parametrize("fmt", ["ascii", "binary"])
@pytest.mark.parametrize("kind", ["drop", "dup", "reorder", "bitflip", "garbage"])
def test_fault_counted_exactly(fmt, kind, rec):
    samples, stats, led = stream(fmt, f"{kind}=4")
    c = led["counts"]
    assert c[kind] == 4
    s = stats.as_dict()
    if kind == "drop":
        assert s["missing"] == 4 and s["gaps"] == 4
        expected_zero(stats, {"missing", "gaps"})
    elif kind == "dup":
        assert s["duplicates"] == 4
        expected_zero(stats, {"duplicates"})
    elif kind == "reorder":
        assert s["reordered"] == 4
        expected_zero(stats, {"reordered"})
    elif kind == "bitflip":
        assert s["crc_errors"] == 4 and s["missing"] == 4 and s["gaps"] == 4
        expected_zero(stats, {"crc_errors", "missing", "gaps"})
    elif kind == "garbage":
        assert s["garbage_bytes"] == led["garbage_bytes"]
        assert s["malformed"] == (4 if fmt == "ascii" else 0)
        expected_zero(stats, {"garbage_bytes", "malformed"})
    assert len(samples) == int(RATE * DURATION) - s["missing"]
    u, y, seq = check_samples(fmt, samples, rec)
    check_converges(u, y, seq, rec)


@pytest.mark.parametrize("fmt", ["ascii", "binary"])
def test_stall_counted(fmt, rec):
    samples, stats, led = stream(fmt, "stall=2,stall_s=2.0")
    assert led["counts"]["stall"] == 2
    assert stats.stalls == 2
    expected_zero(stats, {"stalls"})
    u, y, seq = check_samples(fmt, samples, rec)
    check_converges(u, y, seq, rec)


@pytest.mark.parametrize("fmt", ["ascii", "binary"])
def test_disconnect_reconnects(fmt):
    rec = truth_record(4.0)
    samples, stats, led = stream(fmt, "disconnect=2,disconnect_s=0.3", duration=4.0)
    assert led["counts"]["disconnect"] == 2
    assert stats.disconnects == 2 and stats.reconnects == 2
    assert stats.missing == led["disconnect_lost_samples"] and stats.sequence.gaps == 2
    expected_zero(stats, {"disconnects", "reconnects", "missing", "gaps"})
    u, y, seq = check_samples(fmt, samples, rec)
    check_converges(u, y, seq, rec)


def test_all_faults_together_realtime():
    """Every fault at once, paced in real time at 10 kHz."""
    rec = truth_record(3.0)
    faults = "drop=3,dup=3,reorder=3,bitflip=3,garbage=3,stall=1,disconnect=1,stall_s=1.5,disconnect_s=0.3"
    samples, stats, led = stream("binary", faults, fast=False, duration=3.0)
    s = stats.as_dict()
    assert led["counts"] == {"drop": 3, "dup": 3, "reorder": 3, "bitflip": 3, "garbage": 3, "stall": 1,
                             "disconnect": 1, "badheader": 0}, led
    assert s["duplicates"] == 3 and s["reordered"] == 3 and s["crc_errors"] == 3, (s, led)
    assert s["garbage_bytes"] == led["garbage_bytes"] and s["malformed"] == 0
    assert s["stalls"] == 1 and s["disconnects"] == 1 and s["reconnects"] == 1
    assert s["missing"] == 3 + 3 + led["disconnect_lost_samples"]
    assert s["gaps"] == 3 + 3 + 1
    u, y, seq = check_samples("binary", samples, rec)
    check_converges(u, y, seq, rec)


def test_reconnect_off_exits_with_clear_message():
    from creep_online.io.sources import TransportError
    args = ["--rate", "2000", "--duration", "10", "--transport", "serial-ascii", "--wait-start", "--fast",
            "--faults", "disconnect=1,disconnect_s=2"]
    with PlantProcess(args) as plant:
        src = open_source(f"serial:{plant.port}?start=S&reconnect=0", on_event=None)
        with pytest.raises(TransportError, match="port disappeared"):
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                src.read(0.05)
        src.close()
    assert src.stats.disconnects == 1


def test_plant_killed_then_restarted_reconnects(tmp_path):
    """The plant process dies; a new one on the same link name is picked up again."""
    link = str(tmp_path / "amp")
    args = ["--rate", "2000", "--duration", "30", "--transport", "serial-ascii", "--link", link]
    events = []
    with PlantProcess(args) as plant:
        src = open_source(f"serial:{plant.port}", on_event=events.append)
        first = []
        while len(first) < 200:
            first += src.read(0.05)
        plant.stop()
    deadline = time.monotonic() + 60
    while src.stats.disconnects == 0 and time.monotonic() < deadline:
        src.read(0.05)
    assert src.stats.disconnects == 1
    with PlantProcess(args):
        second = []
        deadline = time.monotonic() + 120
        while len(second) < 200 and time.monotonic() < deadline:
            second += src.read(0.05)
    src.close()
    assert src.stats.reconnects == 1 and len(second) >= 200
    assert any("disappeared" in e for e in events) and any("reconnected" in e for e in events)
    assert src.stats.sequence.resets == 1 and src.stats.sequence.duplicates == 0
