"""Hold physics: tell leakage, a second creep and drift apart by how the output moves during input holds.

The BIC ranking (``explain.py``) weighs whole extended fits, transients included.
This check asks the narrower question the physics poses, on the holds alone:
once the resonance has settled, how does the output move while the input is
constant?

* **one creep law** (the base model): ``y' = b sum_k du_k (t - t_k)^(alpha-1) / Gamma(alpha)``;
* **leakage** (``tau s/(1 + tau s)`` on the output) adds exactly ``-(y - y0)/tau``:
  the output returns toward its zero ``y0`` (within the output range, extended
  by half of it), faster the farther it is;
* **a second creep** adds ``c sum_k du_k (t - t_k)^(alpha2-1) / Gamma(alpha2)``: it keeps moving
  with the sign and size of the steps before, a second power law;
* **drift** adds ``rate``: the same slope in every hold, whatever came before.

Only the settled part of each hold is used (transients, where resonance, delay
and second-mode errors live, are left out); its samples are averaged into
blocks, and the four motions above, in integral form (leakage exactly:
``y = y_creep - (1/tau) int (y - y0) dt``), are fitted to all blocks at once by
linear least squares with one offset, profiled over grids of the exponents (and
of the leakage zero) and polished. The output is taken after removing the fast
part (resonance around creep) of the best-fitting model, so that ringing does
not pass for motion. Each effect's evidence is its BIC drop over one creep law
on these blocks, counting blocks as independent only as far as the best
motion's residual is uncorrelated from block to block (``effective_blocks``).
A hold's level and its motion both count: the levels carry the long memory a
second creep and a leakage leave (within-hold motion alone, tried first, read
the second creep records tried at 3-10x the noise as ``none``). The check names
an effect when it beats one creep law and both other effects by ``EVIDENCE``;
``none`` when nothing beats one creep law by that much; ``inconclusive``
otherwise (no staircase, holds too few or short, or two effects explain the
holds about equally well). Measured by bench/bench_diagnose_physics.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..effects import simulate_with_effects
from ..effects.responses import creep_step
from .locate import input_changes, piecewise_constant

if TYPE_CHECKING:
    from ..model import CreepModel
    from .extended import ExtendedFit, Prepared

#: The effects this check tells apart (catalogue names).
EFFECTS = ("leakage", "second_creep", "drift")
#: BIC drop (on hold blocks) that decides, as the ranking's own threshold.
EVIDENCE = 10.0
#: Parameters of each motion: the creep law's (alpha, gain) and the effect's own.
K = {"none": 2, "drift": 3, "leakage": 4, "second_creep": 4}
#: Lower bound of the exponents.
A_LO = 1e-3
#: Exponent grid for both creep laws (0 < alpha <= 1).
ALPHAS = np.unique(np.concatenate([np.geomspace(0.002, 0.1, 10), np.linspace(0.12, 1.0, 23)]))
#: Grid of the leakage zero y0 over the output range widened by half of it on each side.
ZERO_GRID = np.linspace(-0.5, 1.5, 21)
#: Blocks each hold's settled part is averaged into (fewer in short holds) ...
BLOCKS_PER_HOLD = 16
#: ... and fewer in records with many holds, so that all holds together give at most about this many: the
#: polish evaluates the creep columns (changes x blocks) ~800 times, and on 30,000 samples with ~120 holds at
#: 16 blocks each the check took 0.67 of diagnose's 3.1 s. The bands bench's records (6000 samples, at
#: most ~25 holds) stay below it and keep 16 per hold.
MAX_BLOCKS = 480
#: A hold counts with at least this many blocks; the check needs this many counting holds.
MIN_BLOCKS, MIN_HOLDS = 3, 3
#: Settling skipped after each change: the resonance's settling time, at most this share of the hold.
SETTLE_SHARE = 0.5
#: A hold counts only if it lasts this many settling times of the resonance.
MIN_HOLD_SETTLES = 0.5


@dataclass
class HoldBlocks:
    """Block means of the settled hold samples (rows: blocks, holds one after the other)."""

    w: np.ndarray            # output with the model's fast part (ringing) removed
    t: np.ndarray            # time
    iy: np.ndarray           # running integral of the output (leakage: y' = -(y - y0)/tau)
    zlog: np.ndarray         # log of (t_block - t_change), per change (for creep columns)
    zmask: np.ndarray        # where the change precedes the sample
    du: np.ndarray           # input steps
    hold: np.ndarray         # hold index of each block
    weights: np.ndarray      # block weights (1 for uniform records)
    holds: int
    seconds: float
    y_lo: float
    y_span: float

    def demeaned(self, col: np.ndarray) -> np.ndarray:
        """col minus its weighted mean, times the weight: a regression row with the offset projected out."""
        return (col - np.average(col, weights=self.weights)) * self.weights

    def creep(self, alpha: float) -> np.ndarray:
        """Unit creep law's response to the input at the blocks: sum_k du_k (t - t_k)^alpha / Gamma(1 + alpha)."""
        p = np.where(self.zmask, np.exp(alpha * self.zlog), 0.0)
        return (self.du @ p) / math.gamma(1.0 + alpha)


