"""Reference -> compensator -> plant -> estimator -> compensator, in one process (bench and tests).

``run_closed_loop`` steps a (possibly drifting) plant block by block: the
compensator turns each block of the reference into commands with the model it
holds, the plant (``varying_plant.PlantStream``: per-sample alpha and b)
answers, the estimator learns from (command, noisy output), and the
compensator takes the estimator's model according to ``mode``:

``adaptive``       the estimator's current model after every block, whenever its quality is ``good``
                   (a model the estimator itself calls changing or degraded is not applied);
``frozen``         the first model the estimator calls ``good`` (after 10 s: whatever it has), never again;
``known``          the true initial model from the start (no estimator needed);
``uncompensated``  u = r / g with g the plant's static gain 1 s after a step (b / Gamma(1 + alpha)).

``creep_online.metrics.creep_error`` measures what the issue asks: output minus
reference from the end of the resonance transient after each step to the end of its hold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from creep_online.model import CreepModel
from creep_online.online.compensator import CreepCompensator

from .varying_plant import PlantStream

MODES = ("adaptive", "frozen", "known", "uncompensated")


@dataclass
class LoopRecord:
    """What one closed-loop run produced (noise-free output kept for judging)."""

    t: np.ndarray
    r: np.ndarray
    u: np.ndarray
    y_clean: np.ndarray
    y: np.ndarray
    model_t: list          # times at which the compensator's model changed
    models: list           # the models it took (CreepModel)


def run_closed_loop(t: np.ndarray, r: np.ndarray, plant: CreepModel, mode: str, *,
                    alpha: np.ndarray | None = None, b: np.ndarray | None = None, estimator=None,
                    compensator: CreepCompensator | None = None, noise: float = 2e-4, seed: int = 0,
                    block: int = 10) -> LoopRecord:
    """One run of the loop; ``alpha``/``b`` per sample make the plant drift (default: constant)."""
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    h = float(t[1] - t[0])
    n = t.size
    alpha = np.full(n, plant.alpha) if alpha is None else np.asarray(alpha, dtype=float)
    b = np.full(n, plant.b) if b is None else np.asarray(b, dtype=float)
    stream = PlantStream(h, plant.alpha, plant.a1, plant.a2, plant.b, horizon_s=max(3600.0, 10 * n * h))
    rng = np.random.default_rng(seed)
    comp = compensator or CreepCompensator(h)
    if mode == "known":
        comp.set_model(plant)
    gain = plant.b / math.gamma(1.0 + plant.alpha)
    u_all, y_clean = np.empty(n), np.empty(n)
    model_t, models = [], []
    frozen = False
    for k0 in range(0, n, block):
        k1 = min(n, k0 + block)
        u = r[k0:k1] / gain if mode == "uncompensated" else comp.command_block(r[k0:k1])
        yc = stream.step_block(u, alpha[k0:k1], b[k0:k1])
        u_all[k0:k1], y_clean[k0:k1] = u, yc
        if estimator is None or mode in ("known", "uncompensated"):
            continue
        estimator.update_block(u, yc + noise * rng.standard_normal(k1 - k0))
        m = estimator.model
        if m is None or frozen:
            continue
        if estimator.estimate.quality not in TRUSTED and (mode == "adaptive" or t[k1 - 1] < FROZEN_WAIT_S):
            continue
        if m != comp.current_model:
            comp.set_model(m)
            model_t.append(float(t[k1 - 1]))
            models.append(m)
        frozen = mode == "frozen"
    y = y_clean + noise * np.random.default_rng(seed + 1).standard_normal(n)
    return LoopRecord(t, r, u_all, y_clean, y, model_t, models)


#: Estimate qualities the compensator takes a model from (``OnlineEstimate.quality``).
TRUSTED = ("good",)
#: ``frozen`` waits at most this long (s) for a ``good`` estimate, then takes what there is.
FROZEN_WAIT_S = 10.0


def staircase(t: np.ndarray, levels, hold_s: float, t_start: float = 0.0) -> np.ndarray:
    """Reference holding ``levels[k]`` on [t_start + k hold_s, t_start + (k+1) hold_s); 0 before."""
    k = np.floor((t - t_start) / hold_s).astype(int)
    out = np.asarray(levels, dtype=float)[np.clip(k, 0, len(levels) - 1)]
    return np.where(t >= t_start, out, 0.0)
