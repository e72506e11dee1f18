"""CAN sources: python-can virtual bus (in-process), SLCAN over a pty from another process, log replay."""
from __future__ import annotations

import time

import numpy as np
import pytest

can = pytest.importorskip("can", reason="python-can is an optional extra (creep_online[can])")

from creep_online.io import can_frames as cf  # noqa: E402
from creep_online.io import TransportError, open_source  # noqa: E402
from creep_online.errors import DataError  # noqa: E402
from hil_sim import PlantConfig, generate, parse_params, run_virtual_plant  # noqa: E402
from hil_sim.harness import PlantProcess  # noqa: E402

RATE = 10_000.0


def _record(duration=1.0):
    return generate(PlantConfig(parse_params(""), rate=RATE, duration=duration, t_start=0.05, seed=1))


def _collect(src, last_seq, timeout=120.0):
    out = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out += src.read(0.05)
        if out and out[-1].seq >= last_seq:
            return out
    pytest.fail(f"stream did not reach seq {last_seq}: {src.stats.summary()}")


def _check_values(samples, rec, u_tol, y_tol):
    seq = np.array([s.seq for s in samples])
    assert np.all(np.diff(seq) > 0)
    assert np.max(np.abs(np.array([s.u for s in samples]) - rec.u[seq])) <= u_tol
    assert np.max(np.abs(np.array([s.y for s in samples]) - rec.y[seq])) <= y_tol
    assert samples[5].t == pytest.approx(seq[5] / RATE)


@pytest.mark.parametrize("frame,spf,u_tol,y_tol", [("block", 7, 5.1e-7, 5.1e-7), ("pair", 2, 5.1e-7, 5.1e-6),
                                                   ("sample", 1, 5.1e-6, 5.1e-7)])
def test_virtual_bus_all_frame_kinds(frame, spf, u_tol, y_tol):
    rec = _record(0.5)
    ch = f"t_virtual_{frame}"
    src = open_source(f"can:virtual:{ch}?rate={RATE:g}", on_event=None)
    th, runner = run_virtual_plant(rec, RATE, ch, can_frame=frame, realtime=False)
    th.start()
    try:
        samples = _collect(src, runner.n_samples - 1)
    finally:
        runner.stop.set()
        th.join(30)
        src.close()
    assert len(samples) == runner.n_samples
    _check_values(samples, rec, u_tol, y_tol)
    d = src.stats.as_dict()
    assert d["missing"] == d["duplicates"] == d["malformed"] == d["no_input"] == 0


def test_virtual_bus_faults_counted_in_samples():
    rec = _record(1.0)
    ch = "t_virtual_faults"
    src = open_source(f"can:virtual:{ch}?rate={RATE:g}", on_event=None)
    th, runner = run_virtual_plant(rec, RATE, ch, can_frame="block", realtime=False,
                                   faults="drop=2,dup=2,reorder=2", seed=5)
    th.start()
    try:
        samples = _collect(src, runner.n_samples - 1)
    finally:
        th.join(30)
        src.close()
    led = runner.ledger.to_dict()
    assert led["counts"]["drop"] == 2 and led["counts"]["dup"] == 2 and led["counts"]["reorder"] == 2
    s = src.stats.as_dict()
    assert s["missing"] == 2 * 7 and s["gaps"] == 2
    assert s["duplicates"] == 2 * 7 and s["reordered"] == 2 * 7
    _check_values(samples, rec, 5.1e-7, 5.1e-7)


@pytest.mark.parametrize("frame", ["pair", "block"])
def test_slcan_across_processes_at_10khz(frame):
    """hil_sim acts as an SLCAN adapter on a pty; python-can's slcan interface reads it here."""
    rec = _record(1.0)
    args = ["--rate", str(RATE), "--duration", "1", "--t-start", "0.05", "--seed", "1", "--transport", "slcan",
            "--can-frame", frame, "--faults", "drop=2,dup=1,reorder=1", "--linger", "5"]
    with PlantProcess(args) as plant:
        n = plant.ready["samples"]
        src = open_source(f"can:slcan:{plant.port}?rate={RATE:g}", on_event=None)
        try:
            samples = _collect(src, n - 1)
            led = plant.wait_event("end", timeout=60)["ledger"]
        finally:
            src.close()
    spf = led["samples_per_frame"]
    s = src.stats.as_dict()
    assert s["missing"] == 2 * spf and s["duplicates"] == spf and s["reordered"] == spf
    assert s["malformed"] == 0 and s["no_input"] == 0
    _check_values(samples, rec, 5.1e-7, 5.1e-6)


def test_slcan_disconnect_and_reconnect():
    args = ["--rate", "4000", "--duration", "4", "--transport", "slcan", "--can-frame", "pair", "--fast",
            "--faults", "disconnect=1,disconnect_s=0.3", "--linger", "5"]
    with PlantProcess(args) as plant:
        n = plant.ready["samples"]
        src = open_source(f"can:slcan:{plant.port}?rate=4000", on_event=None)
        try:
            _collect(src, n - 1)
            led = plant.wait_event("end", timeout=60)["ledger"]
        finally:
            src.close()
    assert src.stats.disconnects == 1 and src.stats.reconnects == 1
    assert src.stats.missing == led["disconnect_lost_samples"]


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".csv"])
def test_log_replay(tmp_path, suffix):
    rec = _record(0.3)
    path = tmp_path / f"session{suffix}"
    n = rec.t.size - rec.t.size % 2
    gen = (np.concatenate([[0], np.cumsum(np.diff(rec.u) != 0)]) % 16).astype(int)
    with can.Logger(str(path)) as log:
        ts = 1000.0
        for k in range(0, n, 2):
            msgs = []
            if k % 100 == 0 or gen[k] != gen[k - 1] or gen[k + 1] != gen[k]:
                msgs += [cf.encode_input(int(gen[k]), rec.u[k]), cf.encode_input(int(gen[k + 1]), rec.u[k + 1])]
            if k == 600:
                continue                            # a frame lost on the recorded bus
            msgs.append(cf.encode_pair(k, int(gen[k]), int(gen[k + 1]), rec.y[k], rec.y[k + 1]))
            for fid, data, fd in msgs:
                log(can.Message(timestamp=ts, arbitration_id=fid, data=data, is_extended_id=False))
                ts += 1e-4
    src = open_source(f"canlog:{path}?rate={RATE:g}", on_event=None)
    samples = list(src)
    assert src.ended
    assert len(samples) == n - 2
    assert src.stats.missing == 2 and src.stats.sequence.gaps == 1
    _check_values(samples, rec, 5.1e-7, 5.1e-6)


def test_can_spec_errors_are_one_line():
    with pytest.raises(TransportError, match="rate"):
        open_source("can:virtual:x")
    with pytest.raises(DataError, match="no such CAN log"):
        open_source("canlog:/nonexistent/file.asc?rate=10")
    with pytest.raises(DataError, match="interface and a channel"):
        open_source("can:slcan")
    with pytest.raises(TransportError, match="cannot open"):
        open_source("can:slcan:/dev/does-not-exist?rate=10")