def _changes(t: np.ndarray, u: np.ndarray, u_pre: float | None, t_pre: float | None) -> tuple[np.ndarray, np.ndarray]:
    """(times, sizes) of the input steps, the step into the record first when the record starts with one."""
    idx = input_changes(u)
    tk, du = list(t[idx]), list(np.diff(u)[idx - 1])
    if u_pre is not None and u[0] != u_pre:
        tk.insert(0, t[0] if t_pre is None else t_pre)
        du.insert(0, u[0] - u_pre)
    return np.asarray(tk, dtype=float), np.asarray(du, dtype=float)


def _hold_spans(t: np.ndarray, u: np.ndarray, settle: float, starts_with_step: bool) -> list[tuple[int, int]]:
    """(first, stop) sample of each hold's settled part: after each change, the settling skipped."""
    idx = input_changes(u)
    bounds = np.concatenate(([0], idx, [t.size]))
    spans = []
    for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        first_rest = j == 0 and not starts_with_step
        if b - a < 2 or (not first_rest and t[b - 1] - t[a] < MIN_HOLD_SETTLES * settle):
            continue        # shorter than half the ringing's settling: its motion is not told from ringing
        skip = 0.0 if first_rest else min(settle, SETTLE_SHARE * (t[b - 1] - t[a]))
        first = a + int(np.searchsorted(t[a:b], t[a] + skip))
        spans.append((first, b))
    return spans


