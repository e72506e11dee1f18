"""Randomized time-varying creep plants for judging online estimators (the scenario test bed).

Plant: ``y = H2(t) * (b(t) z)`` with ``z = D^-alpha(t) u`` and
``H2 = 1/(1 + a1(t) s + a2(t) s^2)``, plus optional parallel higher modes.
``simulate_tv`` integrates it *exactly* for a zero-order-held input with the
parameters held over each sample: the fractional integral is the
alpha-independent sum-of-exponentials node vector of
``creep_online.online.soe.SoeBasis`` (``z = w(alpha) . zeta + D u``), and inside
a sample every node is an exponential (the integrator node a ramp) driving a
linear resonance, so one 4x4 matrix exponential per node and per distinct
(a1, a2) gives the exact response. The resonance state [y, y'] simply
continues when a parameter changes (a payload adds mass without a jump in
position or velocity). Against ``creep_online.simulate.simulate`` (exact) it
agrees to the SOE accuracy (tests/test_scenarios.py).

Cost: O(K) per sample (K ~ 40 nodes) plus O(K) matrix exponentials per
distinct (a1, a2) pair: parameters meant to be piecewise constant in a1, a2
(the families below change them at most once); alpha and b may vary at every
sample.

Scenario families (``FAMILIES[name](seed) -> Scenario``; 40 dB white output
noise relative to the noise-free output's rms):

strong_creep   stationary, alpha 0.005-0.7 log-uniform, fn 1 Hz-fs/4, zeta 0.01-1,
               b = +-10^U(-3,3); any input family; 10 kHz (1-2 kHz for half of fn < 200 Hz); 12-16 s
payload        mass +25-60 % mid-record (a2 *= 1+m); steps every 1 s; 16 s at 10 kHz, fn 100-1000 Hz
stiffness      stiffness +-20-50 % (a1, a2, b / ratio) or damping a1 *= 0.5-0.8 or 1.25-2; 16 s, 10 kHz
drift          alpha +10-20 %, b +5-10 % linearly over 60 s at 2 kHz, fn 30-400 Hz
controller     random staircase (5-50 ms holds), stationary; 12 s at 10 kHz
close_modes    two weaker modes (residues 0.1-0.4) 1.3-2.5x above the first; 12 s at 10 kHz;
               ``truth_best`` = best second-order fit (``identify`` on the noise-free record)
mid_operation  12 s taken 5 s into operation after a history of steps (u[0] != 0), t re-zeroed
quiet_start    small steps first (levels 0-0.1 for 1.5-3 s: the start-up search sees little of the
               resonance), then steps of +-1 every 0.5 s; 10 s at 10 kHz, fn 2-300 Hz

Draws are log-uniform: strong_creep as listed; the other families alpha
0.01-0.5, zeta 0.02-0.5, b = +-10^U(-1,1). Every input rests at 0 for
0.05-0.3 s before its first change (mid_operation excepted), or, with
``make(family, seed, rest=k)``, for k samples: ``rest=0`` is the step at the
first sample (the input at its first level from the first sample, the plant at
rest before it: the most common first record), the same plant and input
otherwise.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from numba import njit
from scipy.linalg import expm

from creep_online.identification import identify
from creep_online.online.soe import SOE_TOP, SoeBasis

#: Output noise: 40 dB below the rms of the noise-free output.
SNR_DB = 40.0
#: SOE node spacing in ln(lambda): finer than the estimator's 0.8 so the judge is the more accurate one.
SOE_DX = 0.5
#: SOE memory horizon in units of the record span (the accuracy holds up to it).
HORIZON_SPANS = 10.0

Modes = tuple[tuple[float, float, float], ...]


# --------------------------------------------------------------------------- simulator
@njit(cache=True)
def _soe_weights(alpha: float, lam: np.ndarray, dx: float, w: np.ndarray) -> float:
    """Fill w with the SOE weights of ``D^-alpha`` and return the direct term D.

    The same formula as ``SoeBasis.weights`` (tested equal), compiled because
    alpha may change at every sample.
    """
    q = lam.shape[0]
    s = math.sin(math.pi * alpha) / math.pi
    lo = lam[1] * math.exp(-dx)
    w[0] = s * dx * lo ** (1.0 - alpha) / (-math.expm1(-(1.0 - alpha) * dx))
    for i in range(1, q):
        w[i] = s * dx * lam[i] ** (1.0 - alpha)
    hi = lam[q - 1] * math.exp(dx)
    return s * dx * hi ** (-alpha) / (-math.expm1(-alpha * dx))


def _resonance_tables(lam: np.ndarray, h: float, a1: float, a2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Phi, P, Q) of 1/(1 + a1 s + a2 s^2) over one step h, exact.

    ``P[i]`` is the state [y, y'] after h driven from rest by exp(-lam_i tau),
    ``Q[i]`` by (1 - exp(-lam_i tau))/lam_i (tau for lam_i = 0): the two parts of
    a node's trajectory inside a sample for a held input. One batched 4x4
    matrix exponential (Van Loan) per node.
    """
    m = np.zeros((lam.size, 4, 4))
    m[:, 0, 1] = 1.0
    m[:, 1, 0] = -1.0 / a2
    m[:, 1, 1] = -a1 / a2
    m[:, 1, 2] = 1.0 / a2
    m[:, 2, 2] = -lam
    m[:, 2, 3] = 1.0
    e = expm(m * h)
    return e[0, :2, :2].copy(), e[:, :2, 2].copy(), e[:, :2, 3].copy()


