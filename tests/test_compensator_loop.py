"""The closed loop over a real pty: hil_sim --command-input in its own process applies the commands it
receives (command frames, parsed like sample frames), and ``creep-online demo --compensate`` end to end."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from creep_online.effects.forward import simulate_with_effects
from creep_online.io.frames import encode_command
from creep_online.io import open_source
from creep_online.model import CreepModel
from creep_online.online.compensator import CreepCompensator
from creep_online.simulate import simulate
from hil_sim.harness import PlantProcess

REPO = Path(__file__).resolve().parents[1]
RATE = 10_000.0


def send_commands(plant, cmd: np.ndarray, rate: float = RATE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Write every command frame to the plant's pty (non-blocking) while reading its samples: (seq, u, y)."""
    n = cmd.size
    src = open_source(f"serial:{plant.port}?rate={rate!r}&format=binary")
    fd = os.open(plant.port, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)
    pending = bytearray(b"".join(encode_command(k, cmd[k]) for k in range(n)))
    seq, u, y = [], [], []
    deadline = time.monotonic() + 60
    try:
        while (not seq or seq[-1] < n - 1) and time.monotonic() < deadline:
            if pending:
                try:
                    del pending[:os.write(fd, pending)]
                except BlockingIOError:
                    pass
            for s in src.read(0.01):
                seq.append(s.seq)
                u.append(s.u)
                y.append(s.y)
    finally:
        os.close(fd)
        src.close()
    return np.array(seq), np.array(u), np.array(y)


def test_plant_applies_the_commands_and_the_output_follows_the_reference():
    """2 s at 10 kHz: every sample's applied input is the command sent for it (unless the ledger counts it
    late), the plant's output is the exact simulator's for the applied input, and with the true model
    the output is the shaped reference after the transient."""
    n = int(2 * RATE)
    with PlantProcess(["--rate", repr(RATE), "--duration", "2", "--command-input", "--noise", "0",
                       "--linger", "1"]) as plant:
        truth = CreepModel(**plant.ready["model"])
        comp = CreepCompensator(1 / RATE, truth)
        t = np.arange(n) / RATE
        r = np.where(t >= 0.1, 1.0, 0.0) - np.where(t >= 1.0, 0.5, 0.0)
        cmd, shaped = np.empty(n), np.empty(n)
        for k in range(n):           # feedforward: all commands can be computed ahead
            shaped[k] = comp.shaped_reference
            cmd[k] = comp.command(r[k])
        seq, u, y = send_commands(plant, cmd)
        ledger = plant.wait_event("end", timeout=20)["ledger"]
    assert seq.size == n and np.array_equal(seq, np.arange(n))
    wrong = np.abs(u - cmd) > 1e-6            # the wire carries 1e-6 per LSB
    assert ledger["crc_errors"] == 0 and ledger["commands"] == n - ledger["stale"]
    assert int(wrong.sum()) <= ledger["late_samples"]
    y_sim = simulate(truth, t, u)
    lsb = 10.0 / 2 ** 20
    assert np.max(np.abs(y - y_sim)) < 1e-4 + lsb      # the plant: SOE to ~1e-5 of the range, plus the ADC
    if ledger["late_samples"] == 0:                    # on time (a loaded machine may hold a few samples)
        settled = (t > 0.12) & ~((t >= 1.0) & (t < 1.02))
        assert np.max(np.abs(y - shaped)[settled]) < 1e-4 + lsb


def run_demo(tmp_path: Path, *flags: str) -> tuple[subprocess.CompletedProcess, Path]:
    """``creep-online demo --compensate FLAGS --quiet`` in its own process; (the run, its report folder)."""
    report = tmp_path / "rep"
    proc = subprocess.run([sys.executable, "-m", "creep_online", "demo", "--compensate", *flags, "--report",
                           str(report), "--quiet"], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=300, cwd=tmp_path)
    return proc, report


