"""``second_mode``: a higher structural mode, a parallel path ``g / (1 + a1' s + a2' s^2)``.

Nonlinear parameters: the mode's frequency and damping (log10 scale); the gain
is linear. Starts: a grid over the frequency band plus the base residual's
spectral peaks, and starts where this mode takes over a resonance the base
fit locked onto. Signature: ringing at a frequency the first mode lacks.
"""
from __future__ import annotations

import math

import numpy as np

from .base import FitView, OutputCompensator, ParallelEffect, ParamSpec, StepFn
from .input_lines import harmonic_of_input
from .responses import resonance_step, resonance_step_derivatives

FN = "second_mode.log10_fn"
ZETA = "second_mode.log10_zeta"
#: Damping at and above which a second-order path has no resonance peak (1/sqrt(2)): the catalogue's second mode
#: is a higher structural mode, seen as ringing after steps; a fitted "mode" this damped is a low-pass path
#: standing in for a slow effect (leakage + drift records: 70.9 Hz at zeta 0.81 beside a base deformed to 3 Hz).
NO_PEAK_ZETA = 1.0 / math.sqrt(2.0)
#: Relative steps of the damped frequency around a mode's image across Nyquist (``polished_starts``).
IMAGE_STEPS = (0.97, 0.985, 1.0, 1.015, 1.03)


def zoh_discretize(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(Ad, Bd) of x' = a x + b u under a zero-order hold of ``dt``: ``scipy.signal.cont2discrete(..., dt,
    method="zoh")``'s computation (the exponential of [[a, b], [0, 0]] dt), without importing scipy.signal
    (and scipy.stats with it, ~24 MB resident)."""
    from scipy.linalg import expm
    upper = np.hstack((a, b))
    lower = np.hstack((np.zeros((b.shape[1], a.shape[0])), np.zeros((b.shape[1], b.shape[1]))))
    ms = expm(dt * np.vstack((upper, lower)))[:a.shape[0], :]
    return ms[:, 0:a.shape[1]], ms[:, a.shape[1]:]


class _ModeCompensator(OutputCompensator):
    """The mode's ZOH state-space model driven by the base input, its output subtracted."""

    def __init__(self, dt: float, params: dict) -> None:
        wn = 2 * math.pi * float(params["fn_hz"])
        a = np.array([[0.0, 1.0], [-wn * wn, -2 * float(params["zeta"]) * wn]])
        b = np.array([[0.0], [wn * wn]])
        ad, bd = zoh_discretize(a, b, dt)
        self.ad, self.bd = ad, bd[:, 0]
        self.x = np.zeros(2)
        self.gain = float(params["gain"])
        self.ref = 0.0

    def start(self, v0: float, y0: float) -> None:
        self.ref = v0

    def output(self, y: float, v: float, n: int, t: float) -> float:
        y -= self.gain * self.x[0]  # output at this sample, then advance the state with this input
        self.x = self.ad @ self.x + self.bd * (v - self.ref)
        return y


