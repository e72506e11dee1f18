"""Compare a model with a measurement: fit% (NRMSE), error metrics and overlay data (MATLAB ``compare``)."""
from __future__ import annotations

import numpy as np

from ..metrics import fit_percent, noise_floor_fit, rms


def error_metrics(y: np.ndarray, y_hat: np.ndarray, noise_std: float | None = None) -> dict[str, float]:
    """fit% (100 (1 - ||e|| / ||y - mean y||)), RMS, MAE, max |e|, R^2, and the noise-floor fit% if known."""
    y = np.asarray(y, dtype=float)
    e = y - np.asarray(y_hat, dtype=float)
    var = float(np.var(y))
    out = {
        "fit_percent": fit_percent(y, y_hat),
        "residual_rms": rms(e),
        "residual_mae": float(np.mean(np.abs(e))),
        "residual_max_abs": float(np.max(np.abs(e))),
        "residual_mean": float(np.mean(e)),
        "r2": float(1.0 - np.mean(e * e) / var) if var > 0 else float("nan"),
    }
    if noise_std is not None and np.isfinite(noise_std):
        out["noise_floor_fit_percent"] = noise_floor_fit(y, noise_std)
        out["residual_over_noise"] = out["residual_rms"] / noise_std if noise_std > 0 else float("inf")
    return out


def overlay(t: np.ndarray, y: np.ndarray, **models: np.ndarray) -> dict[str, np.ndarray]:
    """Columns for an overlay plot: time, measurement and each named model output with its residual."""
    out = {"t": np.asarray(t, dtype=float), "y": np.asarray(y, dtype=float)}
    for name, y_hat in models.items():
        out[name] = np.asarray(y_hat, dtype=float)
        out[f"{name}_residual"] = out["y"] - out[name]
    return out


def compare(y: np.ndarray, noise_std: float | None = None, **models: np.ndarray) -> dict[str, dict[str, float]]:
    """Error metrics of each named model output against the measurement y."""
    return {name: error_metrics(y, y_hat, noise_std) for name, y_hat in models.items()}
