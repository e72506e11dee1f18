"""``leakage``: a charge amplifier or finite insulation, the high-pass ``tau s / (1 + tau s)`` on the output.

One nonlinear parameter, log10 tau, searched over 1e-3..1e3 record lengths;
tau at its upper bound switches the effect off. Signature: the output decays
towards zero during holds.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ModelError
from .base import FitView, OutputCompensator, OutputFilterEffect, ParamSpec
from .responses import is_uniform

TAU = "leakage.log10_tau"


def leakage_filter(t: np.ndarray, y: np.ndarray, tau: float) -> np.ndarray:
    """tau s / (1 + tau s) applied to y (rows allowed): y minus its first-order low-pass.

    The low-pass is exact for a piecewise-linear y (first-order hold), with
    variable steps allowed: x[n+1] = a x[n] + (1 - a) y[n] + (1 - tau (1 - a)/dt) (y[n+1] - y[n]),
    a = exp(-dt/tau); x starts at 0 (the record starts from rest).
    """
    y = np.asarray(y, dtype=float)
    if not math.isfinite(tau) or tau <= 0:
        raise ModelError(f"leakage tau_s must be > 0, got {tau}")
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    if is_uniform(t):
        h = float(dt.mean()) if dt.size else 1.0
        a = math.exp(-h / tau)
        c0 = 1.0 - tau * (-math.expm1(-h / tau)) / h
        c1 = (1.0 - a) - c0
        # x[n] = a x[n-1] + c0 y[n] + c1 y[n-1] with x[-1] = y[-1] = 0
        from ..kernels import first_order_filter     # numba on first use: importing the effects stays light
        if y.size == 0:
            return y.copy()
        rows = np.ascontiguousarray(y.reshape(-1, y.shape[-1]))
        return y - first_order_filter(c0, c1, -a, rows).reshape(y.shape)
    a = np.exp(-dt / tau)
    c0 = 1.0 - tau * (-np.expm1(-dt / tau)) / dt
    c1 = (1.0 - a) - c0
    low = np.zeros_like(y)
    for n in range(1, t.size):
        low[..., n] = a[n - 1] * low[..., n - 1] + c0[n - 1] * y[..., n] + c1[n - 1] * y[..., n - 1]
    return y - low


class _LeakageCompensator(OutputCompensator):
    """(1 + tau s)/(tau s) = 1 + 1/(tau s): add the running integral of the output (trapezoid) over tau."""

    def __init__(self, dt: float, params: dict) -> None:
        self.dt = dt
        self.tau = float(params["tau_s"])
        self.integral = 0.0
        self.previous = 0.0
        self.y0 = 0.0

    def start(self, v0: float, y0: float) -> None:
        self.y0 = y0

    def output(self, y: float, v: float, n: int, t: float) -> float:
        d = y - self.y0   # y_lin - y0 = (y - y0) + (1/tau) int (y - y0) dt
        if n:
            self.integral += 0.5 * (d + self.previous) * self.dt
        self.previous = d
        return y + self.integral / self.tau


class Leakage(OutputFilterEffect):
    name = "leakage"
    term = "tau s / (1 + tau s) on the output (high-pass)"

    def filter_output(self, t: np.ndarray, y: np.ndarray, params: dict) -> np.ndarray:
        return leakage_filter(t, y, float(params["tau_s"]))

    def filter_columns(self, t: np.ndarray, cols: np.ndarray, theta: dict[str, float]) -> np.ndarray:
        return leakage_filter(t, cols, 10 ** theta[TAU])

    def nonlinear_params(self, data) -> list[ParamSpec]:
        dur = data.t[-1] - data.t[0]
        hi = math.log10(dur * 1e3)
        return [ParamSpec(TAU, math.log10(dur / 1e3), hi, off=hi)]

    def start_values(self, data, peaks: list[float]) -> list[tuple[list[float], list[float]]]:
        spec = self.nonlinear_params(data)[0]
        return [(list(np.linspace(spec.lo + 0.5, spec.hi - 0.5, 9)), [])]

    def fitted_params(self, fit: FitView) -> dict:
        return {"tau_s": 10 ** fit.theta[TAU]}

    def compensator(self, dt: float, params: dict) -> OutputCompensator:
        return _LeakageCompensator(dt, params)

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        slope = where.get("time_spans", {}).get("hold_slope_mean", float("nan"))
        held = f" (mean hold slope of the residual {slope:.3g}/s)" if np.isfinite(slope) else ""
        return f"output decays towards zero, high-pass{held}; tau {params.get('tau_s', float('nan')):.3g} s"

    def example_params(self, model, t, u, y_base, rng) -> dict:
        return {"tau_s": rng.uniform(2.0, 20.0)}
