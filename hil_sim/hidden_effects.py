"""Data sets with one catalogue effect hidden in the simulated plant (plus clean data), for diagnosis tests.

The input is a staircase with reversals and several amplitudes (it excites
hysteresis, gain nonlinearity, ringing and holds alike). The base plant and
the effect's parameters are drawn from realistic ranges by ``seed``. The
base model absorbs part of any effect (a gain soaks up some nonlinearity,
alpha some second creep), so the strength is set where it matters: the base
model is fitted to the noise-free output with the effect, and the white
measurement noise is scaled so that this base residual is ``ratio`` times
the noise RMS (``ratio`` drawn log-uniformly in ``RATIO_RANGE``, inside the
1.5x-40x band of realistic strengths). numpy/scipy (and creep_online) only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from creep_online.effects import EFFECTS, effect_names, get_effect, simulate_with_effects
from creep_online.model import CreepModel

#: Base-model residual RMS / noise RMS, drawn log-uniformly per data set.
RATIO_RANGE = (2.0, 12.0)


@dataclass
class HiddenDataset:
    """A record with a known hidden effect (``effect`` None = clean) and the truth behind it."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    y_clean: np.ndarray          # noise-free output with the effect
    y_base: np.ndarray           # noise-free output of the base model alone
    noise_std: float
    model: CreepModel
    effect: str | None
    params: dict = field(default_factory=dict)
    seed: int = 0

    @property
    def effect_rms(self) -> float:
        return float(np.sqrt(np.mean((self.y_clean - self.y_base) ** 2)))


def staircase(n: int, h: float, rng: np.random.Generator, hold_s: tuple[float, float] = (0.15, 0.35),
              u_max: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """A staircase from 0 with random holds, alternating directions and mixed step sizes (small and large)."""
    t = np.arange(n) * h
    u = np.zeros(n)
    i = int(rng.uniform(0.02, 0.05) * n)
    level, direction = 0.0, 1.0
    while i < n:
        size = u_max * rng.choice([0.1, 0.25, 0.45, 0.7]) * rng.uniform(0.8, 1.2)
        if rng.random() < 0.3:
            direction = -direction  # a same-direction run now and then, reversals otherwise
        new = level + direction * size
        if new > u_max or new < 0.0:
            direction = -direction
            new = level + direction * size
        new = float(np.clip(new, 0.0, u_max))
        if abs(new - level) < 0.05 * u_max:
            new = u_max - level if abs(u_max - 2 * level) > 0.1 * u_max else 0.5 * level
        level = new
        direction = -direction
        hold = int(rng.uniform(*hold_s) / h)
        u[i:] = level
        i += max(hold, 5)
    return t, u


def random_model(rng: np.random.Generator) -> CreepModel:
    """A base plant: alpha 0.15-0.6, resonance 25-70 Hz with zeta 0.05-0.3 (sampled at 1 kHz)."""
    return CreepModel.from_resonance(rng.uniform(0.15, 0.6), rng.uniform(25.0, 70.0), rng.uniform(0.05, 0.3),
                                     rng.uniform(0.5, 2.0))


def effect_params(effect: str, model: CreepModel, t: np.ndarray, u: np.ndarray, y_base: np.ndarray,
                  rng: np.random.Generator) -> dict:
    """Physically plausible parameters of one hidden effect for this plant and input (the effect's own ranges)."""
    return get_effect(effect).example_params(model, t, u, y_base, rng)


def hidden_dataset(effect: str | None, seed: int = 0, n: int = 4000, h: float = 1e-3,
                   ratio: float | None = None) -> HiddenDataset:
    """One record with ``effect`` hidden (None: clean), reproducible from ``seed``.

    ``ratio`` = base-model residual RMS (fitted to the noise-free output) /
    noise RMS (default: drawn log-uniformly from ``RATIO_RANGE``). Clean
    data get noise at 0.2-1 % of the output range.
    """
    if effect is not None:
        get_effect(effect)  # ModelError naming the catalogue if unknown
    rng = np.random.default_rng([seed, 0 if effect is None else 1 + effect_names().index(effect)])
    t, u = staircase(n, h, rng)
    model = random_model(rng)
    if effect == "second_mode" and model.zeta > 0.15:
        # a second mode is only distinguishable from other structures when the first one rings visibly
        model = CreepModel.from_resonance(model.alpha, model.fn, 0.5 * model.zeta, model.b)
    y_base = simulate_with_effects(model, t, u)
    if effect is None:
        noise = float(np.ptp(y_base)) * rng.uniform(0.002, 0.01)
        return HiddenDataset(t, u, y_base + noise * rng.standard_normal(n), y_base, y_base, noise, model,
                             None, {}, seed)
    params = effect_params(effect, model, t, u, y_base, rng)
    y_eff = simulate_with_effects(model, t, u, {effect: params})
    if ratio is None:
        ratio = math.exp(rng.uniform(math.log(RATIO_RANGE[0]), math.log(RATIO_RANGE[1])))
    from creep_online.diagnostics.extended import fit_base, prepare
    unexplained = fit_base(prepare(t, u, y_eff)).residual_rms
    noise = unexplained / math.sqrt(ratio * ratio - 1.0)
    y = y_eff + noise * rng.standard_normal(n)
    return HiddenDataset(t, u, y, y_eff, y_base, noise, model, effect, params, seed)


def all_hidden(seed: int = 0, **kw) -> dict[str, HiddenDataset]:
    """Clean data (key 'none') and one data set per built-in catalogue effect."""
    out = {"none": hidden_dataset(None, seed, **kw)}
    for e in EFFECTS:
        out[e] = hidden_dataset(e, seed, **kw)
    return out


def save(ds: HiddenDataset, path) -> None:
    """Write the record as a ``t,u,y`` CSV (the truth is not in the file)."""
    from creep_online.io import save_csv
    save_csv(path, ds.t, ds.u, ds.y)
