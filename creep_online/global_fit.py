"""Global convergence for ``identify``: a multi-start joint fit with nuisance terms projected out.

The two layers converge on the step experiments they were made for; on dense
inputs (PRBS, short random holds), strong creep or records taken in operation
their start can lie in another basin, and the warm-started polish stays there.
This module is the fallback ``identify`` runs when the fit is not at the
noise floor:

1. A starting grid over alpha x fn x zeta, scored in one numba pass per alpha
   with the split form (fractional integral, then the FOH-exact resonance),
   the gain and the nuisance columns projected out.
2. Trust-region-reflective fits of (alpha, log a1, log a2) from the best grid
   points and from the caller's warm starts, with the exact simulator and the
   gain, offset and (for ``init``) the free response of the unknown initial
   state (``creep_online.initial_state``) solved linearly at every step.
3. The structure (at rest or in operation) is chosen by BIC, so records that
   do start at rest are not given free initial-state terms they do not need.

Stops as soon as a fit reaches the noise floor (``at_floor``) with the resonance
the refined grid finds (a warm start at the floor is checked against it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import kernels
from .discretize import foh_matrices_batch, step_response_grid
from .initial_state import creep_columns, free_columns, past_offsets
from .metrics import noise_std_estimate
from .model import CreepModel
from .simulate import fractional_integral, superpose

#: alpha values of the starting grid.
GRID_ALPHAS = (0.01, 0.04, 0.12, 0.3, 0.55, 0.8)
#: Damping ratios and number of frequencies of the starting grid.
GRID_ZETAS = (0.01, 0.03, 0.1, 0.3, 0.7, 1.5, 4.0)
GRID_FREQUENCIES = 24
#: Frequencies of the second-pass grid at the best alpha (a lightly damped resonance needs ~3 % steps).
REFINE_FREQUENCIES = 160
#: The grid is scored on at most this many samples from the input's first move (``grid_samples``).
GRID_SAMPLES = 8000
#: Grid points (best first, at most one per alpha) each fitted from.
STARTS = 3
#: Residual rms within this factor (plus 2.5 / sqrt(n)) of the residual's own noise level: at the floor.
FLOOR_SLACK = 0.01
ALPHA_RANGE = (1e-4, 0.999)


def floor_ratio(r: np.ndarray, noise: float | None = None) -> float:
    """rms(r) over the white-noise level of r (second differences, unless given): 1 for pure noise."""
    noise = noise_std_estimate(r) if noise is None else noise
    if not (math.isfinite(noise) and noise > 0):
        return float("inf") if np.any(r) else 1.0
    return float(np.sqrt(np.mean(r * r))) / noise


#: Block lengths (samples) of the low-frequency whiteness test.
BLOCKS = (8, 64, 512)
#: A block statistic this many of its own standard deviations above 1 fails the test.
BLOCK_SIGMAS = 5.0


def block_ratio(r: np.ndarray, width: int, noise: float) -> tuple[float, int]:
    """(mean square of the block means x width / noise^2, number of blocks): about 1 for white noise."""
    k = r.size // width
    if k < 8:
        return 1.0, k
    means = r[:k * width].reshape(k, width).mean(axis=1)
    return float(np.mean(means * means)) * width / noise**2, k


def at_floor(r: np.ndarray, noise: float | None = None) -> bool:
    """Whether a residual looks like white noise alone.

    Two tests against the residual's own high-frequency level (second
    differences): its rms, and the power of its block means over 8, 64 and
    512 samples, which a smooth misfit (the usual kind: a wrong creep, a
    missed slow mode) inflates far more than it does the rms. Each block
    statistic of white noise is a chi-square mean of k blocks (std
    sqrt(2/k)). ``noise``: that level, when the caller has it already.
    """
    noise = noise_std_estimate(r) if noise is None else noise
    if not (math.isfinite(noise) and noise > 0):
        return not np.any(r)
    if floor_ratio(r, noise) > 1.0 + FLOOR_SLACK + 2.5 / math.sqrt(max(r.size, 1)):
        return False
    for width in BLOCKS:
        stat, k = block_ratio(r, width, noise)
        if k >= 8 and stat > 1.0 + BLOCK_SIGMAS * math.sqrt(2.0 / k):
            return False
    return True


@dataclass
class Design:
    """The columns of one parameter set: the model's response s and the nuisance columns."""

    s: np.ndarray
    nuisance: np.ndarray    # (n, k), may have k = 0


