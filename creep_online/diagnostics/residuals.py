"""Residual analysis (MATLAB ``resid``): whiteness, independence from the input, parameter uncertainty.

The 99 % confidence band of a sample correlation of N white samples is about
2.58/sqrt(N). The cross-correlation is taken with the input *increments*
(what a zero-order-held staircase injects; for a random staircase they are
nearly white, so the same band applies; the level u itself is a random walk
whose correlations are large for any residual).
"""
from __future__ import annotations

import math

import numpy as np

from ..model import CreepModel

#: Two-sided 99 % normal quantile.
Z99 = 2.5758293035489


def _xcorr(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised cross-correlation r_ab(k) = sum a[n+k] b[n] / (N sd_a sd_b), k = -max_lag..max_lag."""
    a = np.asarray(a, dtype=float) - np.mean(a)
    b = np.asarray(b, dtype=float) - np.mean(b)
    n = a.size
    den = n * np.std(a) * np.std(b)
    if den == 0:
        return np.zeros(2 * max_lag + 1)
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    full = np.fft.irfft(np.fft.rfft(a, nfft) * np.conj(np.fft.rfft(b, nfft)), nfft)
    lags = np.arange(-max_lag, max_lag + 1)
    return full[lags % nfft] / den


def autocorrelation(r: np.ndarray, max_lag: int = 25) -> dict:
    """Residual autocorrelation at lags 0..max_lag with the 99 % band; ``white`` if lags >= 1 stay inside."""
    c = _xcorr(r, r, max_lag)[max_lag:]
    bound = Z99 / math.sqrt(len(r))
    outside = int(np.sum(np.abs(c[1:]) > bound))
    return {"lags": list(range(max_lag + 1)), "values": c.tolist(), "bound": bound,
            "outside": outside, "white": _passes(c[1:], bound)}


def cross_correlation(r: np.ndarray, u: np.ndarray, max_lag: int = 25) -> dict:
    """Residual vs input-increment cross-correlation at lags -max_lag..max_lag with the 99 % band."""
    du = np.diff(np.asarray(u, dtype=float), prepend=u[0])
    c = _xcorr(r, du, max_lag)
    bound = Z99 / math.sqrt(len(r))
    outside = int(np.sum(np.abs(c) > bound))
    return {"lags": list(range(-max_lag, max_lag + 1)), "values": c.tolist(), "bound": bound,
            "outside": outside, "independent": _passes(c, bound)}


def _passes(c: np.ndarray, bound: float) -> bool:
    """Inside the 99 % band up to chance: at most 2 lags outside, none beyond 1.5x the band.

    Among ~25-50 lags one or two excursions happen by chance (1 % each); one
    beyond 1.5x the band (p ~ 1e-4 per lag) does not.
    """
    a = np.abs(c)
    return bool(np.sum(a > bound) <= 2 and not np.any(a > 1.5 * bound))


def parameter_uncertainty(t: np.ndarray, u: np.ndarray, residual: np.ndarray, model: CreepModel,
                          offset: float = 0.0, u_pre: float | None = None, t_pre: float | None = None,
                          weights: np.ndarray | None = None) -> dict[str, dict[str, float]]:
    """1-sigma standard errors of (alpha, a1, a2, b, offset) from the output Jacobian.

    cov = s^2 (J^T J)^-1 with s^2 = RSS/(N - p), J by central differences of
    the simulated output. Valid for white residuals; coloured residuals make
    it optimistic (see ``autocorrelation``).
    """
    from ..effects import simulate_with_effects

    names = ("alpha", "a1", "a2", "b")
    p0 = np.array([getattr(model, k) for k in names])
    w = 1.0 if weights is None else np.asarray(weights, dtype=float)

    def out(p: np.ndarray) -> np.ndarray:
        return simulate_with_effects(CreepModel(*p), t, u, None, u_pre=u_pre, t_pre=t_pre)

    cols = []
    for i in range(4):
        step = 1e-5 * max(abs(p0[i]), 1e-12)
        up, dn = p0.copy(), p0.copy()
        up[i] += step
        dn[i] -= step
        if i == 0:
            up[i] = min(up[i], 0.9999999)
        cols.append((out(up) - out(dn)) / (up[i] - dn[i]))
    cols.append(np.ones(len(t)))
    jac = np.column_stack(cols) * (w[:, None] if weights is not None else 1.0)
    r = np.asarray(residual, dtype=float) * w
    dof = max(len(r) - 5, 1)
    s2 = float(r @ r) / dof
    try:
        cov = s2 * np.linalg.pinv(jac.T @ jac)
    except np.linalg.LinAlgError:
        cov = np.full((5, 5), np.nan)
    vals = list(p0) + [offset]
    out_d = {}
    for i, k in enumerate(names + ("offset",)):
        sd = float(math.sqrt(max(cov[i, i], 0.0)))
        out_d[k] = {"value": float(vals[i]), "std": sd,
                    "rel_std": sd / abs(vals[i]) if vals[i] != 0 else float("inf")}
    return out_d
