"""Reference plants and experiments: the cases the benchmarks and tests identify.

Each is a CreepModel plus an input schedule and a sampling plan; ``experiment``
simulates it exactly and adds seeded white noise at a given SNR (dB, relative
to the RMS of the noise-free output), so every number can be reproduced.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from creep_online.model import CreepModel
from creep_online.simulate import simulate


@dataclass(frozen=True)
class Experiment:
    """A plant, an input made of held levels, and how it is sampled."""

    name: str
    model: CreepModel
    fs: float                                 # Hz
    duration: float                           # s
    levels: tuple[tuple[float, float], ...]   # (start time s, level) pairs; 0 before the first

    def input(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, u) on the sampling grid."""
        t = np.arange(int(round(self.duration * self.fs))) / self.fs
        u = np.zeros_like(t)
        for t0, level in self.levels:
            u[t >= t0 - 1e-12] = level
        return t, u

    def run(self, snr_db: float | None = 40.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(t, u, y, noise_std): exact response plus white noise at ``snr_db`` (None: noise-free)."""
        t, u = self.input()
        y = simulate(self.model, t, u)
        if snr_db is None:
            return t, u, y, 0.0
        std = float(np.sqrt(np.mean(y * y))) * 10 ** (-snr_db / 20)
        return t, u, y + np.random.default_rng(seed).normal(0.0, std, y.size), std


#: (a) nanopositioner: alpha ~0.02, fn 100-700 Hz, 10 kHz, 10 s
NANOPOSITIONER = Experiment("nanopositioner", CreepModel.from_resonance(0.02, 350.0, 0.08, 1.8),
                            1e4, 10.0, ((0.001, 1.0),))
#: (b) load cell like the paper's setup 2: alpha ~0.06, fn ~6 Hz, 200 Hz, 60 s, step of 50
LOAD_CELL = Experiment("load_cell", CreepModel.from_resonance(0.06, 6.0, 0.12, 0.02),
                       200.0, 60.0, ((0.5, 50.0),))
#: (c) four-step staircase on a nanopositioner-like plant
FOUR_STEP = Experiment("four_step", CreepModel.from_resonance(0.03, 150.0, 0.1, 1.0),
                       1e4, 10.0, ((0.001, 1.0), (2.5, 2.0), (5.0, 0.5), (7.5, 1.5)))
#: (d) strong creep, alpha ~0.4
STRONG_CREEP = Experiment("alpha_0.4", CreepModel.from_resonance(0.4, 20.0, 0.05, 1.0),
                          2e3, 10.0, ((0.0, 1.0),))

RECOVERY_CASES = (NANOPOSITIONER, LOAD_CELL, FOUR_STEP, STRONG_CREEP)
