"""The spectral lines of a periodic input: where an output line is locked to the input.

A record driven by a periodic input (a 1 Hz triangle, a multisine) has its
response at the input's fundamental and harmonics. A fitted "disturbance" line,
or a resonance narrower than the record can resolve, sitting on one of those
harmonics is locked to the input: the record cannot tell it from an input
nonlinearity the catalogue lacks, so it is no evidence of a disturbance or of a
mode. (The micromanipulator's 1 Hz record: a periodic disturbance at 3.000 Hz
and a "second mode" at 1.999 Hz with zeta at its bound ranked 3rd and 4th.)
"""
from __future__ import annotations

import numpy as np

#: Share of the input's variance its fundamental's harmonics must hold for the input to count as periodic.
PERIODIC_SHARE = 0.8
#: Half-width, in frequency bins, of a harmonic's line.
LINE_BINS = 1
#: Highest harmonic an output line is compared with: the input's (and a nonlinearity's) harmonics fall with
#: their order, and on a slow drive every mains frequency is some high harmonic (50 Hz = 50 x 1 Hz).
MAX_HARMONIC = 10
#: Periods of the input the record must hold: the harmonics' lines (3 bins each) then cover at most 3/8 of the
#: spectrum, so a broadband input (a random staircase: its lowest bins strongest) never passes as periodic.
MIN_PERIODS = 8


def input_fundamental(t: np.ndarray, u: np.ndarray) -> float | None:
    """The fundamental frequency (Hz) of a periodic input on a uniform grid; None if the input is not periodic."""
    n = u.size
    if n < 16 or t[-1] <= t[0]:
        return None
    power = np.abs(np.fft.rfft(u - np.mean(u))) ** 2
    total = float(power[1:].sum())
    if total <= 0.0:
        return None
    k0 = 1 + int(np.argmax(power[1:]))
    if k0 < MIN_PERIODS:
        return None                             # a trend, a few steps, a slow staircase: no comb to speak of
    near = np.zeros(power.size, dtype=bool)
    for centre in range(k0, power.size, k0):
        near[max(centre - LINE_BINS, 1):centre + LINE_BINS + 1] = True
    if power[near].sum() < PERIODIC_SHARE * total:
        return None
    around = power[k0 - 1:k0 + 2]
    centre = k0 + float(np.dot(around, (-1.0, 0.0, 1.0)) / around.sum())   # between bins: to ~0.1 bin
    return centre / (n * (t[1] - t[0]))


def harmonic_of_input(f_hz: float, t: np.ndarray, u: np.ndarray) -> tuple[int, float] | None:
    """(k, f0) when ``f_hz`` lies on the k-th harmonic of a periodic input's fundamental f0, else None.

    Harmonics up to ``MAX_HARMONIC``. Tolerance: ``LINE_BINS`` frequency bins
    (1/T) for the line's own width, plus 0.1 bin per order for the
    fundamental's reading.
    """
    f0 = input_fundamental(t, u)
    if f0 is None or not np.isfinite(f_hz) or f_hz <= 0.0:
        return None
    k = max(int(round(f_hz / f0)), 1)
    df = 1.0 / (u.size * (t[1] - t[0]))
    return (k, f0) if k <= MAX_HARMONIC and abs(f_hz - k * f0) <= (LINE_BINS + 0.1 * k) * df else None
