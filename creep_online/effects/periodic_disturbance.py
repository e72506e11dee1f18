"""``periodic_disturbance``: mains pick-up or a fan, ``sum_k A_k sin(2 pi k f t + phi_k)`` added to the output.

One nonlinear parameter, the frequency (>= 3 cycles per record: fewer is a
trend); amplitudes and phases come from linear sine/cosine columns, one pair
per harmonic. Starts on the base residual's spectral peaks. Signature: a narrow
spectral line unrelated to the input.
"""
from __future__ import annotations

import math

import numpy as np

from .base import AdditiveEffect, FitView, OutputCompensator, ParamSpec
from .input_lines import harmonic_of_input

F = "periodic_disturbance.f"


def periodic_columns(t: np.ndarray, f_hz: float, harmonics: int = 1) -> np.ndarray:
    """Rows sin(2 pi k f t), cos(2 pi k f t) for k = 1..harmonics (shape (2 harmonics, n))."""
    t = np.asarray(t, dtype=float)
    rows = []
    for k in range(1, harmonics + 1):
        arg = 2.0 * math.pi * k * f_hz * t
        rows += [np.sin(arg), np.cos(arg)]
    return np.array(rows)


def _harmonics(params: dict) -> tuple[float, np.ndarray, np.ndarray]:
    """(f, amplitudes, phases), amplitudes and phases as arrays of one value per harmonic."""
    amp = np.atleast_1d(np.asarray(params.get("amplitude", 0.0), dtype=float))
    phase = np.broadcast_to(np.atleast_1d(np.asarray(params.get("phase", 0.0), dtype=float)), amp.shape)
    return float(params["f_hz"]), amp, phase


class _LineCompensator(OutputCompensator):
    def __init__(self, params: dict) -> None:
        self.f, self.amp, self.phase = _harmonics(params)

    def output(self, y: float, v: float, n: int, t: float) -> float:
        for k, (a, phi) in enumerate(zip(self.amp, self.phase), start=1):
            y -= float(a) * math.sin(2 * math.pi * k * self.f * t + float(phi))
        return y


class PeriodicDisturbance(AdditiveEffect):
    name = "periodic_disturbance"
    term = "sinusoid(s) sum_k A_k sin(2 pi k f t + phi_k) added to the output"

    def add_to_output(self, t: np.ndarray, y: np.ndarray, params: dict) -> np.ndarray:
        f, amp, phase = _harmonics(params)
        for k, (a, phi) in enumerate(zip(amp, phase), start=1):
            y = y + a * np.sin(2.0 * math.pi * k * f * t + phi)
        return y

    def output_columns(self, t: np.ndarray, theta: dict[str, float], harmonics: int) -> tuple[list[np.ndarray], list[str]]:
        names = [f"periodic.{trig}{k}" for k in range(1, harmonics + 1) for trig in ("sin", "cos")]
        return list(periodic_columns(t, theta[F], harmonics)), names

    def nonlinear_params(self, data) -> list[ParamSpec]:
        # fewer than ~3 cycles over the record is a trend, not a periodic disturbance
        return [ParamSpec(F, 3.0 / (data.t[-1] - data.t[0]), 0.5 * data.fs)]

    def start_values(self, data, peaks: list[float]) -> list[tuple[list[float], list[float]]]:
        spec = self.nonlinear_params(data)[0]
        inside = [f for f in peaks if spec.lo <= f <= spec.hi]
        return [(inside or [0.05 * data.fs], inside)]

    def full_record_values(self, peaks: list[float]) -> dict[str, list[float]]:
        """A line's frequency is sharper on the whole record: retry the peaks there."""
        return {F: list(peaks)}

    def fitted_params(self, fit: FitView) -> dict:
        amps, phases = [], []
        for k in range(1, fit.harmonics + 1):
            s_, c_ = fit.coef[f"periodic.sin{k}"], fit.coef[f"periodic.cos{k}"]
            amps.append(math.hypot(s_, c_))
            phases.append(math.atan2(c_, s_))
        return {"f_hz": fit.theta[F], "amplitude": amps if len(amps) > 1 else amps[0],
                "phase": phases if len(phases) > 1 else phases[0]}

    def compensator(self, dt: float, params: dict) -> OutputCompensator:
        return _LineCompensator(params)

    def applicable(self, data) -> str | None:
        return None if data.uniform else "needs uniform sampling for its frequency search"

    def contradiction(self, params: dict, data, model=None) -> str | None:
        if not data.uniform:
            return None
        locked = harmonic_of_input(float(params.get("f_hz", float("nan"))), data.t, data.u)
        if locked is None:
            return None
        return (f"line at {params['f_hz']:.5g} Hz = {locked[0]} x the input's {locked[1]:.4g} Hz: locked to the "
                "input, so an input effect, not a disturbance")

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        amp = params.get("amplitude", float("nan"))
        amp = amp[0] if isinstance(amp, list) else amp
        return (f"narrow spectral line at {params.get('f_hz', float('nan')):.5g} Hz, amplitude {amp:.3g}, "
                "unrelated to the input")

    def example_params(self, model, t, u, y_base, rng) -> dict:
        span = float(np.ptp(y_base))
        f = rng.choice([50.0, 60.0, rng.uniform(15.0, 150.0)])
        while abs(f - model.fn) < 0.2 * model.fn:
            f = rng.uniform(15.0, 150.0)
        return {"f_hz": float(f), "amplitude": span * rng.uniform(0.005, 0.02), "phase": rng.uniform(0, 2 * math.pi)}
