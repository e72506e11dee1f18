"""Shared numerics of the forward model: unit-step responses and their zero-order-hold superposition.

Every linear path of the extended model is evaluated the same way: the input
is zero-order held, so the output is a superposition of shifted *unit-step
responses*, ``y(t_n) = sum_k du_k S(t_n - t_k)``. This module provides the
step responses (on a uniform grid or at arbitrary times, optionally delayed)
and the superposition (FFT on uniform grids, explicit sums on non-uniform
ones); the effect modules beside it and the extended-model fit in
``creep_online.diagnostics.extended`` reuse them. numpy/scipy plus the core
simulator only.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft
from scipy.interpolate import CubicSpline
from ..special import digamma

from ..discretize import resonance_poles, step_response_grid
from ..errors import DataError

#: Points per grid of the multi-resolution step response used at arbitrary times.
MULTIGRID_POINTS = 2048
#: Ratio between successive grids of the multi-resolution step response.
MULTIGRID_RATIO = 8.0
#: Scratch memory of one batch of rows in ``Superposer.apply`` (their spectra and padded transforms, about three
#: times this in all) and ``Superposer.row_spectra`` (their padded copies): two rows of a 50,000-sample record,
#: as fast per row as eight (the transforms are per row) for a third of the scratch beside the output.
SCRATCH_BYTES = 4 * 2**20
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
    p1, d, live, e1, ratio = _two_pole_terms(fn_hz, zeta, tau)
    # S = 1 - e^{p1 t} + p1 e^{p1 t} (e^{d t} - 1)/d  (limit-safe form of the two-pole formula)
    out = np.ones(tau.shape)
    out[live] = (1.0 - e1 + p1 * e1 * ratio).real
    return out


#: Where Re(p1) tau is below this the transient is < 1e-304: a step response is 1 there, its derivatives 0
#: (not evaluated: complex exponentials that underflow to subnormals cost ~10x more than ordinary ones).
DECAYED = -700.0


def _two_pole_terms(fn_hz: float, zeta: float, tau: np.ndarray) -> tuple[complex, complex, np.ndarray, np.ndarray,
                                                                          np.ndarray]:
    """(p1, d, live, e^{p1 tau}, (e^{d tau} - 1)/d) of 1/(1 + a1 s + a2 s^2), the last two where ``live``.

    p1 is the slow pole, d = p2 - p1; ``live``: the samples whose transient has
    not decayed below 1e-304 (``DECAYED``). tau >= 0.
    """
    wn = 2.0 * math.pi * fn_hz
    p1, p2 = resonance_poles(2.0 * zeta / wn, 1.0 / wn**2)  # slow, fast
    d = p2 - p1
    live = p1.real * tau > DECAYED
    tl = tau[live]
    x = d * tl
    x = np.maximum(x.real, DECAYED) + 1j * x.imag            # e^x below 1e-304 (stiff poles) is 0 to rounding
    small = np.abs(x) < 1e-6
    ratio = np.empty(tl.shape, dtype=complex)
    ratio[~small] = np.expm1(x[~small]) / d
    ratio[small] = tl[small] * (1.0 + x[small] / 2.0)
    return p1, d, live, np.exp(p1 * tl), ratio


def creep_step_derivative(alpha: float, tau: np.ndarray) -> np.ndarray:
    """d/d(alpha) of ``creep_step``: S (ln tau - psi(1 + alpha)) (0 for tau <= 0; psi: digamma)."""
    tau = np.asarray(tau, dtype=float)
    out = np.zeros(tau.shape)
    pos = tau > 0
    out[pos] = creep_step(alpha, tau[pos]) * (np.log(tau[pos]) - digamma(1.0 + alpha))
    return out


def resonance_step_derivatives(fn_hz: float, zeta: float, tau: np.ndarray) -> np.ndarray:
    """d/d(log10 fn) and d/d(log10 zeta) of ``resonance_step``, shape (2, len(tau)) (0 for tau <= 0).

    S depends on wn only through wn tau, so dS/d(log10 fn) = ln10 tau g(tau)
    with g = S' the impulse response. In the damping, dS/d(a1) = -(g * g)(tau)
    (dG/da1 = -s G^2), a1 = 2 zeta / wn; the self-convolution in closed form is
    wn^4 e^{p1 tau} tau^3 psi(x), x = (p2 - p1) tau, psi below (finite for
    repeated poles). Why: the extended fit's Jacobian in a second mode's
    parameters without two more evaluations per step (finite differences).
    """
    tau = np.maximum(np.asarray(tau, dtype=float), 0.0)
    wn = 2.0 * math.pi * fn_hz
    p1, d, live, e1, ratio = _two_pole_terms(fn_hz, zeta, tau)
    tl = tau[live]
    impulse = wn**2 * (e1 * ratio).real
    self_conv = wn**4 * (e1 * tl**3 * _self_convolution_factor(d * tl)).real
    ln10 = math.log(10.0)
    out = np.zeros((2, tau.size))
    out[0, live] = ln10 * tl * impulse
    out[1, live] = -ln10 * zeta * (2.0 / wn) * self_conv
    return out


#: Below this |x| the self-convolution factor is summed as its series (the closed form cancels).
_SERIES_BELOW = 0.1
_SERIES = np.array([(m - 2) / math.factorial(m) for m in range(3, 14)])


def _self_convolution_factor(x: np.ndarray) -> np.ndarray:
    """psi(x) = (x (1 + e^x) + 2 (1 - e^x)) / x^3 = sum_{m>=3} (m - 2)/m! x^(m-3) (complex x, Re x <= 0)."""
    out = np.empty(x.shape, dtype=complex)
    small = np.abs(x) < _SERIES_BELOW
    xs = x[small]
    acc = np.zeros(xs.shape, dtype=complex)
    for c in _SERIES[::-1]:
        acc = acc * xs + c
    out[small] = acc
    xl = x[~small]
    em1 = np.expm1(np.maximum(xl.real, DECAYED) + 1j * xl.imag)
    out[~small] = (2.0 * xl + (xl - 2.0) * em1) / xl**3
    return out


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
    """S(k h - delay) from S on the grid k h (S = 0 before 0), by cubic interpolation.

    ``s`` may hold several responses as rows (e.g. a response and its parameter
    derivatives: the spline is linear in the data, so it delays derivatives too).
    """
    if delay <= 0.0:
        return s
    n = s.shape[-1]
    tk = np.arange(n) * h - delay
    out = np.zeros(s.shape)
    ok = tk > 0
    out[..., ok] = CubicSpline(np.arange(n) * h, s, axis=-1)(tk[ok])
    return out


def delayed_grid_slope(s: np.ndarray, h: float, delay: float) -> np.ndarray:
    """d/d(delay) of ``delayed_grid(s, h, delay)``: -S'(k h - delay) from the same cubic spline (0 before 0)."""
    n = s.shape[-1]
    tk = np.arange(n) * h - max(delay, 0.0)
    out = np.zeros(s.shape)
    ok = tk > 0
    out[..., ok] = -CubicSpline(np.arange(n) * h, s, axis=-1)(tk[ok], 1)
    return out