class SecondMode(ParallelEffect):
    name = "second_mode"
    term = "parallel g / (1 + a1' s + a2' s^2) (a higher structural mode)"

    def parallel_step(self, params: dict) -> StepFn:
        g, fn, z = float(params["gain"]), float(params["fn_hz"]), float(params.get("zeta", 0.05))
        return lambda tau: g * resonance_step(fn, z, tau)

    def unit_step(self, theta: dict[str, float]) -> StepFn:
        fn, z = 10 ** theta[FN], 10 ** theta[ZETA]
        return lambda tau: resonance_step(fn, z, tau)

    def unit_step_derivatives(self, theta: dict[str, float]) -> StepFn:
        fn, z = 10 ** theta[FN], 10 ** theta[ZETA]
        return lambda tau: resonance_step_derivatives(fn, z, tau)

    def nonlinear_params(self, data) -> list[ParamSpec]:
        # up to the sampling rate, as the base mode: a mode between Nyquist and fs rings at its alias
        # fs - fn in the samples, and a step's response still tells the two apart (they differ in
        # damping and in the first samples after the step); capped at Nyquist, such a mode was fitted
        # at its alias and stopped at 1.4-2.5x the noise (bench seeds second_mode 15, 2, 3)
        hi = math.log10(data.fs) if data.uniform else math.log10(1.0 / data.h)
        lo = math.log10(1.0 / (data.t[-1] - data.t[0]))
        return [ParamSpec(FN, lo, hi), ParamSpec(ZETA, -3.0, 0.5)]

    def start_values(self, data, peaks: list[float]) -> list[tuple[list[float], list[float]]]:
        fn = self.nonlinear_params(data)[0]
        lo, hi = fn.lo, fn.hi
        on_peaks = [math.log10(f) for f in peaks if 10 ** lo < f < 10 ** hi]
        return [(list(np.linspace(lo + 0.05 * (hi - lo), hi - 0.01 * (hi - lo), 24)), on_peaks),
                ([math.log10(0.05)], [math.log10(0.02), math.log10(0.08)])]

    def takeover_starts(self, base: np.ndarray) -> list[np.ndarray]:
        """The base may have locked onto the higher mode: hand it to this one, move the base down."""
        starts = []
        for factor in (0.25, 0.4, 0.6):
            th = np.concatenate([base[:3], np.zeros(2)])
            th[3], th[4] = base[1], base[2]
            th[1], th[2] = base[1] + math.log10(factor), math.log10(0.2)
            starts.append(th)
        return starts

    def polished_starts(self, theta: np.ndarray, own: list[int], data) -> list[np.ndarray]:
        """The mode's image across Nyquist: same decay rate, damped frequency fs - f_d (a few per cent either way).

        Sampled at fs, a mode at f_d rings like one at fs - f_d; a fit that
        found the alias (wrong damping and gain, above the noise) cannot walk
        to the image through the bad fits between. The image's frequency is
        only as good as the alias fit's, so it is tried at 1.5 % steps (the
        basin of a mode with zeta 0.05 is about +-1.5 % wide).
        """
        if not data.uniform:
            return []
        fn, zeta = 10 ** theta[own[0]], 10 ** theta[own[1]]
        if zeta >= 1.0:
            return []
        sigma = 2 * math.pi * fn * zeta
        wd = 2 * math.pi * (data.fs - fn * math.sqrt(1.0 - zeta * zeta))
        starts = []
        for k in IMAGE_STEPS:
            wn = math.hypot(k * wd, sigma)
            th = np.array(theta, dtype=float)
            th[own[0]], th[own[1]] = math.log10(wn / (2 * math.pi)), math.log10(sigma / wn)
            starts.append(th)
        return starts

    def fitted_params(self, fit: FitView) -> dict:
        return {"gain": fit.coef[self.gain_column], "fn_hz": 10 ** fit.theta[FN], "zeta": 10 ** fit.theta[ZETA]}

    def compensator(self, dt: float, params: dict) -> OutputCompensator:
        return _ModeCompensator(dt, params)

    def contradiction(self, params: dict, data, model=None) -> str | None:
        fn, zeta = float(params.get("fn_hz", float("nan"))), float(params.get("zeta", float("nan")))
        if zeta >= NO_PEAK_ZETA:
            return (f"zeta {zeta:.2g} at {fn:.4g} Hz has no resonance peak: an overdamped path standing in for "
                    "a slow effect, not a mode")
        if model is not None and fn <= model.fn:
            return (f"resonance at {fn:.4g} Hz is not above the first mode's {model.fn:.4g} Hz: a path standing "
                    "in for another effect, not a higher mode")
        if not data.uniform:
            return None
        locked = harmonic_of_input(fn, data.t, data.u)
        if locked is None or 2.0 * zeta * fn * (data.t[-1] - data.t[0]) >= 1.0:
            return None              # off the input's lines, or wider than the record's resolution: a mode
        return (f"resonance at {fn:.5g} Hz (zeta {zeta:.2g}, narrower than the record resolves) = {locked[0]} x "
                f"the input's {locked[1]:.4g} Hz: a line locked to the input, not a mode")

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        fn = params.get("fn_hz", float("nan"))
        near = [pk for pk in where.get("spectrum_peaks", []) if abs(pk["f_hz"] - params.get("fn_hz", 0)) < 0.1 * params.get("fn_hz", 1)]
        extra = f"; residual spectrum peak at {near[0]['f_hz']:.4g} Hz" if near else ""
        return f"second resonance at {fn:.4g} Hz (zeta {params.get('zeta', float('nan')):.2g}){extra}"

    def example_params(self, model, t, u, y_base, rng) -> dict:
        # a higher mode is weaker than the first: its resonance peak is 10-40 % of the first mode's
        zeta2 = rng.uniform(0.02, 0.08)
        peak1 = abs(model.b) * model.wn ** -model.alpha / (2.0 * model.zeta)
        gain = 2.0 * zeta2 * rng.uniform(0.1, 0.4) * peak1
        return {"gain": gain * rng.choice([-1, 1]), "fn_hz": model.fn * rng.uniform(2.5, 5.0), "zeta": zeta2}
