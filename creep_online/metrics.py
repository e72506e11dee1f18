"""Fit measures a controls engineer expects (MATLAB compare/goodnessOfFit conventions)."""
from __future__ import annotations

import numpy as np


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> float:
    """NRMSE fit: 100 (1 - ||y - y_hat|| / ||y - mean(y)||); 100 is perfect, can be negative."""
    y = np.asarray(y, dtype=float)
    den = np.linalg.norm(y - y.mean())
    if den == 0.0:
        return float("nan")
    return float(100.0 * (1.0 - np.linalg.norm(y - np.asarray(y_hat, dtype=float)) / den))


def rms(x: np.ndarray) -> float:
    """Root mean square."""
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def noise_floor_fit(y: np.ndarray, noise_std: float) -> float:
    """The fit% a perfect model reaches when the measurement carries white noise of this std."""
    y = np.asarray(y, dtype=float)
    return float(100.0 * (1.0 - noise_std * np.sqrt(y.size) / np.linalg.norm(y - y.mean())))


def noise_std_estimate(y: np.ndarray) -> float:
    """Robust white-noise std from second differences (MAD), blind to smooth signal content.

    The second differences come from one compiled pass (``kernels.second_differences``)
    and, for finite y, both medians are in-place selections (``_median_inplace``):
    np.median cost ~1.3 ms per 100,000 samples (its NaN check partitions a second
    element), numba's median ~1.5 ms; the selections ~0.2 ms. Same value bit for
    bit. Non-finite differences keep np.median, for its NaN semantics.
    """
    from . import kernels   # numba: loaded on first use, so that importing this module stays light
    y = np.ascontiguousarray(y, dtype=float)
    if y.size < 4:
        return float("nan")
    d2 = kernels.second_differences(y)
    if not np.isfinite(d2).all():
        return float(1.4826 * np.median(np.abs(d2 - np.median(d2))))
    d2 -= _median_inplace(d2)         # reorders d2: the deviations' median does not depend on the order
    np.abs(d2, out=d2)
    return float(1.4826 * _median_inplace(d2))


def _median_inplace(v: np.ndarray) -> float:
    """np.median of finite v (the same value bit for bit), reordering v: one selection at n // 2 and, for
    even n, the largest element below it; their mean as np.mean computes it, (a + b) / 2."""
    k = v.size // 2
    v.partition(k)
    if v.size % 2:
        return v[k]
    return (v[:k].max() + v[k]) / 2


def long_run_variance_factor(r: np.ndarray, width: int | None = None) -> float:
    """How much more a slowly varying weighted sum of r varies than white noise of r's variance would.

    The ratio (block-mean variance x width) / variance over blocks of ``width``
    samples (default n / 50, 16 to 256): 1 for white noise, (1 + rho) / (1 - rho)
    for AR(1) noise with blocks much longer than its correlation time. Gauss-
    Newton covariances assume white noise; their variances are multiplied by
    this factor (never below 1), since the parameters' sensitivities are slow
    compared with the noise.
    """
    r = np.asarray(r, dtype=float)
    r = r - r.mean()
    width = int(np.clip(r.size // 50, 16, 256)) if width is None else int(width)
    k = r.size // width
    var = float(r @ r) / max(r.size, 1)
    if k < 8 or var <= 0.0:
        return 1.0
    means = r[:k * width].reshape(k, width).mean(axis=1)
    return max(1.0, float(np.mean(means * means)) * width / var)


def creep_error(t: np.ndarray, r: np.ndarray, y: np.ndarray, settle_s: float,
                skip_before: float = 0.0) -> dict:
    """Output minus reference on every hold, from ``settle_s`` after its step to its end.

    Returns the worst ``max_abs``, the ``rms`` over all windows and ``per_hold``
    (start time, max abs, rms); holds starting before ``skip_before`` are left out.
    """
    steps = np.flatnonzero(np.diff(r) != 0) + 1
    ends = np.append(steps[1:], r.size)
    per, pooled = [], []
    for s, e in zip(steps, ends):
        if t[s] < skip_before:
            continue
        sel = slice(int(np.searchsorted(t, t[s] + settle_s)), int(e))
        err = y[sel] - r[sel]
        if err.size == 0:
            continue
        per.append({"t": float(t[s]), "max_abs": float(np.max(np.abs(err))),
                    "rms": float(np.sqrt(np.mean(err * err)))})
        pooled.append(err)
    allerr = np.concatenate(pooled) if pooled else np.zeros(1)
    return {"max_abs": float(np.max(np.abs(allerr))), "rms": float(np.sqrt(np.mean(allerr * allerr))),
            "per_hold": per}