@njit(cache=True)
def _run(u: np.ndarray, alpha: np.ndarray, b: np.ndarray, seg: np.ndarray, res: np.ndarray,
         lam: np.ndarray, dx: float, decay: np.ndarray, gain: np.ndarray,
         phi: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Per-sample loop: output, then the exact step of every resonance and of the SOE nodes.

    Resonance j uses table ``seg[n]`` for j = 0 (the main mode) and the fixed
    table ``n_main + j - 1`` for the extra modes; ``res[j]`` is its residue.
    """
    n = u.shape[0]
    k = lam.shape[0]
    r = res.shape[0]
    n_main = phi.shape[0] - (r - 1)
    zeta = np.zeros(k)
    w = np.empty(k)
    x = np.zeros((r, 2))
    y = np.empty(n)
    d = 0.0
    last = -1.0
    for i in range(n):
        if alpha[i] != last:
            d = _soe_weights(alpha[i], lam, dx, w)
            last = alpha[i]
        acc = 0.0
        for j in range(r):
            acc += res[j] * x[j, 0]
        y[i] = acc
        ui = u[i]
        for j in range(r):
            s = seg[i] if j == 0 else n_main + j - 1
            f0 = d * ui * p[s, 0, 0]
            f1 = d * ui * p[s, 0, 1]
            for m in range(k):
                c = w[m] * zeta[m]
                g = w[m] * ui
                f0 += c * p[s, m, 0] + g * q[s, m, 0]
                f1 += c * p[s, m, 1] + g * q[s, m, 1]
            x0 = x[j, 0]
            x1 = x[j, 1]
            x[j, 0] = phi[s, 0, 0] * x0 + phi[s, 0, 1] * x1 + b[i] * f0
            x[j, 1] = phi[s, 1, 0] * x0 + phi[s, 1, 1] * x1 + b[i] * f1
        for m in range(k):
            zeta[m] = decay[m] * zeta[m] + gain[m] * ui
    return y


def _per_sample(value: np.ndarray | float, n: int) -> np.ndarray:
    """A scalar or length-n array as a contiguous float array of length n."""
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=float), (n,)))


def simulate_tv(h: float, u: np.ndarray, alpha: np.ndarray | float, a1: np.ndarray | float,
                a2: np.ndarray | float, b: np.ndarray | float, modes: Modes | list = ()) -> np.ndarray:
    """Output of the time-varying creep plant for the zero-order-held input u (zero initial state).

    alpha, a1, a2, b: scalars or per-sample arrays (sample n's values hold over
    [t_n, t_{n+1})). ``modes`` = [(r_k, a1_k, a2_k), ...] adds
    ``r_k b z / (1 + a1_k s + a2_k s^2)`` (unmodeled higher modes). y[n] is
    the output at t_n, driven by u[0..n-1].
    """
    u = np.ascontiguousarray(u, dtype=float)
    n = u.size
    alpha, a1, a2, b = (_per_sample(v, n) for v in (alpha, a1, a2, b))
    basis = SoeBasis.build(h, horizon_s=HORIZON_SPANS * max(n * h, 1.0), dx=SOE_DX, top=SOE_TOP)
    pairs, seg = np.unique(np.stack((a1, a2), axis=1), axis=0, return_inverse=True)
    tables = [_resonance_tables(basis.lam, h, c1, c2) for c1, c2 in pairs]
    tables += [_resonance_tables(basis.lam, h, c1, c2) for _, c1, c2 in modes]
    phi, p, q = (np.ascontiguousarray(np.stack(t)) for t in zip(*tables))
    res = np.array([1.0] + [r for r, _, _ in modes])
    return _run(u, alpha, b, np.ascontiguousarray(seg.ravel(), dtype=np.int64), res,
                basis.lam, basis.dx, basis.decay, basis.gain, phi, p, q)


# --------------------------------------------------------------------------- inputs
def _held(t: np.ndarray, t0: float, edges: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Piecewise-constant signal: levels[k] from edges[k] on (times relative to t0), 0 before t0."""
    k = np.searchsorted(edges, t - t0, side="right") - 1
    return np.where(t >= t0, levels[np.clip(k, 0, levels.size - 1)], 0.0)


def _start(rng: np.random.Generator, t: np.ndarray, rest: int | None = None) -> float:
    """First input change: 0.05-0.3 s of rest first (the estimators take the offset there), or after ``rest``
    samples (0: the input at its first level from the first sample, the plant at rest before it). The draw is made
    either way, so the plant and the rest of the input are the same whatever ``rest``."""
    t0 = float(rng.uniform(0.05, 0.3))
    return t0 if rest is None else float(t[rest]) if rest < t.size else float(t[-1]) + 1.0


def steps(t: np.ndarray, rng: np.random.Generator, rest: int | None = None) -> np.ndarray:
    """A step every 1 s to a random level in [-1, 1]."""
    edges = np.arange(0.0, t[-1] + 1.0, 1.0)
    return _held(t, _start(rng, t, rest), edges, rng.uniform(-1.0, 1.0, edges.size))


def staircase(t: np.ndarray, rng: np.random.Generator, rest: int | None = None) -> np.ndarray:
    """Up-then-down staircase with reversals: increments 0.1-0.3, holds 0.5-1.5 s."""
    holds = rng.uniform(0.5, 1.5, int(t[-1] / 0.5) + 2)
    edges = np.concatenate(([0.0], np.cumsum(holds)[:-1]))
    up = np.where(np.arange(edges.size) < edges.size // 2, 0.7, 0.3)
    sign = np.where(rng.random(edges.size) < up, 1.0, -1.0)
    return _held(t, _start(rng, t, rest), edges, np.cumsum(sign * rng.uniform(0.1, 0.3, edges.size)))


def random_staircase(t: np.ndarray, rng: np.random.Generator, rest: int | None = None) -> np.ndarray:
    """A controller's output: holds of 5-50 ms at random levels in [-1, 1]."""
    holds = rng.uniform(5e-3, 50e-3, int(t[-1] / 5e-3) + 2)
    edges = np.concatenate(([0.0], np.cumsum(holds)[:-1]))
    return _held(t, _start(rng, t, rest), edges, rng.uniform(-1.0, 1.0, edges.size))


def prbs(t: np.ndarray, rng: np.random.Generator, rest: int | None = None) -> np.ndarray:
    """Random binary sequence 0/1 with a bit period of 1-20 ms."""
    bit = rng.uniform(1e-3, 20e-3)
    edges = np.arange(0.0, t[-1] + bit, bit)
    levels = rng.integers(0, 2, edges.size).astype(float)
    levels[0] = 1.0
    return _held(t, _start(rng, t, rest), edges, levels)


def multisine(t: np.ndarray, rng: np.random.Generator, rest: int | None = None) -> np.ndarray:
    """Eight sines, log-spaced 0.2 Hz to fs/20, random phases, peak 1 (changes every sample)."""
    fs = 1.0 / (t[1] - t[0])
    f = np.geomspace(0.2, fs / 20.0, 8)
    t0 = _start(rng, t, rest)
    tau = np.maximum(t - t0, 0.0)[:, None]
    x = np.sin(2 * np.pi * f * tau + rng.uniform(0, 2 * np.pi, f.size)).sum(axis=1)
    return np.where(t >= t0, x / np.max(np.abs(x)), 0.0)


def triangle(t: np.ndarray, rng: np.random.Generator, rest: int | None = None) -> np.ndarray:
    """Triangle wave 0..1 with a period of 0.5-4 s."""
    period = rng.uniform(0.5, 4.0)
    t0 = _start(rng, t, rest)
    phase = np.mod(np.maximum(t - t0, 0.0) / period, 1.0)
    return np.where(t >= t0, 1.0 - np.abs(2.0 * phase - 1.0), 0.0)


INPUTS: dict[str, Callable[..., np.ndarray]] = {
    "steps": steps, "staircase": staircase, "random_staircase": random_staircase,
    "prbs": prbs, "multisine": multisine, "triangle": triangle}


# --------------------------------------------------------------------------- scenarios
@dataclass
class Scenario:
    """One simulated record with its per-sample truth.

    ``y`` carries the noise; ``alpha``, ``a1``, ``a2``, ``b`` are the plant's
    parameters at every sample; ``truth_best`` (close_modes only) is the best
    second-order fit of the noise-free record, the fair target for a1, a2.
    ``u_history`` (mid_operation only) is the input before the record's first
    sample, the plant at rest before it: what ``clean`` needs to start the
    record from its true state.
    """

    family: str
    seed: int
    h: float
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    alpha: np.ndarray
    a1: np.ndarray
    a2: np.ndarray
    b: np.ndarray
    change_time: float | None = None
    params: dict = field(default_factory=dict)
    truth_best: dict | None = None
    u_history: np.ndarray | None = None

    def clean(self, **scaled: float) -> np.ndarray:
        """The noise-free output over the record, each parameter's whole trajectory multiplied by ``scaled[name]``
        (default 1), the unmodeled modes included, the state at the first sample the true one (the history
        simulated before it with the parameters' first values): the reference of the bench's Cramer-Rao bounds
        and oracle fit."""
        arrays = {k: np.asarray(getattr(self, k), dtype=float) * scaled.get(k, 1.0)
                  for k in ("alpha", "a1", "a2", "b")}
        u = self.u
        skip = 0 if self.u_history is None else self.u_history.size
        if skip:
            u = np.concatenate((self.u_history, self.u))
            arrays = {k: np.concatenate((np.full(skip, v[0]), v)) for k, v in arrays.items()}
        modes = [tuple(m) for m in self.params.get("modes", [])]
        return simulate_tv(self.h, u, modes=modes, **arrays)[skip:]

    def truth_at(self, index: int | np.ndarray) -> dict:
        """Truth (alpha, a1, a2, b) at sample index (or indices): truth_best where one is set."""
        if self.truth_best is not None:
            return {k: np.broadcast_to(v, np.shape(index)).astype(float) for k, v in self.truth_best.items()}
        return {k: getattr(self, k)[index] for k in ("alpha", "a1", "a2", "b")}

    @property
    def final_truth(self) -> dict[str, float]:
        """Truth at the last sample."""
        return {k: float(v) for k, v in self.truth_at(self.t.size - 1).items()}

    def save(self, path: str | Path) -> None:
        """Write to a compressed npz (t is rebuilt from h on load)."""
        meta = {"family": self.family, "seed": self.seed, "h": self.h, "change_time": self.change_time,
                "params": self.params, "truth_best": self.truth_best}
        history = {} if self.u_history is None else {"u_history": self.u_history}
        np.savez_compressed(path, u=self.u, y=self.y, alpha=self.alpha, a1=self.a1, a2=self.a2,
                            b=self.b, meta=np.array(json.dumps(meta)), **history)

    @classmethod
    def load(cls, path: str | Path) -> "Scenario":
        """Read a file written by ``save``."""
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in ("u", "y", "alpha", "a1", "a2", "b")}
            if "u_history" in z:
                arrays["u_history"] = z["u_history"]
        t = np.arange(arrays["u"].size) * meta["h"]
        return cls(t=t, **arrays, **meta)


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _resonance(fn: float, zeta: float) -> tuple[float, float]:
    """(a1, a2) of a mode at fn Hz with damping zeta."""
    wn = 2.0 * math.pi * fn
    return 2.0 * zeta / wn, 1.0 / wn**2


def _gain(rng: np.random.Generator, decades: float) -> float:
    """Random sign, magnitude 10^U(-decades, decades)."""
    return float(rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(-decades, decades))


def _noisy(y: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """y plus white noise SNR_DB below its rms, and the noise std."""
    std = float(np.sqrt(np.mean(y**2)) * 10 ** (-SNR_DB / 20))
    return y + rng.normal(0.0, std, y.size), std


def _build(family: str, seed: int, rng: np.random.Generator, h: float, u: np.ndarray,
           truth: dict[str, np.ndarray | float], params: dict, change_time: float | None = None,
           modes: Modes = ()) -> tuple[Scenario, np.ndarray]:
    """Simulate, add noise, package; also returns the noise-free output."""
    n = u.size
    arrays = {k: _per_sample(v, n).copy() for k, v in truth.items()}
    clean = simulate_tv(h, u, modes=modes, **arrays)
    y, std = _noisy(clean, rng)
    params = {**params, "fs_hz": 1.0 / h, "noise_std": std}
    scen = Scenario(family=family, seed=seed, h=h, t=np.arange(n) * h, u=u, y=y, change_time=change_time,
                    params=params, **arrays)
    return scen, clean


def _stationary_plant(rng: np.random.Generator, fn_lo: float, fn_hi: float) -> dict:
    """Plant of the families other than strong_creep: alpha 0.01-0.5, zeta 0.02-0.5, b +-10^U(-1,1)."""
    fn = _loguniform(rng, fn_lo, fn_hi)
    zeta = _loguniform(rng, 0.02, 0.5)
    a1, a2 = _resonance(fn, zeta)
    return {"alpha": _loguniform(rng, 0.01, 0.5), "a1": a1, "a2": a2, "b": _gain(rng, 1.0),
            "fn": fn, "zeta": zeta}


def _split(plant: dict) -> tuple[dict, dict]:
    """(truth for the simulator, params for the record) from a plant dict."""
    truth = {k: plant[k] for k in ("alpha", "a1", "a2", "b")}
    return truth, dict(plant)


def _strong_creep_plant(rng: np.random.Generator) -> dict:
    """Draw of the strong_creep family: the plant (with fn, zeta), fs, duration, input and its scale."""
    fn = _loguniform(rng, 1.0, 2500.0)
    fs = float(rng.choice([1000.0, 2000.0])) if fn < 200.0 and rng.random() < 0.5 else 10_000.0
    fn = min(fn, fs / 4)
    zeta = _loguniform(rng, 0.01, 1.0)
    a1, a2 = _resonance(fn, zeta)
    return {"alpha": _loguniform(rng, 0.005, 0.7), "a1": a1, "a2": a2, "b": _gain(rng, 3.0),
            "fn": fn, "zeta": zeta, "fs": fs, "duration_s": float(rng.uniform(12.0, 16.0)),
            "input": str(rng.choice(list(INPUTS))), "input_scale": float(10.0 ** rng.uniform(-1.0, 2.0))}


def strong_creep(seed: int, rest: int | None = None) -> Scenario:
    """Stationary plant over the widest ranges, any input family."""
    rng = np.random.default_rng([seed, 1])
    plant = _strong_creep_plant(rng)
    h = 1.0 / plant["fs"]
    t = np.arange(int(plant["duration_s"] / h)) * h
    truth, params = _split({k: v for k, v in plant.items() if k != "fs"})
    u = plant["input_scale"] * INPUTS[plant["input"]](t, rng, rest)
    return _build("strong_creep", seed, rng, h, u, truth, params)[0]


def _abrupt(family: str, seed: int, stream: int,
            change: Callable[[dict, np.random.Generator], tuple[dict, dict]], rest: int | None = None) -> Scenario:
    """16 s at 10 kHz, fn 100-1000 Hz, steps every 1 s; ``change`` gives the parameters after t_change.

    ``stream`` keeps the families' random draws apart for equal seeds.
    """
    rng = np.random.default_rng([seed, stream])
    h = 1e-4
    t = np.arange(int(16.0 / h)) * h
    plant = _stationary_plant(rng, 100.0, 1000.0)
    t_change = float(rng.uniform(6.0, 10.0))
    after, info = change(plant, rng)
    on = t >= t_change
    truth = {k: np.where(on, after[k], plant[k]) for k in ("alpha", "a1", "a2", "b")}
    return _build(family, seed, rng, h, steps(t, rng, rest), truth, {**plant, **info, "input": "steps"},
                  change_time=float(t[np.argmax(on)]))[0]


def _add_mass(plant: dict, rng: np.random.Generator) -> tuple[dict, dict]:
    """Mass +25-60 %: a2 grows, a1 (damping/stiffness) and b stay."""
    m = float(rng.uniform(0.25, 0.6))
    return {**plant, "a2": plant["a2"] * (1 + m)}, {"change": "mass", "mass_ratio": 1 + m}


def _stiffness_or_damping(plant: dict, rng: np.random.Generator) -> tuple[dict, dict]:
    """Stiffness x(1 +- 0.2-0.5) (a1, a2, b divided by it), or damping a1 x 0.5-0.8 / 1.25-2."""
    if rng.random() < 0.5:
        k = 1.0 + float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 0.5))
        return ({**plant, "a1": plant["a1"] / k, "a2": plant["a2"] / k, "b": plant["b"] / k},
                {"change": "stiffness", "stiffness_ratio": k})
    c = float(rng.uniform(0.5, 0.8) if rng.random() < 0.5 else rng.uniform(1.25, 2.0))
    return {**plant, "a1": plant["a1"] * c}, {"change": "damping", "damping_ratio": c}


