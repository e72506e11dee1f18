"""A seeded, randomized validation set for batch identification.

Every record is simulated with the exact simulator (``creep_online.simulate``)
from a random model: alpha log-uniform in 0.005-0.8, fn log-uniform over three
decades below the sample rate's reach (2e-4 to 0.2 fs), zeta log-uniform in
0.01-2, a gain of either sign over six decades, a random output offset and
white measurement noise at 30-60 dB of the output's standard deviation.

Input families: ``step``, ``staircase`` (up and down, with reversals),
``random_staircase`` (5-50 ms holds), ``prbs``, ``multisine``, ``triangle`` and
``in_operation``: a record cut out of a longer simulation after a few seconds
of random steps, so the plant is moving and the input is non-zero at the first
sample (the unknown initial state includes the fractional memory of the past).

``truth`` is the noise-free output of the true model over the record (its
history included), so ``fit_percent(y, truth)`` is the floor a fit must reach.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from creep_online.model import CreepModel
from creep_online.simulate import simulate

FAMILIES = ("step", "staircase", "random_staircase", "prbs", "multisine", "triangle", "in_operation")
#: Sample rates drawn from (Hz).
SAMPLE_RATES = (1e3, 2e3, 5e3, 1e4, 2e4)


@dataclass
class ValidationRecord:
    """One synthetic record with the model and noise that made it."""

    family: str
    seed: int
    model: CreepModel
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    truth: np.ndarray
    noise_std: float


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def random_model(rng: np.random.Generator, fs: float) -> CreepModel:
    """A random plant: alpha, fn (three decades below 0.2 fs), zeta, gain of any sign and scale."""
    gain = _log_uniform(rng, 1e-3, 1e3) * float(rng.choice([-1.0, 1.0]))
    return CreepModel.from_resonance(_log_uniform(rng, 0.005, 0.8), _log_uniform(rng, 2e-4 * fs, 0.2 * fs),
                                     _log_uniform(rng, 0.01, 2.0), gain)


def _held(n: int, starts: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Piecewise-constant input: levels[k] from sample starts[k] on (0 before the first)."""
    u = np.zeros(n)
    for i0, lv in zip(starts, levels):
        u[int(i0):] = lv
    return u


def _random_holds(rng: np.random.Generator, n: int, lo: int, hi: int, first: int) -> np.ndarray:
    """Change instants from sample ``first`` on, holds drawn uniformly in [lo, hi] samples."""
    out, i = [], first
    while i < n:
        out.append(i)
        i += int(rng.integers(lo, hi + 1))
    return np.asarray(out, dtype=np.int64)


