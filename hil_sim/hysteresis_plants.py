"""Creep plants with a Prandtl-Ishlinskii loop on the input, driven by the input families a user records.

``hysteresis_record(family, seed)`` draws a plant (alpha 0.01-0.3, a resonance
100-1500 Hz, sampled at 10 kHz), a loop (a smooth threshold density on its own
thresholds, not the fit's, scaled to a loop width of 2-20 % of the stroke,
a random initial state) and white noise at 0.1-1 % of the output's range,
and simulates ``INPUT_FAMILIES[family]``. numpy (and creep_online) only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from creep_online.effects import INITIAL_STATES, loop_width, simulate_with_effects
from creep_online.effects.hysteresis import hysteresis_input, threshold_fractions
from creep_online.model import CreepModel
from creep_online.simulate import simulate

from .hidden_effects import staircase

#: Loop width (``effects.loop_width``) over the stroke, drawn log-uniformly.
WIDTH_RANGE = (0.02, 0.2)
#: The plant's creep exponent, drawn uniformly.
ALPHA_RANGE = (0.01, 0.3)
#: Noise RMS over the output's range, drawn log-uniformly.
NOISE_RANGE = (1e-3, 1e-2)
#: Thresholds of the simulated loops (fractions of the stroke): 30 evenly spaced up to 1/2, none on the fit's grid.
TRUE_THRESHOLDS = tuple(np.linspace(0.0, 0.5, 31)[1:])
#: The largest sum of weights a drawn loop may have (its large-signal slope at most twice the small-signal one).
MAX_WEIGHT_SUM = 1.0


@dataclass
class HysteresisRecord:
    """A record of a plant with hysteresis and the truth behind it."""

    family: str
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    y_clean: np.ndarray
    noise_std: float
    model: CreepModel
    params: dict
    u_pre: float | None = None
    seed: int = 0
    notes: dict = field(default_factory=dict)


def _step(n: int, h: float, rng: np.random.Generator, stroke: float) -> tuple[np.ndarray, float | None]:
    u = np.zeros(n)
    u[int(rng.uniform(0.02, 0.1) * n):] = stroke
    return u, None


def _step_first(n: int, h: float, rng: np.random.Generator, stroke: float) -> tuple[np.ndarray, float | None]:
    return np.full(n, stroke), 0.0          # the plain step at the first sample, from rest


def _few_levels(n: int, h: float, rng: np.random.Generator, stroke: float) -> tuple[np.ndarray, float | None]:
    levels = np.sort(rng.choice([0.0, 0.25, 0.5, 0.75, 1.0], size=int(rng.integers(3, 5)), replace=False))
    levels = (levels - levels[0]) / (levels[-1] - levels[0]) * stroke
    holds = int(rng.integers(5, 9))
    seq = [levels[0]]
    while len(seq) < holds:
        seq.append(rng.choice([x for x in levels if x != seq[-1]]))
    u = np.zeros(n)
    start = int(rng.uniform(0.02, 0.05) * n)
    edges = np.linspace(start, n, holds + 1).astype(int)
    for level, a, b in zip(seq, edges[:-1], edges[1:]):
        u[a:b] = level
    return u, None


def _periodic(shape: str):
    def make(n: int, h: float, rng: np.random.Generator, stroke: float) -> tuple[np.ndarray, float | None]:
        t = np.arange(n) * h
        f = rng.uniform(2.0, 6.0) / (n * h)            # 2-6 periods in the record
        phase = f * t
        if shape == "sine":
            u = 0.5 * stroke * (1.0 - np.cos(2.0 * math.pi * phase))
        else:
            u = stroke * (1.0 - np.abs(2.0 * (phase % 1.0) - 1.0))
        return u, None
    return make


def _random_staircase(n: int, h: float, rng: np.random.Generator, stroke: float) -> tuple[np.ndarray, float | None]:
    return staircase(n, h, rng, hold_s=(0.03, 0.12), u_max=stroke)[1], None


#: Input families: name -> (n, h, rng, stroke) -> (u, u_pre); u_pre None: the record starts in equilibrium at u[0].
INPUT_FAMILIES = {"step": _step, "step_first": _step_first, "few_levels": _few_levels, "sine": _periodic("sine"),
                  "triangle": _periodic("triangle"), "random_staircase": _random_staircase}


def random_loop(rng: np.random.Generator, stroke: float, width: float | None = None) -> dict:
    """A loop of relative width ``width`` (default log-uniform in WIDTH_RANGE): weights decaying with the threshold
    over a random scale (a smooth density), positive, summing to at most MAX_WEIGHT_SUM; random initial state."""
    if width is None:
        width = math.exp(rng.uniform(math.log(WIDTH_RANGE[0]), math.log(WIDTH_RANGE[1])))
    r = np.asarray(TRUE_THRESHOLDS) * stroke
    while True:
        shape = np.exp(-r / (rng.uniform(0.05, 0.5) * stroke))
        opening = float(np.sum(shape * 2.0 * r)) / stroke     # loop width = k opening / (1 + k sum(shape))
        k = width / (opening - width * float(shape.sum())) if opening > width * shape.sum() else -1.0
        if 0.0 < k * shape.sum() <= MAX_WEIGHT_SUM:
            break
    w = k * shape
    return {"r": r.tolist(), "w": w.tolist(), "initial": str(rng.choice(list(INITIAL_STATES)))}


#: The closed-loop plant's loop for a bare ``--effects hysteresis`` (``command_loop``): its width over the stroke.
COMMAND_LOOP_WIDTH = 0.1


def command_loop(model: CreepModel, seed: int) -> dict:
    """The loop of a closed-loop plant given a bare ``--effects hysteresis``: ``random_loop`` of width
    COMMAND_LOOP_WIDTH over the stroke of the commands that move the output by 1 (1 / |b|), centred."""
    return {**random_loop(np.random.default_rng([seed, 41]), 1.0 / abs(model.b), COMMAND_LOOP_WIDTH),
            "initial": "centred"}


def random_plant(rng: np.random.Generator) -> CreepModel:
    """alpha in ALPHA_RANGE, fn 100-1500 Hz, zeta 0.05-0.5, gain of either sign 0.5-2."""
    return CreepModel.from_resonance(rng.uniform(*ALPHA_RANGE), math.exp(rng.uniform(math.log(100.0), math.log(1500.0))),
                                     rng.uniform(0.05, 0.5), rng.uniform(0.5, 2.0) * rng.choice([-1.0, 1.0]))


def hysteresis_record(family: str, seed: int, n: int = 20_000, h: float = 1e-4) -> HysteresisRecord:
    """One record of ``family`` (``INPUT_FAMILIES``), reproducible from ``seed``."""
    if family not in INPUT_FAMILIES:
        raise ValueError(f"unknown input family {family!r}; one of {', '.join(INPUT_FAMILIES)}")
    rng = np.random.default_rng([seed, list(INPUT_FAMILIES).index(family)])
    stroke = rng.uniform(5.0, 100.0)
    u, u_pre = INPUT_FAMILIES[family](n, h, rng, stroke)
    t = np.arange(n) * h
    model = random_plant(rng)
    params = random_loop(rng, stroke)
    y_clean = simulate_with_effects(model, t, u, {"hysteresis": params}, u_pre=u_pre)
    noise = math.exp(rng.uniform(*np.log(NOISE_RANGE))) * float(np.ptp(y_clean) or abs(model.b) * stroke)
    y = y_clean + noise * rng.standard_normal(n)
    width = loop_width(params["r"], params["w"], stroke) / stroke
    return HysteresisRecord(family, t, u, y, y_clean, noise, model, params, u_pre, seed, {"loop_width_rel": width})


def online_creep_plant(rng: np.random.Generator) -> CreepModel:
    """A plant for the online estimator's hysteresis records: fn 200-500 Hz, zeta 0.2-0.5, alpha 0.03-0.2, b 0.5-3."""
    wn = 2 * math.pi * rng.uniform(200, 500)
    zeta = rng.uniform(0.2, 0.5)
    return CreepModel(rng.uniform(0.03, 0.2), 2 * zeta / wn, 1 / wn ** 2, rng.uniform(0.5, 3.0))