def hold_blocks(data: Prepared, model: CreepModel, settle: float) -> HoldBlocks | str:
    """The hold blocks of a prepared record, ringing of ``model`` removed, or the reason there are too few to tell."""
    t, u, y = data.t, data.u, data.y
    if not piecewise_constant(u):
        return "the input is not a staircase: no holds to watch"
    tk, du = _changes(t, u, data.u_pre, data.t_pre)
    path = simulate_with_effects(model, t, u, {}, u_pre=data.u_pre, t_pre=data.t_pre)
    w_all = y - (path - model.b * _creep_at(t, tk, du, model.alpha))    # the model's fast part removed
    iy_all = np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))))
    wt_all = np.ones(t.size) if data.weights is None else np.asarray(data.weights, dtype=float)
    rows: dict[str, list] = {k: [] for k in ("w", "t", "iy", "wt", "hold")}
    seconds, holds = 0.0, 0
    spans = _hold_spans(t, u, settle, data.u_pre is not None)
    per_hold = max(MIN_BLOCKS, min(BLOCKS_PER_HOLD, MAX_BLOCKS // max(len(spans), 1)))
    for first, stop in spans:
        m = stop - first
        nb = min(per_hold, m // 2)
        if nb < MIN_BLOCKS:
            continue
        blk = np.arange(m) * nb // m
        cnt = np.bincount(blk, minlength=nb)
        for key, arr in (("w", w_all), ("t", t), ("iy", iy_all), ("wt", wt_all)):
            rows[key].append(np.bincount(blk, arr[first:stop], nb) / cnt)
        rows["hold"].append(np.full(nb, holds))
        seconds += t[stop - 1] - t[first]
        holds += 1
    if holds < MIN_HOLDS:
        return f"{holds} hold(s) long enough to watch (needs {MIN_HOLDS}): too few to tell"
    tb = np.concatenate(rows["t"])
    lag = tb[None, :] - tk[:, None]
    mask = lag > 0
    return HoldBlocks(np.concatenate(rows["w"]), tb, np.concatenate(rows["iy"]),
                      np.log(np.where(mask, lag, 1.0)), mask, du, np.concatenate(rows["hold"]),
                      np.concatenate(rows["wt"]), holds, float(seconds), float(np.min(y)), float(np.ptp(y)))


def _creep_at(t: np.ndarray, tk: np.ndarray, du: np.ndarray, alpha: float) -> np.ndarray:
    """sum_k du_k creep_step(alpha, t - t_k) at every sample (the base model's creep, deviation variables)."""
    out = np.zeros(t.size)
    for tj, d in zip(tk, du):
        out += d * creep_step(alpha, t - tj)
    return out


# --------------------------------------------------------------------------- the four motions
def _fit(target: np.ndarray, cols: list[np.ndarray]) -> tuple[float, np.ndarray, np.ndarray]:
    """(RSS, coefficients, residual) of target on cols (scaled for conditioning)."""
    a = np.column_stack(cols)
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    coef = np.linalg.lstsq(a / scale, target, rcond=None)[0] / scale
    r = target - a @ coef
    return float(r @ r), coef, r


def effective_blocks(blocks: HoldBlocks, resid: np.ndarray) -> float:
    """Blocks counted as independent: n (1 - rho)/(1 + rho), rho = lag-1 correlation of resid within holds.

    A misfit no motion explains (ringing left over, an effect outside these
    three) is smooth from block to block; counting its blocks as independent
    would make small differences between motions look decisive.
    """
    same = blocks.hold[1:] == blocks.hold[:-1]
    den = float(resid @ resid)
    rho = float(np.sum(resid[1:][same] * resid[:-1][same]) / den) if den > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    return resid.size * (1.0 - rho) / (1.0 + rho)


def motions(blocks: HoldBlocks) -> dict[str, dict]:
    """Best fit of each motion on the hold blocks: {name: {rss, k, params}} for none and the three effects.

    Each motion's exponents (and the leakage zero) are searched on ``ALPHAS``
    (``ZERO_GRID``), then polished continuously: a grid point a little off the
    true exponent would pass for a second creep law.
    """
    w = blocks.demeaned(blocks.w)
    tc = blocks.demeaned(blocks.t)
    z_grid = {a: blocks.demeaned(blocks.creep(a)) for a in ALPHAS}

    def z(a: float) -> np.ndarray:
        return z_grid[a] if a in z_grid else blocks.demeaned(blocks.creep(a))

    def zero_col(f: float) -> np.ndarray:
        return blocks.demeaned(blocks.iy - (blocks.y_lo + f * blocks.y_span) * blocks.t)

    def leak(p) -> tuple[float, np.ndarray, np.ndarray]:
        rss, c, r = _fit(w, [z(p[0]), zero_col(p[1])])
        if c[1] < 0:        # tau > 0: decays toward y0; else the bound tau = inf (one creep law)
            return rss, c, r
        rss, c, r = _fit(w, [z(p[0])])
        return rss, np.array([c[0], 0.0]), r

    models = {
        "none": (lambda p: _fit(w, [z(p[0])]), [(a,) for a in ALPHAS], [(A_LO, 1.0)]),
        "drift": (lambda p: _fit(w, [z(p[0]), tc]), [(a,) for a in ALPHAS], [(A_LO, 1.0)]),
        "leakage": (leak, [(a, f) for a in ALPHAS for f in ZERO_GRID], [(A_LO, 1.0), (ZERO_GRID[0], ZERO_GRID[-1])]),
        "second_creep": (lambda p: _fit(w, [z(p[0]), z(p[1])]),
                         [(a, b) for i, a in enumerate(ALPHAS) for b in ALPHAS[i + 1:]], [(A_LO, 1.0)] * 2),
    }
    return {name: _profile(fn, grid, bounds, name, blocks) for name, (fn, grid, bounds) in models.items()}


def _profile(fn, grid: list[tuple], bounds: list[tuple[float, float]], name: str, blocks: HoldBlocks) -> dict:
    """The grid's best point of ``fn`` (-> rss, coef, residual) polished by bounded Nelder-Mead; rss, k, params."""
    from scipy.optimize import minimize
    start = np.array(min(grid, key=lambda p: fn(p)[0]), dtype=float)
    res = minimize(lambda p: fn(p)[0], start, method="Nelder-Mead", bounds=bounds,
                   options={"xatol": 1e-5, "fatol": 1e-14, "maxfev": 300})
    p = res.x if res.fun <= fn(start)[0] else start
    rss, c, resid = fn(p)
    params = {"alpha": float(p[0]), "gain": float(c[0])}
    if name == "drift":
        params["rate"] = float(c[1])
    elif name == "leakage":
        params.update(tau_s=-1.0 / c[1] if c[1] < 0 else math.inf, zero=blocks.y_lo + float(p[1]) * blocks.y_span)
    elif name == "second_creep":
        params.update(alpha2=float(p[1]), gain2=float(c[1]))
    return {"rss": rss, "k": K[name], "params": params, "residual": resid}


# --------------------------------------------------------------------------- the verdict
def _sentence(effect: str, p: dict) -> str:
    """What the fitted motion says, with its numbers."""
    if effect == "leakage":
        return (f"the output returns toward {p['zero']:.4g} during holds, -(y - y0)/tau with tau = {p['tau_s']:.3g} s")
    if effect == "second_creep":
        return (f"the output keeps moving after each step with the step's sign: a second power law "
                f"alpha2 = {p['alpha2']:.3g} beside alpha = {p['alpha']:.3g}")
    if effect == "drift":
        return f"the output moves at the same rate in every hold whatever the step before: {p['rate']:.4g} per s"
    return "one creep law explains how the output moves during holds"


def _decide(ev: dict[str, float], ranked: list[str], margin: float, top_params: dict) -> tuple[str, str]:
    """(verdict, reason): the top effect if it beats one creep law and the runner-up by EVIDENCE."""
    top, runner = ranked[0], ranked[1]
    if ev[top] < EVIDENCE:
        return "none", f"no effect beats one creep law by {EVIDENCE:g} (best {top} {ev[top]:.3g})"
    if margin < EVIDENCE:
        return "inconclusive", (f"{top} and {runner} explain the holds about equally well "
                                f"({ev[top]:.3g} vs {ev[runner]:.3g})")
    return top, _sentence(top, top_params)


def physics_check(data: Prepared, base: ExtendedFit, fits: tuple[ExtendedFit, ...] = ()) -> dict:
    """Which of leakage, second creep or drift the holds point to, why, and how firmly (JSON-ready).

    The resonance whose ringing is removed is that of the best-fitting of
    ``base`` and ``fits`` (the extended fits): a strong effect drags the base
    fit's resonance off (e.g. damping on its bound), and its ringing would then
    pass for motion.

    ``verdict`` is one of ``EFFECTS``, ``none`` (one creep law explains the
    holds) or ``inconclusive`` (``reason`` says why); ``evidence`` holds each
    effect's BIC drop over one creep law on the hold blocks, ``margin`` the
    winner's lead over the runner-up, ``params`` each motion's fitted numbers.
    """
    model = min((base, *fits), key=lambda f: f.rss).model
    settle = min(model.settling_time, 0.25 * (data.t[-1] - data.t[0]))
    blocks = hold_blocks(data, model, settle)
    if isinstance(blocks, str):
        return {"applicable": False, "verdict": "inconclusive", "reason": blocks, "evidence": {}}
    moved = motions(blocks)
    best = min(EFFECTS, key=lambda e: moved[e]["rss"])
    n = effective_blocks(blocks, moved[best]["residual"])

    def bic(f: dict) -> float:
        return n * math.log(max(f["rss"], 1e-300)) + f["k"] * math.log(n)

    ev = {e: bic(moved["none"]) - bic(moved[e]) for e in EFFECTS}
    ranked = sorted(EFFECTS, key=lambda e: -ev[e])
    margin = ev[ranked[0]] - max(ev[ranked[1]], 0.0)
    verdict, reason = _decide(ev, ranked, margin, moved[ranked[0]]["params"])
    return {"applicable": True, "verdict": verdict, "reason": reason, "evidence": ev, "margin": margin,
            "ranked": ranked, "holds": blocks.holds, "hold_seconds": blocks.seconds, "blocks": int(blocks.w.size),
            "settle_s": settle, "effective_blocks": n, "params": {e: moved[e]["params"] for e in ("none", *EFFECTS)},
            "explanations": {e: _sentence(e, moved[e]["params"]) for e in EFFECTS if ev[e] > 0}}