def payload(seed: int, rest: int | None = None) -> Scenario:
    """A payload added mid-record."""
    return _abrupt("payload", seed, 2, _add_mass, rest)


def stiffness(seed: int, rest: int | None = None) -> Scenario:
    """A stiffness or damping change mid-record."""
    return _abrupt("stiffness", seed, 3, _stiffness_or_damping, rest)


def drift(seed: int, rest: int | None = None) -> Scenario:
    """Thermal drift: alpha +10-20 % and b +5-10 % linearly over 60 s at 2 kHz."""
    rng = np.random.default_rng([seed, 4])
    h = 5e-4
    t = np.arange(int(60.0 / h)) * h
    plant = _stationary_plant(rng, 30.0, 400.0)
    da, db = float(rng.uniform(0.1, 0.2)), float(rng.uniform(0.05, 0.1))
    ramp = t / t[-1]
    truth = {**_split(plant)[0], "alpha": plant["alpha"] * (1 + da * ramp), "b": plant["b"] * (1 + db * ramp)}
    name = str(rng.choice(["steps", "staircase"]))
    return _build("drift", seed, rng, h, INPUTS[name](t, rng, rest), truth,
                  {**plant, "alpha_drift": da, "b_drift": db, "input": name})[0]


def controller(seed: int, rest: int | None = None) -> Scenario:
    """Stationary plant under a controller-like random staircase (5-50 ms holds)."""
    rng = np.random.default_rng([seed, 5])
    h = 1e-4
    t = np.arange(int(12.0 / h)) * h
    truth, params = _split(_stationary_plant(rng, 100.0, 2500.0))
    return _build("controller", seed, rng, h, random_staircase(t, rng, rest), truth,
                  {**params, "input": "random_staircase"})[0]


