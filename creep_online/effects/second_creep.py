"""``second_creep``: two creep mechanisms, a parallel path ``c / s^alpha2``.

One nonlinear parameter, alpha2 in (0, 1]; the gain is linear. The two
exponents can trade places, so the fit also starts with the base alpha moved
by +-0.2. Signature: a log-log slope that changes with time.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ModelError
from .base import FitView, OutputCompensator, ParallelEffect, ParamSpec, StepFn
from .responses import creep_step, creep_step_derivative

ALPHA2 = "second_creep.alpha2"


class _CreepCompensator(OutputCompensator):
    """The second creep path's response to the base input so far, exact for a staircase (O(changes) per sample)."""

    def __init__(self, dt: float, params: dict) -> None:
        self.dt = dt
        self.gain = float(params["gain"])
        self.alpha2 = float(params["alpha2"])
        self.changes: list[tuple[int, float]] = []
        self.previous = 0.0

    def start(self, v0: float, y0: float) -> None:
        self.previous = v0

    def output(self, y: float, v: float, n: int, t: float) -> float:
        dv = v - self.previous
        if dv != 0.0:
            self.changes.append((n, dv))
        y -= self.gain * sum(dvk * ((n - k) * self.dt) ** self.alpha2 for k, dvk in self.changes) \
            / math.gamma(1.0 + self.alpha2)
        self.previous = v
        return y


class SecondCreep(ParallelEffect):
    name = "second_creep"
    term = "parallel c / s^alpha2 (a second creep mechanism)"

    def parallel_step(self, params: dict) -> StepFn:
        c, alpha2 = float(params["gain"]), float(params["alpha2"])
        if not 0.0 < alpha2 <= 1.0:
            raise ModelError(f"second_creep alpha2 must satisfy 0 < alpha2 <= 1, got {alpha2}")
        return lambda tau: c * creep_step(alpha2, tau)

    def unit_step(self, theta: dict[str, float]) -> StepFn:
        alpha2 = theta[ALPHA2]
        return lambda tau: creep_step(alpha2, tau)

    def unit_step_derivatives(self, theta: dict[str, float]) -> StepFn:
        alpha2 = theta[ALPHA2]
        return lambda tau: creep_step_derivative(alpha2, tau)[None, :]

    def nonlinear_params(self, data) -> list[ParamSpec]:
        return [ParamSpec(ALPHA2, 1e-3, 1.0)]

    def start_values(self, data, peaks: list[float]) -> list[tuple[list[float], list[float]]]:
        return [([0.05, 0.15, 0.3, 0.5, 0.7, 0.85, 0.97], [])]

    def base_variants(self, base: np.ndarray, alpha_bounds: tuple[float, float]) -> list[np.ndarray]:
        """The two exponents trade places: move alpha too."""
        out = []
        for shift in (-0.2, 0.2):
            v = base.copy()
            v[0] = float(np.clip(v[0] + shift, alpha_bounds[0] + 0.01, alpha_bounds[1] - 0.01))
            out.append(v)
        return out

    def swapped(self, theta: np.ndarray, own: list[int]) -> np.ndarray | None:
        """alpha and alpha2 exchanged (a fit that put the resonance on the wrong creep path leaves from there)."""
        out = np.array(theta, dtype=float)
        out[0], out[own[0]] = theta[own[0]], theta[0]
        return out

    def fitted_params(self, fit: FitView) -> dict:
        return {"gain": fit.coef[self.gain_column], "alpha2": fit.theta[ALPHA2]}

    def compensator(self, dt: float, params: dict) -> OutputCompensator:
        return _CreepCompensator(dt, params)

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        return (f"log-log slope changes with time: second power law alpha2 = {params.get('alpha2', float('nan')):.3g} "
                f"beside alpha = {fit.model.alpha:.3g}")

    def example_params(self, model, t, u, y_base, rng) -> dict:
        alpha2 = model.alpha + rng.choice([-1, 1]) * rng.uniform(0.3, 0.4)
        if not 0.1 <= alpha2 <= 0.95:  # keep a creep (not an elastic or viscous) term, 0.3-0.4 away from alpha
            # above alpha if that stays below 0.95, else below it (alpha + 0.35 was 1.12 for alpha 0.77)
            alpha2 = model.alpha + 0.35 if model.alpha <= 0.6 else model.alpha - 0.35
        return {"gain": model.b * rng.uniform(0.2, 0.5) * rng.choice([-1, 1]), "alpha2": alpha2}