# --------------------------------------------------------------------------- superposition
def _steps(x: np.ndarray, pre: np.ndarray, in_place: bool) -> np.ndarray:
    """``np.diff(x, axis=1, prepend=pre[:, None])``: the same subtractions, without its concatenated copy of the
    rows; ``in_place``, in x itself, a row at a time (each row's previous samples copied first: one row of
    scratch instead of a second set of rows, 5-10 MB for hysteresis' rows of a 50,000-sample record)."""
    if not in_place:
        dx = np.empty_like(x)
        np.subtract(x[:, :1], pre[:, None], out=dx[:, :1])
        np.subtract(x[:, 1:], x[:, :-1], out=dx[:, 1:])
        return dx
    for i in range(x.shape[0]):
        previous = x[i, :-1].copy()
        np.subtract(x[i, 1:], previous, out=x[i, 1:])
        x[i, 0] -= pre[i]
    return x


class Superposer:
    """Zero-order-hold superposition y = sum_k dx_k S(t - t_k) for fixed input rows.

    Built once per record and input features (rows of ``x``); ``apply(S)``
    then costs one FFT of S plus one inverse FFT per row on uniform grids
    (the input spectra are cached), or an explicit sum over the input changes
    on non-uniform ones. ``x_pre`` is the input before the record (default:
    the first sample, i.e. deviation variables; 0 = from rest) and ``t_pre``
    the time of that first jump (default t[0]). ``overwrite_x``: the rows are
    the caller's to overwrite (a float array built for this superposer), and
    their steps are computed in their place instead of beside them.
    """

    def __init__(self, t: np.ndarray, x: np.ndarray, x_pre=None, t_pre: float | None = None,
                 keep_spectra: bool = True, overwrite_x: bool = False) -> None:
        self.t = np.asarray(t, dtype=float)
        x = np.atleast_2d(np.asarray(x, dtype=float))
        n = self.t.size
        if x.shape[1] != n:
            raise DataError(f"input rows have {x.shape[1]} samples, time has {n}")
        pre = x[:, 0] if x_pre is None else np.broadcast_to(np.asarray(x_pre, dtype=float), (x.shape[0],))
        self.dx = _steps(x, pre.copy(), overwrite_x and x.flags.writeable and x.flags.c_contiguous)
        self.rows = x.shape[0]
        self.n = n
        self.t_pre = float(self.t[0] if t_pre is None else t_pre)
        self.uniform = is_uniform(self.t) and self.t_pre == self.t[0]
        if self.uniform:
            self.h = (self.t[-1] - self.t[0]) / max(n - 1, 1)
            self.nfft = next_fast_len(2 * n)
            # ``keep_spectra`` False: each ``apply`` transforms the rows again, a few at a time (for a superposer
            # used once: its spectra are twice its rows' memory)
            self.spectra = self.row_spectra() if keep_spectra else None
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

    def row_spectra(self) -> np.ndarray:
        """The input rows' padded spectra ``rfft(dx, nfft, axis=1)``, a few rows at a time: the same numbers (each
        row's transform is its own) without the padded copy of every row at once beside them (10 MB for
        hysteresis' 13 rows of a 50,000-sample record)."""
        out = np.empty((self.rows, self.nfft // 2 + 1), dtype=complex)
        batch = max(1, SCRATCH_BYTES // (8 * self.nfft))
        for a in range(0, self.rows, batch):
            out[a:a + batch] = rfft(self.dx[a:a + batch], self.nfft, axis=1)
        return out

    @property
    def grid_tau(self) -> np.ndarray:
        """Times k h (uniform records) at which apply() wants the step response."""
        return np.arange(self.n) * self.h

    def apply(self, step: np.ndarray | StepFn, out: np.ndarray | None = None) -> np.ndarray:
        """Rows of outputs for a step response given on the grid (uniform) or as a function of tau.

        Uniform records also take several step responses on the grid at once
        (shape (k, n)) and give (k, rows, n): one superposition per response.
        ``out``: an array of that shape to write them in (e.g. the first rows of
        a design the caller assembles), returned.
        """
        if self.uniform:
            s = step(self.grid_tau) if callable(step) else np.asarray(step, dtype=float)
            fs = rfft(s, self.nfft, axis=-1)
            if out is None:
                out = np.empty(fs.shape[:-1] + (self.rows, self.n))
            # a few rows at a time (each row's transform is its own): the padded transforms of every row at once
            # were 4x the output, 50 MB beside it for hysteresis' 25 rows of a 50,000-sample record
            batch = max(1, SCRATCH_BYTES // (16 * self.nfft * max(1, s.size // self.n)))
            for a in range(0, self.rows, batch):
                spectra = (self.spectra[a:a + batch] if self.spectra is not None
                           else rfft(self.dx[a:a + batch], self.nfft, axis=1))
                out[..., a:a + batch, :] = irfft(spectra * fs[..., None, :], self.nfft, axis=-1)[..., : self.n]
            return out
        if not callable(step):
            raise ValueError("non-uniform records need the step response as a function of time")
        if self.change.size == 0:
            value = np.zeros((self.rows, self.n))
        else:
            tau = self.tau
            s = np.zeros(tau.shape)
            pos = tau > 0
            s[pos] = step(tau[pos])
            value = self.dx[:, self.change] @ s
        if out is None:
            return value
        out[...] = value
        return out

    def products(self, steps: np.ndarray, weights: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For step responses S_k on the grid (uniform): (sum_i w_i apply(S_k)_i, apply(S_k) @ v) per k.

        Shapes (k, n) and (k, rows): what a Jacobian needs of the columns
        ``apply`` would give (their weighted sum and their products with a
        residual) without forming them, one inverse FFT per response for the
        sums (the rows' spectra are summed first) and, for the products,
        apply(S)_i . v = S . c_i with c_i the cross-correlation of dx_i and v:
        one inverse FFT per row (or, with more rows than responses,
        dx_i . q_k with q_k the cross-correlation of v and S_k: one per response).
        """
        steps = np.atleast_2d(steps)
        if self.spectra is None:
            self.spectra = self.row_spectra()
        fs = rfft(steps, self.nfft, axis=-1)
        summed = irfft((weights @ self.spectra) * fs, self.nfft, axis=-1)[:, : self.n]
        fv = rfft(v, self.nfft)
        if self.rows < steps.shape[0]:
            c = irfft(np.conj(self.spectra) * fv, self.nfft, axis=-1)[:, : self.n]
            return summed, steps @ c.T
        q = irfft(fv * np.conj(fs), self.nfft, axis=-1)[:, : self.n]
        return summed, q @ self.dx.T
