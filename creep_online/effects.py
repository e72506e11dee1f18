"""The catalogue of model-discrepancy effects as extensions of the forward model (DESIGN.md section 5).

Eight effects with stable names, each a term added to
``G(s) = b / (s^alpha (1 + a1 s + a2 s^2))``:

============================  ==================================================  ==========================================
name                          model term                                          parameters (``effects[name]`` dict)
============================  ==================================================  ==========================================
``hysteresis``                Prandtl-Ishlinskii play operators on the input       ``r`` thresholds, ``w`` weights:
                                                                                  ``v = u + sum_i w_i play_{r_i}[u]``
``nonlinear_gain``            static polynomial on the input                      ``k2``, ``k3``: ``v = u + k2 u^2 + k3 u^3``
``second_mode``               parallel ``g / (1 + a1' s + a2' s^2)``              ``gain``, ``fn_hz``, ``zeta``
``drift``                     ``rate * (t - t0) + offset``                        ``rate``, ``offset``
``leakage``                   ``tau s / (1 + tau s)`` on the output               ``tau_s``
``delay``                     ``e^{-s d}`` (fractional delays allowed)            ``delay_s``
``periodic_disturbance``      sinusoid(s) ``sum_k A_k sin(2 pi k f t + phi_k)``   ``f_hz``, ``amplitude``, ``phase`` (scalars
                                                                                  or lists, one per harmonic)
``second_creep``              parallel ``c / s^alpha2``                           ``gain``, ``alpha2``
============================  ==================================================  ==========================================

Signal flow of :func:`simulate_with_effects`: input nonlinearity (hysteresis,
nonlinear gain) -> linear paths in parallel (base, second mode, second
creep) -> delay -> leakage -> additive terms (drift, periodic disturbance).

Every linear path is evaluated the same way: the input is zero-order held,
so the output is a superposition of shifted *unit-step responses*,
``y(t_n) = sum_k du_k S(t_n - t_k)``. This module provides the step responses
(on a uniform grid or at arbitrary times, optionally delayed), the
superposition (FFT on uniform grids, explicit sums on non-uniform ones), the
play operators and the leakage filter; the extended-model fit in
``creep_online.diagnostics`` reuses them. numpy/scipy plus the core
simulator only.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft
from scipy.interpolate import CubicSpline
from scipy.signal import lfilter

from .discretize import resonance_poles, step_response_grid
from .errors import DataError, ModelError
from .model import CreepModel

EFFECTS = ("hysteresis", "nonlinear_gain", "second_mode", "drift", "leakage", "delay",
           "periodic_disturbance", "second_creep")

#: Points per grid of the multi-resolution step response used at arbitrary times.
MULTIGRID_POINTS = 2048
#: Ratio between successive grids of the multi-resolution step response.
MULTIGRID_RATIO = 8.0
#: Non-uniform records: at most this many (samples x input changes) pairs are summed explicitly.
MAX_PAIRS = 20_000_000

StepFn = Callable[[np.ndarray], np.ndarray]


# --------------------------------------------------------------------------- time grids
def is_uniform(t: np.ndarray, rtol: float = 1e-6) -> bool:
    """True when the sampling step varies by less than ``rtol`` relative."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return True
    h = (t[-1] - t[0]) / (t.size - 1)
    return bool(np.max(np.abs(np.diff(t) - h)) <= rtol * h + 1e-12 * abs(t[-1]))


# --------------------------------------------------------------------------- unit-step responses
def creep_step(alpha: float, tau: np.ndarray) -> np.ndarray:
    """Unit-step response of 1/s^alpha: tau^alpha / Gamma(1 + alpha) (0 for tau <= 0)."""
    tau = np.asarray(tau, dtype=float)
    return np.power(np.maximum(tau, 0.0), alpha) / math.gamma(1.0 + alpha)


def resonance_step(fn_hz: float, zeta: float, tau: np.ndarray) -> np.ndarray:
    """Unit-step response of 1/(1 + a1 s + a2 s^2) with a2 = 1/wn^2, a1 = 2 zeta/wn, at times tau.

    ``1 + (p2 e^{p1 t} - p1 e^{p2 t}) / (p1 - p2)``, written with expm1 so that it
    is accurate for repeated and stiff poles.
    """
    tau = np.maximum(np.asarray(tau, dtype=float), 0.0)
    wn = 2.0 * math.pi * fn_hz
    a1, a2 = 2.0 * zeta / wn, 1.0 / wn**2
    p1, p2 = resonance_poles(a1, a2)  # slow, fast
    d = p2 - p1
    # S = 1 - e^{p1 t} + p1 e^{p1 t} (e^{d t} - 1)/d  (limit-safe form of the two-pole formula)
    x = d * tau
    small = np.abs(x) < 1e-6
    ratio = np.empty(tau.shape, dtype=complex)
    ratio[~small] = np.expm1(x[~small]) / d
    ratio[small] = tau[small] * (1.0 + x[small] / 2.0)
    e1 = np.exp(p1 * tau)
    return (1.0 - e1 + p1 * e1 * ratio).real