@dataclass
class Problem:
    """One record and one model structure: input deviations, data, which nuisance terms are free."""

    u: np.ndarray
    y: np.ndarray
    h: float
    init: bool              # free response of an unknown initial state
    offset: bool            # free output offset

    def design(self, alpha: float, a1: float, a2: float) -> Design:
        """Exact response and nuisance columns at (alpha, a1, a2)."""
        n = self.u.size
        if not self.init:
            s = superpose(step_response_grid(alpha, a1, a2, self.h, n), self.u)
            cols = np.ones((n, 1)) if self.offset else np.zeros((n, 0))
            return Design(s, cols)
        long = step_response_grid(alpha, a1, a2, self.h, n + int(past_offsets(n)[-1]) + 1)
        s = superpose(long[:n], self.u - self.u[0])
        cols = [free_columns(long, a1, a2, self.h, n)]
        if self.offset:
            cols.insert(0, np.ones((n, 1)))
        return Design(s, np.hstack(cols))

    def solve(self, d: Design) -> tuple[np.ndarray, np.ndarray]:
        """Linear least squares for [b, nuisance weights]: (coefficients, residual)."""
        a = np.column_stack((d.s, d.nuisance))
        norms = np.linalg.norm(a, axis=0)
        keep = norms > 1e-300
        coef = np.zeros(a.shape[1])
        if np.any(keep):
            c, *_ = np.linalg.lstsq(a[:, keep] / norms[keep], self.y, rcond=1e-12)
            coef[keep] = c / norms[keep]
        return coef, self.y - a @ coef

    def residual(self, p: np.ndarray) -> np.ndarray:
        """Residual at (alpha, log a1, log a2) in units of the data's spread, so that the solver's
        tolerances (gtol) mean the same for any output scale."""
        scale = float(np.std(self.y)) or 1.0
        return self.solve(self.design(p[0], math.exp(p[1]), math.exp(p[2])))[1] / scale

    @property
    def linear_count(self) -> int:
        n = self.u.size
        return 1 + int(self.offset) + (past_offsets(n).size + 2 if self.init else 0)


@dataclass
class GlobalFit:
    """The best fit over the starts and structures tried."""

    model: CreepModel
    problem: Problem
    coef: np.ndarray
    residual: np.ndarray
    y_hat: np.ndarray
    bic: float
    info: dict = field(default_factory=dict)

    @property
    def offset(self) -> float:
        return float(self.coef[1]) if self.problem.offset else 0.0


def grid_samples(prob: Problem) -> int:
    """The leading samples the starting grid scores: GRID_SAMPLES after the input's first move (from 0; for a
    record in operation, from its first level), so that a record which holds its level for longer still shows
    the grid a forced response."""
    ref = prob.u[0] if prob.init else 0.0
    moved = np.flatnonzero(prob.u != ref)
    first = int(moved[0]) if moved.size else 0
    return min(prob.u.size, first + GRID_SAMPLES)


