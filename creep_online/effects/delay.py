"""``delay``: amplifier or sensor latency, ``e^{-s d}`` on every linear path (fractional delays allowed).

One nonlinear parameter, the delay in seconds (up to ``MAX_DELAY_SAMPLES``
samples of a uniform record); 0 switches it off. Signature: a residual shaped
like minus the output's derivative just after steps.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ModelError
from .base import DelayEffect, FitView, InputCompensator, ParamSpec

D = "delay.d"
#: Largest delay searched, in samples (uniform) of the record.
MAX_DELAY_SAMPLES = 40


class _DelayLine(InputCompensator):
    """Delay = k whole samples + a fraction f.

    The sample-held input delayed by (k + f) h, averaged over each sample
    interval, is (1 - f) v[n-k] + f v[n-k-1] (rounding to whole samples left
    1.2-1.5x the noise floor online on the hidden-effect records; this leaves ~1.0x).
    """

    def __init__(self, dt: float, params: dict) -> None:
        d = float(params.get("delay_s", 0.0)) / dt
        self.k = int(math.floor(d + 1e-9))
        self.frac = d - self.k if d - self.k > 1e-9 else 0.0
        self.kept = self.k + (1 if self.frac else 0)   # samples of history kept
        self.history: list[float] = []

    def start(self, v0: float, y0: float) -> None:
        self.history = [v0] * self.kept

    def input(self, v: float) -> float:
        if not self.kept:
            return v
        self.history.append(v)          # history[-1 - j] = v[n - j]
        v = self.history[-1 - self.k]
        if self.frac:
            v = (1.0 - self.frac) * v + self.frac * self.history[0]
        self.history.pop(0)
        return v


class Delay(DelayEffect):
    name = "delay"
    term = "e^{-s d} on every linear path (fractional delays allowed)"

    def delay_s(self, params: dict) -> float:
        d = float(params.get("delay_s", 0.0))
        if d < 0:
            raise ModelError(f"delay_s must be >= 0, got {d}")
        return d

    def fitted_delay(self, theta: dict[str, float]) -> float:
        return theta[D]

    def nonlinear_params(self, data) -> list[ParamSpec]:
        hi = MAX_DELAY_SAMPLES * data.h if data.uniform else 0.05 * (data.t[-1] - data.t[0])
        return [ParamSpec(D, 0.0, hi, off=0.0)]

    def start_values(self, data, peaks: list[float]) -> list[tuple[list[float], list[float]]]:
        hi = self.nonlinear_params(data)[0].hi
        steps = np.array([0.3, 1, 2, 3, 5, 8, 13, 20, 30]) * data.h
        return [(list(np.unique(np.concatenate([steps, [hi * 0.99]]))), [])]

    def fitted_params(self, fit: FitView) -> dict:
        return {"delay_s": fit.theta[D], "delay_samples": fit.theta[D] / fit.data.h}

    def compensator(self, dt: float, params: dict) -> InputCompensator:
        return _DelayLine(dt, params)

    def applicable(self, data) -> str | None:
        if not data.uniform:
            return "needs uniform sampling (delays below one sample step of a log-spaced record are not identifiable)"
        return None

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        r = base.residual
        dy = np.gradient(base.y_hat, data.t)
        c = float(np.corrcoef(dy, r)[0, 1]) if np.std(r) > 0 and np.std(dy) > 0 else 0.0
        return (f"residual shaped like -d(output)/dt after steps (correlation {c:.2f}); "
                f"delay {1e3 * params.get('delay_s', float('nan')):.3g} ms = "
                f"{params.get('delay_samples', float('nan')):.3g} samples")

    def example_params(self, model, t, u, y_base, rng) -> dict:
        return {"delay_s": rng.uniform(1.5, 6.0) * float(t[1] - t[0])}