def random_input(rng: np.random.Generator, family: str, n: int, fs: float) -> np.ndarray:
    """The input of one family on n samples at fs (amplitude about 1, scaled later)."""
    first = int(rng.integers(0, max(n // 50, 2)))
    if family == "step":
        return _held(n, np.array([first]), np.array([1.0]))
    if family == "staircase":
        k = int(rng.integers(3, 9))
        starts = first + np.sort(rng.choice(np.arange(1, k * 10), k - 1, replace=False)) * (n - first) // (k * 10)
        levels = rng.uniform(-1.0, 1.0, k)
        return _held(n, np.concatenate(([first], starts)), levels)
    if family == "random_staircase":
        idx = _random_holds(rng, n, max(int(0.005 * fs), 2), max(int(0.05 * fs), 3), first)
        return _held(n, idx, rng.uniform(-1.0, 1.0, idx.size))
    if family == "prbs":
        bit = int(rng.integers(1, max(int(0.01 * fs), 2) + 1))
        idx = np.arange(first, n, bit)
        return _held(n, idx, rng.choice([-1.0, 1.0], idx.size))
    t = np.arange(n) / fs
    if family == "multisine":
        f = np.geomspace(2.0 / (n / fs), 0.3 * fs, int(rng.integers(5, 16)))
        u = np.sum(np.sin(2 * np.pi * f[:, None] * t[None, :] + rng.uniform(0, 2 * np.pi, f.size)[:, None]), 0)
        u[:first] = 0.0
        return u / np.max(np.abs(u))
    if family == "triangle":
        period = n / fs / rng.uniform(1.0, 10.0)
        u = 2.0 * np.abs(((t / period) % 1.0) - 0.5) * 2.0 - 1.0
        u = u - u[first]
        u[:first] = 0.0
        return u
    raise ValueError(f"unknown family {family!r}; choose one of {', '.join(FAMILIES)}")


def make_record(family: str, seed: int, *, snr_db: tuple[float, float] = (30.0, 60.0)) -> ValidationRecord:
    """One seeded record of a family: random plant, input, offset and noise."""
    rng = np.random.default_rng([seed, FAMILIES.index(family)])
    fs = float(rng.choice(SAMPLE_RATES))
    n = int(rng.integers(5000, 20001))
    model = random_model(rng, fs)
    scale = _log_uniform(rng, 1e-2, 1e2)
    if family == "in_operation":
        hist = int(round(rng.uniform(1.0, 5.0) * fs))
        total = hist + n
        longest = max(int(min(1.0, n / fs / 3.0) * fs), int(0.05 * fs) + 1)  # the record holds changes too
        idx = _random_holds(rng, total, int(0.05 * fs), longest, 0)
        levels = rng.uniform(0.2, 1.0, idx.size) * rng.choice([-1.0, 1.0], idx.size)
        u_all = _held(total, idx, levels) * scale
        y_all = simulate(model, np.arange(total) / fs, u_all)
        u, y_clean = u_all[hist:], y_all[hist:]
    else:
        u = random_input(rng, family, n, fs) * scale
        y_clean = simulate(model, np.arange(n) / fs, u)
    offset = float(rng.normal(0.0, 1.0)) * float(np.std(y_clean))
    std = float(np.std(y_clean)) * 10 ** (-rng.uniform(*snr_db) / 20)
    t = np.arange(n) / fs
    truth = y_clean + offset
    y = truth + rng.normal(0.0, std, n)
    return ValidationRecord(family, seed, model, t, u, y, truth, std)


def validation_set(per_family: int = 30, families: tuple[str, ...] = FAMILIES):
    """Yield per_family seeded records of every family (seeds 0..per_family-1)."""
    for family in families:
        for seed in range(per_family):
            yield make_record(family, seed)


#: Sub-steps per sample of the asynchronous records' change instants.
ASYNC_SUBSTEPS = 16


def make_async_record(seed: int, *, synchronous: bool = False) -> ValidationRecord:
    """A random staircase (5-50 ms holds) whose changes reach the plant between samples.

    The change instants are uniform in continuous time (quantized to 1/16 of a
    sample for the exact simulation on a 16x finer grid); the recorded u shows
    each change at the first sample at or after it, as an ADC on its own
    clock records a DAC's output. ``synchronous`` puts every change on a sample
    (the control case).
    """
    rng = np.random.default_rng([seed, 99])
    fs = float(rng.choice(SAMPLE_RATES))
    n = int(rng.integers(5000, 20001))
    model = random_model(rng, fs)
    m = ASYNC_SUBSTEPS
    fine_idx = _random_holds(rng, n * m, max(int(0.005 * fs), 2) * m, max(int(0.05 * fs), 3) * m,
                             int(rng.integers(1, n // 50)) * m)
    if synchronous:
        fine_idx = fine_idx - fine_idx % m
    levels = rng.uniform(-1.0, 1.0, fine_idx.size) * _log_uniform(rng, 1e-2, 1e2)
    y_fine = simulate(model, np.arange(n * m) / (fs * m), _held(n * m, fine_idx, levels))
    y_clean = y_fine[::m]
    u = _held(n, -(-fine_idx // m), levels)        # seen at the first sample at or after the change
    std = float(np.std(y_clean)) * 10 ** (-rng.uniform(40.0, 60.0) / 20)
    y = y_clean + rng.normal(0.0, std, n)
    return ValidationRecord("async_staircase" if not synchronous else "sync_staircase", seed, model,
                            np.arange(n) / fs, u, y, y_clean, std)