def online_loop_weights(rng: np.random.Generator) -> np.ndarray:
    """Eight play weights decaying from 0.02-0.1 (the loop a few percent of the stroke), at the online estimator's
    thresholds (``threshold_fractions(8)`` of the stroke)."""
    return rng.uniform(0.02, 0.1) * np.exp(-np.arange(8) / rng.uniform(1.0, 3.0))


@dataclass
class RestingRecord:
    """A plant at rest on a branch of its loop, then swept (``resting_record``): sample period h, input u, output y,
    the creep plant and the true weights w."""
    h: float
    u: np.ndarray
    y: np.ndarray
    model: CreepModel
    w: np.ndarray


def resting_record(seed: int, initial: str, rest_s: float = 2.0, seconds: float = 10.0,
                   fs: float = 5000.0) -> RestingRecord:
    """A creep + resonance plant (``online_creep_plant``) behind a loop of 8 operators (``online_loop_weights``) resting
    on the branch ``initial`` (its plays at u - r, u + r or centred since long before the record) for ``rest_s``,
    then a 1 Hz triangle from the rest level up to 4; the record is the output's deviation from that rest, with
    white noise at 1e-4 of its range. What a device at rest on a branch when the stream starts gives the
    estimator: the start in equilibrium that the window's start columns model."""
    rng = np.random.default_rng(seed)
    h = 1.0 / fs
    t = np.arange(int(seconds * fs)) * h
    model = online_creep_plant(rng)
    phase = np.maximum(t - rest_s, 0.0)
    u = np.round(4.0 * (1.0 - np.abs(2.0 * (phase % 1.0) - 1.0)) * 250) / 250
    r = threshold_fractions(8) * np.ptp(u)
    w = online_loop_weights(rng)
    v = hysteresis_input(u, r, w, initial)
    y = simulate(model, t, v - v[0])
    noise = 1e-4 * np.ptp(y)
    return RestingRecord(h, u, y + noise * rng.standard_normal(t.size), model, w)