def test_demo_compensate_writes_the_compensation_report(tmp_path):
    proc, report = run_demo(tmp_path, "--duration", "5", "--period", "1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "creep error" in proc.stdout
    summary = json.loads((report / "summary.json").read_text())
    c = summary["compensation"]
    assert c["model_changes"] >= 1 and c["first_model_t"] < 2.0
    measured, uncomp = c["creep_error_compensated"], c["creep_error_uncompensated_simulated"]
    assert math.isfinite(measured["rms"]) and uncomp["rms"] > 5 * measured["rms"]
    for name in ("report.html", "compensation.png", "fit.png"):
        assert (report / name).is_file(), name


def test_command_input_refuses_what_it_cannot_do_in_one_line():
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for extra, message in ((["--transport", "serial-ascii"], "needs --transport serial-binary"),
                           (["--faults", "drop=2"], "cannot be combined with --faults"),
                           (["--drift", "beta=1"], "--drift takes alpha=..,b=..")):
        proc = subprocess.run([sys.executable, "-m", "hil_sim", "--command-input", *extra],
                              capture_output=True, text=True, env=env, timeout=120)
        assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1


def test_command_frames_survive_garbage_and_bit_flips_on_a_real_pty():
    """The plant's side parses commands with the sample parser: garbage skipped and counted, a corrupt
    frame dropped (CRC), the rest applied at their sample numbers; stale and non-command frames counted."""
    from creep_online.io.frames import encode_binary
    from hil_sim.command_runner import CommandRunner
    from hil_sim.links import PtyLink
    link = PtyLink()
    try:
        runner = CommandRunner(CreepModel(0.1, 1e-4, 1e-8, 1.0), RATE, 100, link, start_timeout=5.0)
        bad = bytearray(encode_command(3, 0.3))
        bad[10] ^= 0x04
        wire = (b"S\x01\x02garbage" + encode_command(0, 0.1) + encode_command(1, 0.2) + bytes(bad)
                + encode_binary(7, 1.0, 2.0) + encode_command(4, 0.4) + encode_command(500, 9.0))
        fd = os.open(link.tty, os.O_WRONLY | os.O_NOCTTY)
        try:
            os.write(fd, wire)
        finally:
            os.close(fd)
        assert runner.wait_first_command()
        deadline = time.monotonic() + 5
        while runner.ledger.commands < 3 and time.monotonic() < deadline:
            runner._take_commands(0.05)
    finally:
        link.close()
    led = runner.ledger
    assert (led.commands, led.crc_errors, led.other_frames, led.stale) == (3, 1, 1, 1)
    assert led.garbage_bytes >= 10
    np.testing.assert_allclose(runner.cmd[[0, 1, 4]], [0.1, 0.2, 0.4], atol=1e-6)   # 1e-6 per LSB
    assert np.isnan(runner.cmd[[2, 3, 5]]).all()


@pytest.mark.long
def test_demo_compensate_with_hysteresis_compensates_loop_and_creep(tmp_path):
    """``demo --compensate --effects hysteresis`` (8 s): the live loop and creep compensated on the scan, measured
    over the pty, against creep-only and uncompensated simulated on the same plant."""
    proc, report = run_demo(tmp_path, "--effects", "hysteresis", "--duration", "8")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "hysteresis: 2 Hz triangle scan" in proc.stdout
    h = json.loads((report / "summary.json").read_text())["compensation"]["hysteresis"]
    tr = h["tracking_rms"]
    assert len(h["loop"]["r"]) == 30                       # (hil_sim's loop for a bare --effects hysteresis)
    assert h["live_loop"] is not None and len(h["live_loop"]["w"]) == 8
    # (the demo runs in real time over the pty: on a loaded machine the live loop arrives later in the 8 s, and the
    # ratio fell to 9.8x once; bench_hysteresis_compensation holds the 10x number on recorded scans)
    assert tr["uncompensated_simulated"] > 5 * tr["compensated"]
    assert tr["creep_only_simulated"] > 3 * tr["compensated"]
    assert (report / "compensation.png").is_file()


def test_demo_compensate_refuses_effects_it_cannot_invert(tmp_path):
    proc, _ = run_demo(tmp_path, "--effects", "delay")
    assert proc.returncode == 2 and "cannot be combined with --effects delay" in proc.stderr and "Traceback" not in proc.stderr


def test_command_input_plant_with_hysteresis_over_a_pty():
    """1 s at 10 kHz through ``--effects hysteresis``: the output is the exact simulation of the applied
    commands through the given loop (the JSON form of --effects)."""
    rate, n = 10_000.0, 10_000
    loop = {"r": [0.05, 0.15, 0.3], "w": [0.2, 0.1, 0.05]}
    with PlantProcess(["--rate", repr(rate), "--duration", "1", "--command-input", "--noise", "0",
                       "--effects", json.dumps({"hysteresis": loop}), "--linger", "1"]) as plant:
        truth = CreepModel(**plant.ready["model"])
        assert plant.ready["effects"] == {"hysteresis": loop}
        t = np.arange(n) / rate
        cmd = 0.4 * (1 - np.cos(2 * np.pi * 3.0 * t))
        seq, u, y = send_commands(plant, cmd, rate)
    assert np.array_equal(seq, np.arange(n))
    y_sim = simulate_with_effects(truth, t, u, {"hysteresis": {**loop, "initial": "centred"}})
    assert np.max(np.abs(y - y_sim)) < 1e-4 + 10.0 / 2 ** 20


def test_command_input_refuses_other_effects_in_one_line():
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for effects, message in (("drift", "cannot be combined with --effects drift"),
                             ('{"hysteresis": {"r": [0.1, 0.2], "w": [0.1]}}', "--effects hysteresis:")):
        proc = subprocess.run([sys.executable, "-m", "hil_sim", "--command-input", "--effects", effects],
                              capture_output=True, text=True, env=env, timeout=120)
        assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