def grid_starts(prob: Problem, f_lo: float, f_hi: float,
                alphas: tuple[float, ...] = GRID_ALPHAS,
                frequencies: int = GRID_FREQUENCIES) -> list[tuple[float, float, float, float]]:
    """(cost, alpha, fn, zeta) of the best grid point per alpha, best first (split form, nuisance projected)."""
    n = grid_samples(prob)
    h = prob.h
    u = prob.u[:n] - (prob.u[0] if prob.init else 0.0)
    y = prob.y[:n]
    fn, zeta = np.meshgrid(np.geomspace(f_lo, f_hi, frequencies), GRID_ZETAS, indexing="ij")
    fn, zeta = fn.ravel(), zeta.ravel()
    wn = 2 * np.pi * fn
    phi, g0, g1 = foh_matrices_batch(2 * zeta / wn, 1 / wn**2, h)
    out = []
    for alpha in alphas:
        cols = [np.ones(n)] if prob.offset else []
        if prob.init:
            cols += list(creep_columns(alpha, h, n).T)
        q = _orthonormal(np.column_stack(cols) if cols else np.zeros((n, 0)))
        y_perp = y - q @ (q.T @ y)
        z = fractional_integral(u, h, alpha)
        kernel = kernels.foh_grid_costs_free if prob.init else kernels.foh_grid_costs_projected
        costs = kernel(z, np.ascontiguousarray(y_perp), np.ascontiguousarray(q), phi, g0, g1, h)
        k = int(np.argmin(costs))
        out.append((float(costs[k]), alpha, float(fn[k]), float(zeta[k])))
    return sorted(out)


