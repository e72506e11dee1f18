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
    """Robust white-noise std from second differences (MAD), blind to smooth signal content."""
    y = np.asarray(y, dtype=float)
    if y.size < 4:
        return float("nan")
    d2 = np.diff(y, 2) / np.sqrt(6.0)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))))
