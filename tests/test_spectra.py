"""What keeps scipy.signal and scipy.stats (~24 MB resident) out of a diagnosis must not change a number: the
Welch spectra, peaks, first-order filter, zero-order-hold discretisation and chi-square tail computed without
them are scipy's bit for bit."""
from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.signal as ss
from scipy.stats import chi2

from creep_online.diagnostics import spectra
from creep_online.diagnostics.bic import chi2_sf
from creep_online.effects.leakage import leakage_filter
from creep_online.effects.second_mode import zoh_discretize

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("seed", range(4))
def test_welch_and_csd_are_scipys_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    for trial in range(25):
        n = int(rng.integers(20, 3000))
        nper = int(rng.integers(4, n + 50))                  # beyond n: scipy shortens it to n (with a warning)
        fs = float(rng.uniform(1, 5000))
        x = np.cumsum(rng.normal(size=n)) if trial % 2 else rng.normal(size=n)
        y = rng.normal(size=n) + 0.3 * x
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            expected = ss.welch(x, fs, nperseg=nper), ss.csd(x, y, fs, nperseg=nper)
        got = spectra.welch(x, fs, nper), spectra.csd(x, y, fs, nper)
        for (f0, p0), (f1, p1) in zip(expected, got):
            assert np.array_equal(f0, f1) and np.array_equal(p0, p1) and p0.dtype == p1.dtype


@pytest.mark.parametrize("seed", range(3))
def test_find_peaks_is_scipys(seed):
    rng = np.random.default_rng(seed)
    for _ in range(100):
        x = np.round(rng.normal(size=int(rng.integers(0, 300))), int(rng.integers(0, 3)))    # with plateaus
        assert np.array_equal(spectra.find_peaks(x)[0], ss.find_peaks(x)[0])
        level = float(rng.uniform(0, 2))
        (i0, p0), (i1, p1) = ss.find_peaks(x, prominence=level), spectra.find_peaks(x, prominence=level)
        assert np.array_equal(i0, i1) and np.array_equal(p0["prominences"], p1["prominences"])


def test_leakage_filter_is_lfilter_bit_for_bit():
    rng = np.random.default_rng(1)
    for shape in [(1,), (2500,), (3, 1700), (2, 4, 300)]:
        y = np.cumsum(rng.normal(size=shape), axis=-1)
        for tau in (1e-3, 0.05, 3.0, 900.0):
            t = np.arange(shape[-1]) * 1e-3
            h = float(np.diff(t).mean()) if t.size > 1 else 1.0
            a = math.exp(-h / tau)
            c0 = 1.0 - tau * (-math.expm1(-h / tau)) / h
            expected = y - ss.lfilter([c0, (1.0 - a) - c0], [1.0, -a], y, axis=-1)
            assert np.array_equal(leakage_filter(t, y, tau), expected)


def test_zoh_discretize_is_cont2discrete_bit_for_bit():
    rng = np.random.default_rng(2)
    for _ in range(50):
        wn, zeta, dt = 2 * np.pi * 10 ** rng.uniform(0, 4), 10 ** rng.uniform(-3, 1), 10 ** rng.uniform(-6, -2)
        a, b = np.array([[0.0, 1.0], [-wn * wn, -2 * zeta * wn]]), np.array([[0.0], [wn * wn]])
        ad, bd, *_ = ss.cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), dt, method="zoh")
        got = zoh_discretize(a, b, dt)
        assert np.array_equal(got[0], ad) and np.array_equal(got[1], bd)


def test_chi2_sf_is_scipy_stats():
    rng = np.random.default_rng(3)
    for x in [*rng.uniform(-10, 400, 300), 0.0, math.inf, -math.inf, math.nan, 1e-300, 1e300]:
        for dk in (1, 2, 3, 8, 40, 0, -1):
            expected = float(chi2.sf(x, dk))
            assert chi2_sf(x, dk) == expected or (math.isnan(expected) and math.isnan(chi2_sf(x, dk)))


def test_the_diagnosis_imports_neither_scipy_signal_nor_scipy_stats():
    """Every module a diagnosis loads, imported (the functions import nothing more), and no source line in the
    package's diagnosis and effects that imports either."""
    code = ("import sys, creep_online.commands.diagnose\n"
            "import creep_online.diagnostics.explain, creep_online.diagnostics.pairs, creep_online.diagnostics.score\n"
            "import creep_online.diagnostics.holds, creep_online.kernels, creep_online.effects as fx\n"
            "[fx.get_effect(name) for name in fx.effect_names()]\n"
            "print(sorted(m for m in sys.modules if m.startswith(('scipy.signal', 'scipy.stats'))))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd=REPO).stdout
    assert out.strip() == "[]"
    for folder in ("diagnostics", "effects"):
        for path in (REPO / "creep_online" / folder).glob("*.py"):
            text = path.read_text()
            assert "scipy.signal import" not in text and "scipy.stats import" not in text, path
