"""The simulated plant with hysteresis (``hil_sim.play_stage``) in the closed loops: in process
(``hil_sim.closed_loop``) and over a real pty (``python -m hil_sim --command-input --effects hysteresis``).

Reference: the library's exact simulation ``simulate_with_effects`` (the same Prandtl-Ishlinskii operator, the
creep plant's SOE simulation) on the commands the plant applied.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from creep_online.effects import loop_width
from creep_online.effects.forward import simulate_with_effects
from creep_online.effects.hysteresis import hysteresis_input, play_operators
from creep_online.io import open_source
from creep_online.io.frames import encode_command
from creep_online.model import CreepModel, ExtendedModel
from creep_online.online import OnlineEstimator
from creep_online.online.compensator import CreepCompensator
from hil_sim.closed_loop import run_closed_loop
from hil_sim.harness import PlantProcess
from hil_sim.hysteresis_plants import random_loop
from hil_sim.play_stage import PlayStage, width_scale

REPO = Path(__file__).resolve().parents[1]
H = 1e-4


@pytest.mark.parametrize("seed", range(4))
def test_play_stage_in_blocks_is_the_library_operator(seed):
    rng = np.random.default_rng(seed)
    u = np.cumsum(rng.normal(0, 0.3, 5000)) + np.repeat(rng.uniform(-5, 5, 50), 100)
    loop = random_loop(rng, stroke=10.0)
    stage = PlayStage(loop)
    cuts = np.sort(rng.choice(np.arange(1, u.size), 20, replace=False))
    v = np.concatenate([stage.step_block(part) for part in np.split(u, cuts)])
    np.testing.assert_allclose(v, hysteresis_input(u, loop["r"], loop["w"], loop["initial"]), rtol=0, atol=1e-12)
    # a per-sample weight scale scales the loop's term only: the plays do not depend on the weights
    scale = np.linspace(1.0, 1.4, u.size)
    v2 = PlayStage(loop).step_block(u, scale)
    plays = play_operators(u, np.array(loop["r"]),
                           initial=u[0] + {"centred": 0, "ascending": -1, "descending": 1}[loop["initial"]]
                           * np.array(loop["r"]))
    np.testing.assert_allclose(v2, u + scale * (np.array(loop["w"]) @ plays), atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_width_scale_grows_the_loop_width_linearly(seed):
    rng = np.random.default_rng(seed)
    loop = random_loop(rng, stroke=20.0)
    s = width_scale(loop, 20.0, 0.3, 101)
    widths = [loop_width(loop["r"], np.array(loop["w"]) * k, 20.0) for k in s]
    np.testing.assert_allclose(widths, widths[0] * (1 + 0.3 * np.linspace(0, 1, 101)), rtol=1e-12)
    assert s[0] == pytest.approx(1.0)


def test_closed_loop_plant_with_hysteresis_is_the_exact_simulation_and_known_model_tracks():
    """``known``: the true loop and creep inverted; the loop's output is simulate_with_effects of the commands,
    and it follows the shaped reference to 1e-3 of the stroke where uncompensated misses by the loop."""
    plant = CreepModel.from_resonance(0.15, 300.0, 0.2, 2.0)
    loop = {**random_loop(np.random.default_rng(5), stroke=1.0, width=0.1), "initial": "centred"}
    t = np.arange(20_000) * H
    r = 2.0 * 0.5 * (1 - np.cos(2 * np.pi * 2.0 * t))
    comp = CreepCompensator(H, bandwidth_hz=150.0)
    rec = run_closed_loop(t, r, plant, "known", compensator=comp, hysteresis=loop, noise=0.0)
    np.testing.assert_allclose(rec.y_clean, simulate_with_effects(plant, t, rec.u, {"hysteresis": loop}),
                               atol=1e-5 * np.ptp(r))
    shaped = CreepCompensator(H, ExtendedModel(plant, {"hysteresis": loop}), bandwidth_hz=150.0)
    target = np.array([(shaped.command(x), shaped.shaped_reference)[1] for x in r])
    late = t > 0.5
    assert np.max(np.abs(rec.y_clean - target)[late]) < 1e-3 * np.ptp(r)
    un = run_closed_loop(t, r, plant, "uncompensated", hysteresis=loop, noise=0.0)
    assert np.sqrt(np.mean((un.y_clean - target)[late] ** 2)) > 0.02 * np.ptp(r)


def test_adaptive_closed_loop_takes_the_live_loop():
    """``adaptive`` with the hysteresis estimator: the compensator takes ExtendedModels carrying the live loop.
    (Sensor noise 0.25 % of the stroke: an 8-operator loop misses this 30-threshold loop by about 0.3 % of the
    stroke, so on a much cleaner sensor the estimate reads ``degraded`` and the gate gives nothing.)"""
    plant = CreepModel.from_resonance(0.15, 300.0, 0.2, 2.0)
    loop = {**random_loop(np.random.default_rng(5), stroke=1.0, width=0.1), "initial": "centred"}
    t = np.arange(40_000) * H
    levels = np.random.default_rng(1).uniform(0.1, 2.0, 40)
    r = levels[(t / 0.1).astype(int) % 40]
    rec = run_closed_loop(t, r, plant, "adaptive", compensator=CreepCompensator(H, bandwidth_hz=150.0),
                          estimator=OnlineEstimator(H, input_gate=0.0, effects=("hysteresis",)),
                          hysteresis=loop, block=100, noise=5e-3)
    assert rec.models and all(isinstance(m, ExtendedModel) for m in rec.models)


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
    assert np.array_equal(seq, np.arange(n))
    u = np.array(u)
    y_sim = simulate_with_effects(truth, t, u, {"hysteresis": {**loop, "initial": "centred"}})
    assert np.max(np.abs(np.array(y) - y_sim)) < 1e-4 + 10.0 / 2 ** 20


def test_command_input_refuses_other_effects_in_one_line():
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for effects, message in (("drift", "cannot be combined with --effects drift"),
                             ('{"hysteresis": {"r": [0.1, 0.2], "w": [0.1]}}', "--effects hysteresis:")):
        proc = subprocess.run([sys.executable, "-m", "hil_sim", "--command-input", "--effects", effects],
                              capture_output=True, text=True, env=env, timeout=120)
        assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