def close_modes(seed: int, rest: int | None = None) -> Scenario:
    """First mode plus two weaker ones 1.3-2.5x above it; truth_best from a noise-free second-order fit."""
    rng = np.random.default_rng([seed, 6])
    h = 1e-4
    t = np.arange(int(12.0 / h)) * h
    plant = _stationary_plant(rng, 100.0, 1000.0)
    ratios = np.sort(rng.uniform(1.3, 2.5, 2))
    modes = tuple((float(rng.uniform(0.1, 0.4)), *_resonance(plant["fn"] * r, _loguniform(rng, 0.02, 0.2)))
                  for r in ratios)
    truth, params = _split(plant)
    u = steps(t, rng, rest)
    scen, clean = _build("close_modes", seed, rng, h, u, truth,
                         {**params, "input": "steps", "modes": [list(m) for m in modes],
                          "mode_ratios": ratios.tolist()}, modes=modes)
    scen.truth_best = identify(t, u, clean).model.params()
    return scen


def mid_operation(seed: int, rest: int | None = None) -> Scenario:
    """12 s of a stationary plant taken 5 s into operation (steps or staircase since t = 0.05-0.3 s)."""
    rng = np.random.default_rng([seed, 7])
    h = 1e-4
    skip = int(5.0 / h)
    t = np.arange(skip + int(12.0 / h)) * h
    truth, params = _split(_stationary_plant(rng, 100.0, 1000.0))
    name = str(rng.choice(["steps", "staircase"]))
    scen, _ = _build("mid_operation", seed, rng, h, INPUTS[name](t, rng), truth,
                     {**params, "input": name, "dropped_s": 5.0})
    scen.u_history = scen.u[:skip].copy()
    for k in ("u", "y", "alpha", "a1", "a2", "b"):
        setattr(scen, k, getattr(scen, k)[skip:].copy())
    scen.t = np.arange(scen.u.size) * h
    return scen


