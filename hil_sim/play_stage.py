"""The actuator's hysteresis before the creep plant, streamed: ``v = u + sum_i s w_i play_{r_i}[u]``.

A Prandtl-Ishlinskii loop (``creep_online.effects.hysteresis``: the operator the
library fits and inverts) stepped block by block with persistent play states,
so a closed loop can drive it with commands it computes as it goes. ``s`` is a
per-sample scale of the weights: a loop whose width drifts (temperature,
preload). With a constant scale of 1 the output equals the library's
``hysteresis_input`` on the whole input (the operators start as ``initial``
says on the first input, as ``simulate_with_effects`` starts them).
"""
from __future__ import annotations

import numpy as np

from creep_online.effects.hysteresis import initial_plays, loop_width, play_operators


class PlayStage:
    """The loop ``{"r": thresholds, "w": weights, "initial": ...}`` with persistent play states."""

    def __init__(self, params: dict) -> None:
        self.r = np.atleast_1d(np.asarray(params.get("r", []), dtype=float))
        self.w = np.atleast_1d(np.asarray(params.get("w", []), dtype=float))
        if self.r.shape != self.w.shape or np.any(self.r < 0):
            raise ValueError("hysteresis needs matching r and w lists, thresholds >= 0")
        self.initial = params.get("initial", "centred")
        initial_plays(0.0, self.r, self.initial)           # (ModelError, a ValueError, for an unknown state)
        self.plays: np.ndarray | None = None

    def step_block(self, u: np.ndarray, scale: np.ndarray | float = 1.0) -> np.ndarray:
        """v for the next len(u) inputs (weights times ``scale``, per sample or one number)."""
        u = np.asarray(u, dtype=float)
        if u.size == 0:
            return u.copy()
        if self.plays is None:
            self.plays = initial_plays(float(u[0]), self.r, self.initial)
        p = play_operators(u, self.r, initial=self.plays)
        self.plays = p[:, -1].copy()
        return u + np.asarray(scale, dtype=float) * (self.w @ p)


def width_scale(params: dict, stroke: float, growth: float, n: int) -> np.ndarray:
    """Per-sample weight scales (1 at the start) that make the loop's width (``loop_width`` over ``stroke``) grow
    linearly by the fraction ``growth`` over n samples. The width is ``k A / (1 + k B)`` for weights ``k w``
    (A = sum w 2 min(r, stroke/2), B = sum w), so the scale for a width W is ``W / (A - W B)``."""
    r = np.asarray(params["r"], dtype=float)
    w = np.asarray(params["w"], dtype=float)
    a = float(np.sum(w * 2.0 * np.minimum(r, stroke / 2.0)))
    b = float(np.sum(w))
    width = loop_width(r, w, stroke) * (1.0 + growth * np.arange(n) / max(n - 1, 1))
    return width / (a - width * b)
