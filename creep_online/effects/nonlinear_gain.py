"""``nonlinear_gain``: amplitude-dependent gain, a static polynomial on the input.

``v = u + k2 u^2 + k3 u^3`` on the absolute input. The fit adds the rows u^2
and u^3 (scaled by max |u| for conditioning) with linear weights. Signature:
the level error grows with the input level.
"""
from __future__ import annotations

import numpy as np

from .base import FitView, InputCompensator, InputEffect


def polynomial_input(u: np.ndarray, k2: float = 0.0, k3: float = 0.0) -> np.ndarray:
    """v = u + k2 u^2 + k3 u^3 (static nonlinear gain on the absolute input)."""
    u = np.asarray(u, dtype=float)
    return u + k2 * u * u + k3 * u * u * u


class _PolynomialCompensator(InputCompensator):
    def __init__(self, params: dict) -> None:
        self.k2 = float(params.get("k2", 0.0))
        self.k3 = float(params.get("k3", 0.0))

    def input(self, v: float) -> float:
        return v + self.k2 * v * v + self.k3 * v ** 3


class NonlinearGain(InputEffect):
    name = "nonlinear_gain"
    term = "static polynomial on the input: v = u + k2 u^2 + k3 u^3"

    @staticmethod
    def _coefficients(params: dict) -> tuple[float, float]:
        return float(params.get("k2", 0.0)), float(params.get("k3", 0.0))

    def transform_input(self, v: np.ndarray, params: dict) -> np.ndarray:
        return polynomial_input(v, *self._coefficients(params))

    def transform_before(self, v_pre: float, params: dict) -> float:
        return float(polynomial_input(np.array([v_pre]), *self._coefficients(params))[0])

    def design_rows(self, data, u: np.ndarray, variant: str | None, before: bool = False) -> np.ndarray:
        scale = data.u_scale
        x = u / scale
        return np.array([scale * x * x, scale * x * x * x])

    def column_names(self) -> list[str]:
        return ["c2", "c3"]

    def fitted_params(self, fit: FitView) -> dict:
        scale = fit.data.u_scale
        k2, k3 = fit.coef["c2"] / fit.gain / scale, fit.coef["c3"] / fit.gain / scale**2
        lo, hi = float(fit.data.u.min()), float(fit.data.u.max())
        gains = [1 + 2 * k2 * x + 3 * k3 * x * x for x in np.linspace(lo, hi, 21)]  # incremental gain
        return {"k2": k2, "k3": k3,
                "gain_change": float(max(gains) / min(gains) - 1) if min(gains) > 0 else float("inf")}

    def compensator(self, dt: float, params: dict) -> InputCompensator:
        return _PolynomialCompensator(params)

    def applicable(self, data) -> str | None:
        return "needs at least 3 input levels" if np.unique(data.u).size < 3 else None

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        reg = where.get("input_regimes", {})
        return (f"level error grows with the input level (trend {reg.get('level_trend', 0):.2f} x RMS); "
                f"incremental gain changes {100 * params.get('gain_change', float('nan')):.3g} % over the range")

    def example_params(self, model, t, u, y_base, rng) -> dict:
        um = float(np.max(np.abs(u)))
        k2 = rng.uniform(0.1, 0.3) / um * rng.choice([-1, 1]) * 0.5
        return {"k2": k2, "k3": rng.uniform(-0.05, 0.05) / um**2}
