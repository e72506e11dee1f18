"""Welch spectra and peak finding for the diagnosis, in numpy and ``scipy.fft``: scipy.signal's numbers without it.

``import scipy.signal`` loads ``scipy.stats`` and adds ~24 MB of resident memory to a process (of the ~300
a long diagnosis may use) for three functions. These are the same computations in the same order (the same
operations on the same arrays, so the same bits; ``tests/test_spectra.py`` holds them to scipy.signal's):

* ``welch(x, fs, nperseg)`` and ``csd(x, y, fs, nperseg)``: scipy.signal's defaults (periodic Hann window,
  half-overlapping segments, each segment's mean removed, one-sided density, segments averaged by the mean);
* ``find_peaks(x, prominence=None)``: the local maxima (a plateau's middle sample) and, with ``prominence``,
  those standing at least that far above the higher of their two bases, with ``{"prominences": ...}``.
"""
from __future__ import annotations

import numpy as np
from scipy import fft as sp_fft


def hann_periodic(m: int) -> np.ndarray:
    """The periodic (DFT-even) Hann window of ``m`` samples, computed as ``scipy.signal.get_window("hann", m)``."""
    if m <= 1:
        return np.ones(m)
    fac = np.linspace(-np.pi, np.pi, m + 1, dtype=np.float64)
    w = np.zeros(m + 1, dtype=np.float64)
    for k, a in enumerate(np.array([0.5, 0.5])):
        w += a * np.cos(k * fac)
    return w[:-1]


def _segment_spectra(x: np.ndarray, win: np.ndarray, nperseg: int) -> np.ndarray:
    """(nperseg // 2 + 1, segments) one-sided FFTs of ``x``'s half-overlapping segments, each less its mean and
    windowed by ``win`` (the density-scaled window)."""
    hop = nperseg - nperseg // 2
    count = (x.size - nperseg // 2) // hop
    out = np.zeros((nperseg // 2 + 1, count), dtype=complex)
    for p in range(count):
        seg = x[p * hop:p * hop + nperseg]
        seg = seg - np.mean(seg, -1, keepdims=True)
        out[:, p] = sp_fft.rfft(seg * win.conj(), n=nperseg, axis=-1)
    return out


def _density(x: np.ndarray, y: np.ndarray | None, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """(f, averaged one-sided cross density Y conj(X), or |X|^2 when ``y`` is None; X, Y: the segments' FFTs)."""
    n = x.size if y is None else max(x.size, y.size)
    nperseg = min(int(nperseg), n)
    if nperseg < 1:
        raise ValueError(f"nperseg={nperseg} is not a positive integer")
    win = hann_periodic(nperseg)
    win = win * (1 / np.sqrt(sum(win.real ** 2 + win.imag ** 2) / (1 / fs)))   # density scaling, as scipy sums
    sx = _segment_spectra(x, win, nperseg)
    if y is None:
        pxy = sx.real ** 2 + sx.imag ** 2
    else:
        pxy = _segment_spectra(y, win, nperseg) * sx.conj()
    pxy[1:-1 if nperseg % 2 == 0 else None] *= 2
    pxy = pxy.mean(axis=-1) if pxy.shape[-1] > 1 else np.reshape(pxy, pxy.shape[:-1])
    return sp_fft.rfftfreq(nperseg, 1 / fs), pxy.astype(complex)


def welch(x: np.ndarray, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """(f, one-sided power spectral density) of a real 1-d ``x``: ``scipy.signal.welch(x, fs, nperseg=nperseg)``."""
    f, p = _density(np.asarray(x, dtype=float), None, float(fs), nperseg)
    return f, p.real


def csd(x: np.ndarray, y: np.ndarray, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """(f, one-sided cross spectral density of real 1-d ``x`` and ``y`` of one length):
    ``scipy.signal.csd(x, y, fs, nperseg=nperseg)``."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.size != y.size:
        raise ValueError(f"x and y differ in length ({x.size}, {y.size})")
    return _density(x, y, float(fs), nperseg)


def _local_maxima(x: list[float]) -> list[int]:
    """Indices of the local maxima of ``x``; of a flat peak (a plateau) its middle sample (the left one of two)."""
    peaks, i, last = [], 1, len(x) - 1
    while i < last:
        if x[i - 1] < x[i]:
            ahead = i + 1
            while ahead < last and x[ahead] == x[i]:
                ahead += 1
            if x[ahead] < x[i]:
                peaks.append((i + ahead - 1) // 2)
                i = ahead
        i += 1
    return peaks


def _prominence(x: np.ndarray, peak: int) -> float:
    """How far ``x[peak]`` stands above the higher of its bases: the lowest ``x`` on each side before ``x`` first
    rises above the peak (or ends)."""
    top = x[peak]
    left = np.flatnonzero(~(x[:peak] <= top))
    right = np.flatnonzero(~(x[peak + 1:] <= top))
    lo = left[-1] + 1 if left.size else 0
    hi = peak + 1 + right[0] if right.size else x.size
    return top - max(x[lo:peak + 1].min(), x[peak:hi].min())


def find_peaks(x: np.ndarray, prominence: float | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(indices, properties) of the peaks of a 1-d ``x``: ``scipy.signal.find_peaks(x)`` or, with a minimum
    ``prominence``, ``scipy.signal.find_peaks(x, prominence=prominence)`` (properties: ``prominences``)."""
    x = np.asarray(x, dtype=float)
    peaks = np.array(_local_maxima(x.tolist()), dtype=np.intp)
    if prominence is None:
        return peaks, {}
    prom = np.array([_prominence(x, int(i)) for i in peaks], dtype=float)
    keep = prominence <= prom
    return peaks[keep], {"prominences": prom[keep]}