def quiet_start(seed: int, rest: int | None = None) -> Scenario:
    """A start the search can get wrong: 1.5-3 s of small steps (levels 0-0.1 every 0.3 s, the resonance
    near the noise), then steps to +-1 every 0.5 s (the jump stays within 20 input ranges: not a glitch)."""
    rng = np.random.default_rng([seed, 8])
    h = 1e-4
    t = np.arange(int(10.0 / h)) * h
    truth, params = _split(_stationary_plant(rng, 2.0, 300.0))
    t0, t_big = _start(rng, t, rest), float(rng.uniform(1.5, 3.0))
    small = _held(t, t0, np.arange(0.0, t_big, 0.3), rng.uniform(0.0, 0.1, int(t_big / 0.3) + 1))
    big = _held(t, t0 + t_big, np.arange(0.0, 10.0, 0.5), rng.uniform(-1.0, 1.0, 20))
    u = np.where(t >= t0 + t_big, big, small)
    info = {**params, "input": "quiet_start", "big_from_s": t0 + t_big}
    return _build("quiet_start", seed, rng, h, u, truth, info)[0]


FAMILIES: dict[str, Callable[..., Scenario]] = {
    "strong_creep": strong_creep, "payload": payload, "stiffness": stiffness, "drift": drift,
    "controller": controller, "close_modes": close_modes, "mid_operation": mid_operation,
    "quiet_start": quiet_start}


#: Families whose records can start at rest (all but the one taken in operation): ``make``'s ``rest``.
FROM_REST = tuple(name for name in FAMILIES if name != "mid_operation")


def make(family: str, seed: int, rest: int | None = None) -> Scenario:
    """Scenario ``seed`` of ``family`` (deterministic). ``rest``: the input's first change after this many samples
    of rest (0: its first level from the first sample, the plant at rest before it: the step at the first sample)
    instead of the family's 0.05-0.3 s; the same plant and input otherwise. Not for mid_operation (taken in
    operation: no rest)."""
    if rest is not None and family not in FROM_REST:
        raise ValueError(f"{family} records are taken in operation: no rest to set")
    scen = FAMILIES[family](seed, rest)
    if rest is not None:
        scen.params["rest_samples"] = int(rest)
    return scen
