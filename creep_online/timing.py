"""Input changes that fall between samples: detect them from the residual and estimate the shift.

When the DAC and the ADC run on different clocks, an input step recorded at
sample k reached the plant up to one sample earlier. The model, fed the
recorded input, then lags each change by a fraction eps_k of a sample, and the
residual near change k is close to

    size_k * eps_k * (S(t - t_k + h) - S(t - t_k)),

the one-sample difference of the unit-step response S. Regressing the
residual on that column over each change's own hold gives eps_k and its
standard error; white noise gives t-statistics of unit variance, so their
sum of squares is chi-square with one degree of freedom per change. Far more
than that means the record's timing does not match its sample grid, and a fit
of alpha on it is biased.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: The chi-square excess (in its own standard deviations) above which the timing is flagged.
TIMING_SIGMAS = 6.0
#: Fewest input changes the test runs on.
MIN_CHANGES = 3


@dataclass
class TimingCheck:
    """Per-change sub-sample shifts (in samples, positive = the plant saw the change earlier)."""

    shift: np.ndarray
    stderr: np.ndarray
    excess_sigmas: float     # (sum t^2 - K) / sqrt(2K)

    @property
    def flagged(self) -> bool:
        return self.excess_sigmas > TIMING_SIGMAS

    def describe(self) -> str:
        """One warning line saying what was found and what it does to the fit."""
        ok = np.isfinite(self.shift)
        return (f"the input changes look asynchronous to the output samples (the residual follows a sub-sample "
                f"shift of the steps at {self.excess_sigmas:.0f} sigma; median shift "
                f"{float(np.median(self.shift[ok])):+.2f} sample, {int(ok.sum())} changes): alpha and the "
                "resonance are biased by it; record u and y on one clock, or resample u to the output's instants")


def check_timing(step: np.ndarray, index: np.ndarray, size: np.ndarray, residual: np.ndarray,
                 noise: float) -> TimingCheck | None:
    """Sub-sample shift of every input change from the fit's residual (None when it cannot be tested).

    ``step`` is the fitted model's step response with its gain (length >= n
    + 1), ``index``/``size`` the input changes, ``noise`` the white-noise std.
    Each change is tested over its own hold (to the next change), where its
    derivative column dominates.
    """
    n = residual.size
    if index.size < MIN_CHANGES or not (math.isfinite(noise) and noise > 0):
        return None
    diff = step[1:n + 1] - step[:n]
    stops = np.append(index[1:], n)
    shift = np.full(index.size, np.nan)
    stderr = np.full(index.size, np.nan)
    for k, (i0, i1, a) in enumerate(zip(index, stops, size)):
        col = a * diff[:i1 - i0]
        cc = float(col @ col)
        if i1 - i0 < 2 or cc <= 0:
            continue
        shift[k] = float(col @ residual[i0:i1]) / cc
        stderr[k] = noise / math.sqrt(cc)
    ok = np.isfinite(shift) & (stderr < 1.0)   # changes too small to tell a sample's shift are left out
    if ok.sum() < MIN_CHANGES:
        return None
    tstat = shift[ok] / stderr[ok]
    k = int(ok.sum())
    return TimingCheck(shift, stderr, float((tstat @ tstat - k) / math.sqrt(2 * k)))