def _orthonormal(c: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the column span of c (SVD, numerically rank-revealing)."""
    if c.shape[1] == 0:
        return c
    u, sv, _ = np.linalg.svd(c / np.maximum(np.linalg.norm(c, axis=0), 1e-300), full_matrices=False)
    return u[:, sv > 1e-10 * sv[0]]


def fit_from(prob: Problem, start: CreepModel, max_nfev: int = 80) -> tuple[CreepModel, np.ndarray, np.ndarray]:
    """TRF over (alpha, log a1, log a2) from ``start``: (model, linear coefficients, residual)."""
    from scipy.optimize import least_squares   # ~0.1 s to import: only the fits that come here pay for it

    p0 = np.array([min(max(start.alpha, 2e-4), 0.99), math.log(start.a1), math.log(start.a2)])
    lo = [ALPHA_RANGE[0], p0[1] - 12.0, p0[2] - 12.0]
    hi = [ALPHA_RANGE[1], p0[1] + 12.0, p0[2] + 12.0]
    sol = least_squares(prob.residual, p0, bounds=(lo, hi), method="trf", x_scale=[0.02, 0.2, 0.2],
                        diff_step=1e-7, max_nfev=max_nfev, xtol=1e-10, ftol=1e-10)
    alpha, a1, a2 = float(sol.x[0]), math.exp(sol.x[1]), math.exp(sol.x[2])
    coef, r = prob.solve(prob.design(alpha, a1, a2))
    b = coef[0] if coef[0] != 0.0 else 1.0
    return CreepModel(alpha, a1, a2, b), coef, r


def n_bic(r: np.ndarray, params: int) -> float:
    """Bayesian information criterion of a Gaussian residual with ``params`` fitted parameters."""
    n = r.size
    return n * math.log(max(float(r @ r), 1e-300) / n) + params * math.log(n)


def global_fit(u: np.ndarray, y: np.ndarray, h: float, *, warm: list[CreepModel], offset_free: bool = True,
               try_init: bool = True) -> GlobalFit:
    """Best fit over the structures (at rest; in operation when ``try_init``) and multi-starts.

    ``warm`` are starting models from elsewhere (e.g. the two layers), fitted
    first. Returns as soon as a fit is at the noise floor and its resonance is the
    refined grid's (``_refined``); otherwise the lowest BIC over everything tried.
    """
    n = u.size
    f_hi = 0.45 / h
    f_lo = min(max(1.0 / (min(n, GRID_SAMPLES) * h), 1e-6), f_hi / 8)
    structures = [Problem(u, y, h, init=False, offset=offset_free)]
    if try_init:
        structures.append(Problem(u, y, h, init=True, offset=offset_free))
    best: GlobalFit | None = None
    tried: list[dict] = []
    for prob in structures:
        starts = list(warm)
        for cost, alpha, fn, zeta in grid_starts(prob, f_lo, f_hi)[:STARTS]:
            starts.append(CreepModel.from_resonance(alpha, fn, zeta))
        from_warm = False
        for k, start in enumerate(starts):
            fit = _fit(prob, start, tried)
            if fit is not None and (best is None or fit.bic < best.bic):
                best, from_warm = fit, k < len(warm)
            if fit is not None and at_floor(fit.residual):
                break
        if best is None or best.problem is not prob:
            continue
        if from_warm or not at_floor(best.residual):
            best = _refined(prob, best, f_lo, f_hi, tried)
        if at_floor(best.residual):
            break
    if best is None:
        raise ValueError("no start converged")
    best.info = {"tried": tried, "design": best.problem.design(best.model.alpha, best.model.a1, best.model.a2)}
    return best


def _fit(prob: Problem, start: CreepModel, tried: list[dict]) -> GlobalFit | None:
    """``fit_from`` as a ``GlobalFit`` (None when it fails), recorded in ``tried``."""
    try:
        model, coef, r = fit_from(prob, start)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return None
    fit = GlobalFit(model, prob, coef, r, prob.y - r, n_bic(r, 3 + prob.linear_count))
    tried.append({"init": prob.init, "start": start.params(), "bic": fit.bic, "floor_ratio": floor_ratio(r)})
    return fit


#: A refined grid start within this factor of the best fit's natural frequency lies in its basin: not fitted again.
SAME_BASIN_FN = 1.25


def _refined(prob: Problem, best: GlobalFit, f_lo: float, f_hi: float, tried: list[dict]) -> GlobalFit:
    """The resonance grid again at the best fit's alpha (creep fixes alpha well before the resonance); a fit from
    its best point kept when its BIC is lower.

    Also run when a warm start reached the noise floor: the warm start is the layers' resonance, which is why the
    global fit runs at all, and "at the floor" says the residual is white, not that the resonance is the best one
    (a wrong resonance of a record taken in operation can ring inside the free-response terms of the initial state
    and pass the whiteness test).
    """
    refine = grid_starts(prob, f_lo, f_hi, (best.model.alpha,), REFINE_FREQUENCIES)[0]
    if max(refine[2] / best.model.fn, best.model.fn / refine[2]) < SAME_BASIN_FN:
        return best
    fit = _fit(prob, CreepModel.from_resonance(refine[1], refine[2], refine[3]), tried)
    return fit if fit is not None and fit.bic < best.bic else best


def global_uncertainty(fit: GlobalFit) -> dict[str, float]:
    """1-sigma of (alpha, a1, a2, b) from the Gauss-Newton covariance of the whole problem.

    The Jacobian holds the derivatives of the fitted output in (alpha, log a1,
    log a2) with the linear weights held, and every linear column (gain,
    offset, free response), so the correlations with the nuisance terms widen
    the intervals as they should.
    """
    prob, m, coef = fit.problem, fit.model, fit.coef
    p = np.array([m.alpha, math.log(m.a1), math.log(m.a2)])
    d0 = fit.info["design"]
    base = np.column_stack((d0.s, d0.nuisance))
    cols = []
    for k in range(3):
        step = 1e-6 * max(abs(p[k]), 1e-2)
        dp = p.copy()
        dp[k] += step
        d = prob.design(dp[0], math.exp(dp[1]), math.exp(dp[2]))
        cols.append((np.column_stack((d.s, d.nuisance)) @ coef - base @ coef) / step)
    jac = np.column_stack(cols + [base])
    jac = jac[:, np.linalg.norm(jac, axis=0) > 1e-300]
    r = fit.residual
    sigma2 = float(r @ r) / max(r.size - jac.shape[1], 1)
    norms = np.linalg.norm(jac, axis=0)
    cov = sigma2 * np.linalg.pinv((jac / norms).T @ (jac / norms), rcond=1e-13) / np.outer(norms, norms)
    sd = np.sqrt(np.abs(np.diag(cov)))
    return {"alpha": float(sd[0]), "a1": float(sd[1] * m.a1), "a2": float(sd[2] * m.a2), "b": float(sd[3])}