def base_step_grid(alpha: float, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """Exact unit-step response of 1/(s^alpha (1 + a1 s + a2 s^2)) at k h, k = 0..n-1."""
    return step_response_grid(alpha, a1, a2, h, n)


def base_step_at(alpha: float, a1: float, a2: float, tau: np.ndarray) -> np.ndarray:
    """The base unit-step response at arbitrary times tau (>= 0), e.g. a log-spaced record.

    Multi-resolution: exact responses on uniform grids of ``MULTIGRID_POINTS``
    points whose spans shrink by ``MULTIGRID_RATIO`` down to the smallest tau,
    each time interpolated (cubic) from the finest grid that covers it.
    """
    tau = np.asarray(tau, dtype=float)
    out = np.zeros(tau.shape)
    pos = tau > 0
    if not pos.any():
        return out
    tp = tau[pos]
    res = np.zeros(tp.shape)
    span = float(tp.max()) * 1.0001
    lo = float(tp.min())
    m = MULTIGRID_POINTS
    done = np.zeros(tp.shape, dtype=bool)
    for _ in range(64):
        h = span / (m - 1)
        grid = step_response_grid(alpha, a1, a2, h, m)
        last = span / MULTIGRID_RATIO <= lo
        sel = ~done & ((tp > span / MULTIGRID_RATIO) | last)
        if sel.any():
            res[sel] = CubicSpline(np.arange(m) * h, grid)(tp[sel])
            done |= sel
        if last:
            break
        span /= MULTIGRID_RATIO
    out[pos] = res
    return out


def delayed_grid(s: np.ndarray, h: float, delay: float) -> np.ndarray:
    """S(k h - delay) from S on the grid k h (S = 0 before 0), by cubic interpolation."""
    if delay <= 0.0:
        return s
    n = s.size
    tk = np.arange(n) * h - delay
    out = np.zeros(n)
    ok = tk > 0
    out[ok] = CubicSpline(np.arange(n) * h, s)(tk[ok])
    return out


# --------------------------------------------------------------------------- input operators
def play_operators(u: np.ndarray, r: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
    """Play (backlash) operator outputs, one row per threshold r_i >= 0.

    ``p[n] = max(u[n] - r, min(u[n] + r, p[n-1]))`` with ``p[-1] = u[0]``
    (the operators start centred on the first input value unless ``initial``
    is given). Work is done only where the input changes.
    """
    u = np.asarray(u, dtype=float)
    r = np.atleast_1d(np.asarray(r, dtype=float))
    out = np.empty((r.size, u.size))
    p = np.full(r.size, u[0]) if initial is None else np.asarray(initial, dtype=float).copy()
    change = np.flatnonzero(np.diff(u, prepend=u[0] - 1.0) != 0.0)
    stops = np.append(change[1:], u.size)
    for i0, i1 in zip(change, stops):
        p = np.maximum(u[i0] - r, np.minimum(u[i0] + r, p))
        out[:, i0:i1] = p[:, None]
    return out


#: Play-operator states before the record, as multiples of the threshold added to u[0].
INITIAL_STATES = {"centred": 0.0, "ascending": -1.0, "descending": 1.0}


def hysteresis_input(u: np.ndarray, r, w, initial: str = "centred") -> np.ndarray:
    """v = u + sum_i w_i play_{r_i}[u] (Prandtl-Ishlinskii).

    ``initial``: the operators' state before the record -- "centred" on u[0],
    "ascending" (the input last rose to u[0]: p = u[0] - r) or "descending"
    (it last fell to u[0]: p = u[0] + r).
    """
    w = np.atleast_1d(np.asarray(w, dtype=float))
    r = np.atleast_1d(np.asarray(r, dtype=float))
    u = np.asarray(u, dtype=float)
    if initial not in INITIAL_STATES:
        raise ModelError(f"hysteresis initial must be one of {', '.join(INITIAL_STATES)}, got {initial!r}")
    return u + w @ play_operators(u, r, initial=u[0] + INITIAL_STATES[initial] * r)


def polynomial_input(u: np.ndarray, k2: float = 0.0, k3: float = 0.0) -> np.ndarray:
    """v = u + k2 u^2 + k3 u^3 (static nonlinear gain on the absolute input)."""
    u = np.asarray(u, dtype=float)
    return u + k2 * u * u + k3 * u * u * u


def loop_width(r, w, u_range: float) -> float:
    """Widest vertical opening (input units, relative to the large-signal slope) of the PI loop.

    A play operator of threshold r cycled over a range >= 2 r opens a loop of
    height 2 r; over a range A < 2 r it never moves. The PI loop over the
    measured input range is therefore ``sum_i w_i 2 min(r_i, A/2) / (1 + sum_i w_i)``.
    """
    r = np.atleast_1d(np.asarray(r, dtype=float))
    w = np.atleast_1d(np.asarray(w, dtype=float))
    slope = 1.0 + float(w.sum())
    if slope == 0.0:
        return float("nan")
    return float(np.sum(w * 2.0 * np.minimum(r, u_range / 2.0)) / slope)


# --------------------------------------------------------------------------- superposition
class Superposer:
    """Zero-order-hold superposition y = sum_k dx_k S(t - t_k) for fixed input rows.

    Built once per record and input features (rows of ``x``); ``apply(S)``
    then costs one FFT of S plus one inverse FFT per row on uniform grids
    (the input spectra are cached), or an explicit sum over the input changes
    on non-uniform ones. ``x_pre`` is the input before the record (default:
    the first sample, i.e. deviation variables; 0 = from rest) and ``t_pre``
    the time of that first jump (default t[0]).
    """

    def __init__(self, t: np.ndarray, x: np.ndarray, x_pre=None, t_pre: float | None = None) -> None:
        self.t = np.asarray(t, dtype=float)
        x = np.atleast_2d(np.asarray(x, dtype=float))
        n = self.t.size
        if x.shape[1] != n:
            raise DataError(f"input rows have {x.shape[1]} samples, time has {n}")
        pre = x[:, 0] if x_pre is None else np.broadcast_to(np.asarray(x_pre, dtype=float), (x.shape[0],))
        self.dx = np.diff(x, axis=1, prepend=pre[:, None])
        self.rows = x.shape[0]
        self.n = n
        self.t_pre = float(self.t[0] if t_pre is None else t_pre)
        self.uniform = is_uniform(self.t) and self.t_pre == self.t[0]
        if self.uniform:
            self.h = (self.t[-1] - self.t[0]) / max(n - 1, 1)
            self.nfft = next_fast_len(2 * n)
            self.spectra = rfft(self.dx, self.nfft, axis=1)
        else:
            self.h = float("nan")
            any_change = np.flatnonzero(np.any(self.dx != 0.0, axis=0))
            if any_change.size * n > MAX_PAIRS:
                raise DataError(
                    f"non-uniform time with {any_change.size} input changes: the exact superposition would need "
                    f"{any_change.size * n} step-response evaluations; resample to a uniform grid first")
            self.change = any_change
            tc = self.t[any_change].copy()
            if any_change.size and any_change[0] == 0:
                tc[0] = self.t_pre
            self.tau = self.t[None, :] - tc[:, None]  # (changes, n)

    @property
    def grid_tau(self) -> np.ndarray:
        """Times k h (uniform records) at which apply() wants the step response."""
        return np.arange(self.n) * self.h

    def apply(self, step: np.ndarray | StepFn) -> np.ndarray:
        """Rows of outputs for a step response given on the grid (uniform) or as a function of tau."""
        if self.uniform:
            s = step(self.grid_tau) if callable(step) else np.asarray(step, dtype=float)
            fs = rfft(s, self.nfft)
            return irfft(self.spectra * fs[None, :], self.nfft, axis=1)[:, : self.n]
        if not callable(step):
            raise ValueError("non-uniform records need the step response as a function of time")
        if self.change.size == 0:
            return np.zeros((self.rows, self.n))
        tau = self.tau
        s = np.zeros(tau.shape)
        pos = tau > 0
        s[pos] = step(tau[pos])
        return self.dx[:, self.change] @ s


# --------------------------------------------------------------------------- output operators
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
        low = lfilter([c0, c1], [1.0, -a], y, axis=-1)
        return y - low
    a = np.exp(-dt / tau)
    c0 = 1.0 - tau * (-np.expm1(-dt / tau)) / dt
    c1 = (1.0 - a) - c0
    low = np.zeros_like(y)
    for n in range(1, t.size):
        low[..., n] = a[n - 1] * low[..., n - 1] + c0[n - 1] * y[..., n] + c1[n - 1] * y[..., n - 1]
    return y - low


def periodic_columns(t: np.ndarray, f_hz: float, harmonics: int = 1) -> np.ndarray:
    """Rows sin(2 pi k f t), cos(2 pi k f t) for k = 1..harmonics (shape (2 harmonics, n))."""
    t = np.asarray(t, dtype=float)
    rows = []
    for k in range(1, harmonics + 1):
        arg = 2.0 * math.pi * k * f_hz * t
        rows += [np.sin(arg), np.cos(arg)]
    return np.array(rows)


# --------------------------------------------------------------------------- forward model
def _check_names(effects: dict) -> None:
    unknown = [k for k in effects if k not in EFFECTS]
    if unknown:
        raise ModelError(f"unknown effect(s) {', '.join(unknown)}; the catalogue is {', '.join(EFFECTS)}")


def _listify(value) -> np.ndarray:
    return np.atleast_1d(np.asarray(value, dtype=float))


def simulate_with_effects(model: CreepModel, t: np.ndarray, u: np.ndarray, effects: dict[str, dict] | None = None,
                          *, offset: float = 0.0, u_pre: float | None = 0.0, t_pre: float | None = None) -> np.ndarray:
    """Output of the base model extended by catalogue effects, for a zero-order-held input.

    ``effects`` maps catalogue names to their parameter dicts (see the module
    table), e.g. ``{"delay": {"delay_s": 2.5e-3}, "drift": {"rate": 1e-3}}``.
    ``u_pre`` is the input before the record (0: from rest, as ``simulate``
    assumes; None: the first sample, i.e. the record starts in equilibrium)
    and ``t_pre`` the time of the jump from ``u_pre`` to ``u[0]`` (default
    t[0]). Works for uniform and non-uniform (e.g. log-spaced) time. With no
    effects and uniform time it equals ``simulate(model, t, u)`` to rounding.
    """
    effects = dict(effects or {})
    _check_names(effects)
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    if t.shape != u.shape or t.ndim != 1:
        raise DataError(f"t and u must be 1-D of equal length (got {t.shape}, {u.shape})")
    v = u
    pre = u_pre
    if "hysteresis" in effects:
        p = effects["hysteresis"]
        v = hysteresis_input(v, p.get("r", []), p.get("w", []), p.get("initial", "centred"))
    if "nonlinear_gain" in effects:
        p = effects["nonlinear_gain"]
        k2, k3 = float(p.get("k2", 0.0)), float(p.get("k3", 0.0))
        v = polynomial_input(v, k2, k3)
        if pre is not None:
            pre = float(polynomial_input(np.array([pre]), k2, k3)[0])
    sup = Superposer(t, v, x_pre=pre, t_pre=t_pre)
    d = float(effects.get("delay", {}).get("delay_s", 0.0))
    if d < 0:
        raise ModelError(f"delay_s must be >= 0, got {d}")

    if sup.uniform:
        s = model.b * delayed_grid(base_step_grid(model.alpha, model.a1, model.a2, sup.h, sup.n), sup.h, d)
    parts: list[StepFn] = []
    if "second_mode" in effects:
        p = effects["second_mode"]
        g, fn, z = float(p["gain"]), float(p["fn_hz"]), float(p.get("zeta", 0.05))
        parts.append(lambda tau, g=g, fn=fn, z=z: g * resonance_step(fn, z, tau))
    if "second_creep" in effects:
        p = effects["second_creep"]
        c, a2_ = float(p["gain"]), float(p["alpha2"])
        if not 0.0 < a2_ <= 1.0:
            raise ModelError(f"second_creep alpha2 must satisfy 0 < alpha2 <= 1, got {a2_}")
        parts.append(lambda tau, c=c, a=a2_: c * creep_step(a, tau))

    def extra(tau: np.ndarray) -> np.ndarray:
        out = np.zeros(np.shape(tau))
        for fn_ in parts:
            out = out + fn_(tau)
        return out

    if sup.uniform:
        total = s + (extra(sup.grid_tau - d) if parts else 0.0)
        y = sup.apply(total)[0]
    else:
        def total_fn(tau: np.ndarray) -> np.ndarray:
            tt = np.asarray(tau) - d
            return model.b * base_step_at(model.alpha, model.a1, model.a2, tt) + extra(tt)
        y = sup.apply(total_fn)[0]
    if "leakage" in effects:
        y = leakage_filter(t, y, float(effects["leakage"]["tau_s"]))
    y = y + offset
    if "drift" in effects:
        p = effects["drift"]
        y = y + float(p.get("rate", 0.0)) * (t - t[0]) + float(p.get("offset", 0.0))
    if "periodic_disturbance" in effects:
        p = effects["periodic_disturbance"]
        amp, ph = _listify(p.get("amplitude", 0.0)), _listify(p.get("phase", 0.0))
        ph = np.broadcast_to(ph, amp.shape)
        f = float(p["f_hz"])
        for k, (a, phi) in enumerate(zip(amp, ph), start=1):
            y = y + a * np.sin(2.0 * math.pi * k * f * t + phi)
    return y
