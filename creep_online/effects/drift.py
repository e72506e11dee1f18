"""``drift``: thermal or sensor drift, ``rate (t - t0) + offset`` added to the output.

Linear in its rate (the offset is the one every model has), so the fit adds
one column and searches nothing. Signature: the residual trends with time.
"""
from __future__ import annotations

import numpy as np

from .base import AdditiveEffect, FitView, OutputCompensator


class _DriftCompensator(OutputCompensator):
    def __init__(self, params: dict) -> None:
        self.rate = float(params.get("rate", 0.0))

    def output(self, y: float, v: float, n: int, t: float) -> float:
        return y - self.rate * t


class Drift(AdditiveEffect):
    name = "drift"
    term = "rate (t - t0) + offset added to the output"

    def add_to_output(self, t: np.ndarray, y: np.ndarray, params: dict) -> np.ndarray:
        return y + float(params.get("rate", 0.0)) * (t - t[0]) + float(params.get("offset", 0.0))

    def output_columns(self, t: np.ndarray, theta: dict[str, float], harmonics: int) -> tuple[list[np.ndarray], list[str]]:
        return [t - t[0]], ["drift.rate"]

    def fitted_params(self, fit: FitView) -> dict:
        return {"rate": fit.coef["drift.rate"]}

    def compensator(self, dt: float, params: dict) -> OutputCompensator:
        return _DriftCompensator(params)

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        r = base.residual
        c = float(np.corrcoef(data.t - data.t[0], r)[0, 1]) if np.std(r) > 0 else 0.0
        return f"residual trends with time (correlation {c:.2f}); rate {params.get('rate', float('nan')):.3g} per s"

    def example_params(self, model, t, u, y_base, rng) -> dict:
        span = float(np.ptp(y_base))
        return {"rate": span * rng.uniform(0.06, 0.15) / (t[-1] - t[0]) * rng.choice([-1, 1])}
