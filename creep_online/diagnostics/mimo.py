"""A virtual single-input experiment from periodic multi-input data (e.g. orthogonal multisines).

When m inputs are active at once, ``y`` is not the response to ``u`` alone,
and a SISO diagnosis of the raw columns mixes m paths. With R >= m
realisations of a periodic steady-state experiment, the frequency response
row of an output is solved line by line, ``Y_r(f) = sum_j G_j(f) U_rj(f)``,
and the output channel ``j`` alone would have produced is synthesised,
``y_j = IFFT(G_j U_j)``: a clean SISO record (steady state, repeated for a
few periods) the diagnosis can use.
"""
from __future__ import annotations

import numpy as np

from ..errors import DataError


def virtual_siso(inputs: list[np.ndarray], outputs: list[np.ndarray], fs: float, period: int,
                 channel: int = 0, periods: int = 2, skip_periods: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, u, y) of input ``channel`` alone, from R realisations of (N, m) inputs and (N,) outputs.

    Uses one steady-state period per realisation (after ``skip_periods``)
    and tiles the result ``periods`` times.
    """
    m = np.atleast_2d(inputs[0]).shape[1]
    if len(inputs) < m or len(outputs) != len(inputs):
        raise DataError(f"need at least {m} realisations of the {m}-input experiment, got {len(inputs)}")
    a, b = skip_periods * period, (skip_periods + 1) * period
    U = np.stack([np.fft.rfft(np.asarray(u, dtype=float)[a:b], axis=0) for u in inputs], axis=1)  # (f, R, m)
    Y = np.stack([np.fft.rfft(np.asarray(y, dtype=float)[a:b]) for y in outputs], axis=1)        # (f, R)
    level = np.abs(U).max()
    g = np.zeros((U.shape[0], m), dtype=complex)
    for k in range(U.shape[0]):
        if np.abs(U[k]).max() > 1e-6 * level:  # excited line
            g[k] = np.linalg.lstsq(U[k], Y[k], rcond=None)[0]
    uj = U[:, 0, channel]
    y = np.fft.irfft(g[:, channel] * uj, period)
    u = np.fft.irfft(uj, period)
    t = np.arange(period * periods) / fs
    return t, np.tile(u, periods), np.tile(y, periods)
