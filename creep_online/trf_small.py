"""Trust-region-reflective least squares for a few bounded parameters: scipy's iteration, lean.

``scipy.optimize.least_squares(method="trf")`` with its defaults (exact trust-region
solver, linear loss, x_scale 1, ftol = xtol = gtol = 1e-8, at most 100 n evaluations)
spends ~0.3 ms of Python per iteration on its wrappers and on ~60 calls over
2-element arrays: more than layer 2's simulations on a 12,000-sample record.
``trf`` is the same iteration (Branch, Coleman and Li's reflective trust region with
the Coleman-Li scaling; More's trust-region solve on one SVD of the scaled,
augmented Jacobian; the step chosen among the trust-region step, its reflection on
the bound and the scaled gradient), following scipy's ``trf_bounds`` step for step,
with the n-vectors in Python floats and only the m-sized products in numpy. It
agrees with least_squares up to round-off (``tests/test_trf_small.py``: the same
evaluations and minimum on random bounded problems; the SVD is scipy's own LAPACK
call, ``_svd``), so layer 2 keeps scipy's behaviour where the data leave a
parameter undetermined (the earlier Levenberg-Marquardt replacement wandered
further along that direction).
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.linalg import LinAlgError, get_lapack_funcs

EPS = float(np.finfo(float).eps)


def trf(evaluate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], x0, lb, ub, *,
        ftol: float = 1e-8, xtol: float = 1e-8, gtol: float = 1e-8,
        max_nfev: int | None = None) -> tuple[np.ndarray, int, int]:
    """Minimise ||f(x)||^2 / 2 for lb < x < ub: (x, evaluations, scipy's status code).

    ``evaluate(x)`` returns (f, J) with J the m x n Jacobian at the same x (it
    comes with every evaluation; scipy would ask for it only at accepted points).
    """
    lb = [float(v) for v in lb]
    ub = [float(v) for v in ub]
    n = len(lb)
    x = _strictly_feasible([float(v) for v in x0], lb, ub, 1e-10)
    f, jac = evaluate(np.array(x))
    nfev, m = 1, f.size
    cost = 0.5 * float(f @ f)
    g = (jac.T @ f).tolist()
    v, _ = _scaling(x, g, lb, ub)
    delta = _norm([xi / math.sqrt(vi) for xi, vi in zip(x, v)]) or 1.0
    max_nfev = 100 * n if max_nfev is None else max_nfev
    alpha, status = 0.0, None
    while True:
        v, dv = _scaling(x, g, lb, ub)
        g_norm = max(abs(gi * vi) for gi, vi in zip(g, v))
        if g_norm < gtol:
            status = 1
        if status is not None or nfev == max_nfev:
            break
        d = [math.sqrt(vi) for vi in v]
        diag_h = [gi * dvi for gi, dvi in zip(g, dv)]
        g_h = [di * gi for di, gi in zip(d, g)]
        j_h = jac * np.array(d)
        u_svd, s, vt = _svd(np.vstack((j_h, np.diag(np.sqrt(diag_h)))))
        uf = (u_svd[:m].T @ f).tolist()
        s, vmat = s.tolist(), vt.T.tolist()
        theta = max(0.995, 1 - g_norm)
        reduction = -1.0
        while reduction <= 0 and nfev < max_nfev:
            p_h, alpha = _trust_region_step(n, m, uf, s, vmat, delta, alpha)
            p = [di * pi for di, pi in zip(d, p_h)]
            step, step_h, predicted = _select_step(x, j_h, diag_h, g_h, p, p_h, d, delta, lb, ub, theta)
            x_new = _strictly_feasible([xi + si for xi, si in zip(x, step)], lb, ub, 0.0)
            f_new, jac_new = evaluate(np.array(x_new))
            nfev += 1
            step_h_norm = _norm(step_h)
            if not np.all(np.isfinite(f_new)):
                delta = 0.25 * step_h_norm
                continue
            cost_new = 0.5 * float(f_new @ f_new)
            reduction = cost - cost_new
            delta_new, ratio = _update_radius(delta, reduction, predicted, step_h_norm, step_h_norm > 0.95 * delta)
            status = _termination(reduction, cost, _norm(step), _norm(x), ratio, ftol, xtol)
            if status is not None:
                break
            alpha *= delta / delta_new
            delta = delta_new
        if reduction > 0:
            x, f, jac, cost = x_new, f_new, jac_new, cost_new
            g = (jac.T @ f).tolist()
    return np.array(x), nfev, 0 if status is None else status


def _svd(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """scipy.linalg.svd(a, full_matrices=False), as trf calls it, without its wrappers (~25 us a call):
    the same LAPACK routine (gesdd) with the same optimal work size, so the same factors bit for bit.
    scipy's SVD, not numpy's: their LAPACKs round differently, and a degenerate record then ended
    elsewhere on its flat direction."""
    gesdd, gesdd_lwork = get_lapack_funcs(("gesdd", "gesdd_lwork"), (a,), ilp64="preferred")
    work, info = gesdd_lwork(a.shape[0], a.shape[1], compute_uv=1, full_matrices=0)
    u, s, vt, info = gesdd(a, compute_uv=1, lwork=int(work.real), full_matrices=0)
    if info != 0:
        raise LinAlgError(f"SVD did not converge (gesdd info {info})")
    return u, s, vt


def _norm(v) -> float:
    return math.sqrt(sum(vi * vi for vi in v))


def _dot(a, b) -> float:
    return sum(ai * bi for ai, bi in zip(a, b))


def _scaling(x, g, lb, ub) -> tuple[list, list]:
    """Coleman-Li scaling vector v and its derivative's sign dv (scipy's CL_scaling_vector)."""
    v, dv = [1.0] * len(x), [0.0] * len(x)
    for i, (xi, gi) in enumerate(zip(x, g)):
        if gi < 0 and math.isfinite(ub[i]):
            v[i], dv[i] = ub[i] - xi, -1.0
        if gi > 0 and math.isfinite(lb[i]):
            v[i], dv[i] = xi - lb[i], 1.0
    return v, dv


def _strictly_feasible(x, lb, ub, rstep: float) -> list:
    """x moved off the bounds it touches (scipy's make_strictly_feasible)."""
    out = list(x)
    for i, (xi, lo, hi) in enumerate(zip(x, lb, ub)):
        if rstep == 0.0:
            side = 1 if xi >= hi else (-1 if xi <= lo else 0)
        else:
            lower = xi - lo <= min(hi - xi, rstep * max(1.0, abs(lo))) and math.isfinite(lo)
            upper = hi - xi <= min(xi - lo, rstep * max(1.0, abs(hi))) and math.isfinite(hi)
            side = 1 if upper else (-1 if lower else 0)
        if side == -1:
            out[i] = math.nextafter(lo, hi) if rstep == 0.0 else lo + rstep * max(1.0, abs(lo))
        elif side == 1:
            out[i] = math.nextafter(hi, lo) if rstep == 0.0 else hi - rstep * max(1.0, abs(hi))
        if out[i] < lo or out[i] > hi:
            out[i] = 0.5 * (lo + hi)
    return out


def _trust_region_step(n: int, m: int, uf, s, vmat, delta: float, alpha: float) -> tuple[list, float]:
    """More's solution of the trust-region subproblem from the SVD (scipy's solve_lsq_trust_region)."""
    suf = [si * ui for si, ui in zip(s, uf)]
    full_rank = m >= n and s[-1] > EPS * m * s[0]
    if full_rank:
        p = [-_dot(row, [ui / si for ui, si in zip(uf, s)]) for row in vmat]
        if _norm(p) <= delta:
            return p, 0.0

    def phi_and_derivative(a: float) -> tuple[float, float]:
        denom = [si * si + a for si in s]
        p_norm = _norm([su / de for su, de in zip(suf, denom)])
        return p_norm - delta, -sum(su * su / de**3 for su, de in zip(suf, denom)) / p_norm

    upper = _norm(suf) / delta
    if full_rank:
        phi, phi_prime = phi_and_derivative(0.0)
        lower = -phi / phi_prime
    else:
        lower = 0.0
    if not full_rank and alpha == 0:
        alpha = max(0.001 * upper, math.sqrt(lower * upper))
    for _ in range(10):
        if alpha < lower or alpha > upper:
            alpha = max(0.001 * upper, math.sqrt(lower * upper))
        phi, phi_prime = phi_and_derivative(alpha)
        if phi < 0:
            upper = alpha
        ratio = phi / phi_prime
        lower = max(lower, alpha - ratio)
        alpha -= (phi + delta) * ratio / delta
        if abs(phi) < 0.01 * delta:
            break
    coef = [su / (si * si + alpha) for su, si in zip(suf, s)]
    p = [-_dot(row, coef) for row in vmat]
    scale = delta / _norm(p)
    return [pi * scale for pi in p], alpha


def _quadratic(j_h: np.ndarray, g, s, diag) -> float:
    """The model's change g.s + (|J s|^2 + s.diag.s) / 2 (scipy's evaluate_quadratic)."""
    js = j_h @ np.array(s)
    return 0.5 * (float(js @ js) + _dot([si * di for si, di in zip(s, diag)], s)) + _dot(s, g)


def _quadratic_1d(j_h: np.ndarray, g, s, diag, s0=None) -> tuple[float, float, float]:
    """(a, b, c) of the model along s0 + t s as a t^2 + b t + c (scipy's build_quadratic_1d)."""
    v = j_h @ np.array(s)
    a = 0.5 * (float(v @ v) + _dot([si * di for si, di in zip(s, diag)], s))
    b = _dot(g, s)
    if s0 is None:
        return a, b, 0.0
    u = j_h @ np.array(s0)
    b += float(u @ v)
    c = 0.5 * float(u @ u) + _dot(g, s0)
    s0d = [si * di for si, di in zip(s0, diag)]
    return a, b + _dot(s0d, s), c + 0.5 * _dot(s0d, s0)


def _minimize_1d(a: float, b: float, lo: float, hi: float, c: float = 0.0) -> tuple[float, float]:
    """Minimum of a t^2 + b t + c on [lo, hi] (scipy's minimize_quadratic_1d; first of equal values)."""
    ts = [lo, hi]
    if a != 0:
        extremum = -0.5 * b / a
        if lo < extremum < hi:
            ts.append(extremum)
    values = [t * (a * t + b) + c for t in ts]
    k = values.index(min(values))
    return ts[k], values[k]


def _to_bound(x, s, lb, ub) -> tuple[float, list]:
    """Largest stride along s inside the bounds and which components hit them, signed (step_size_to_bound)."""
    steps = [max((lo - xi) / si, (hi - xi) / si) if si != 0 else math.inf
             for xi, si, lo, hi in zip(x, s, lb, ub)]
    least = min(steps)
    return least, [(st == least) * ((si > 0) - (si < 0)) for st, si in zip(steps, s)]


def _to_trust_region(x, s, delta: float) -> float:
    """Larger t with |x + t s| = delta (scipy's intersect_trust_region, upper root)."""
    a, b, c = _dot(s, s), _dot(x, s), _dot(x, x) - delta**2
    d = math.sqrt(b * b - a * c)
    q = -(b + math.copysign(d, b))
    return max(q / a, c / q) if q != 0 else 0.0


def _select_step(x, j_h, diag_h, g_h, p, p_h, d, delta, lb, ub, theta):
    """The best of the trust-region step, its reflection and the scaled gradient (scipy's select_step)."""
    if all(lo <= xi + pi <= hi for xi, pi, lo, hi in zip(x, p, lb, ub)):
        return p, p_h, -_quadratic(j_h, g_h, p_h, diag_h)
    p_stride, hits = _to_bound(x, p, lb, ub)
    r_h = [-ri if hit else ri for ri, hit in zip(p_h, hits)]
    r = [di * ri for di, ri in zip(d, r_h)]
    p = [pi * p_stride for pi in p]
    p_h = [pi * p_stride for pi in p_h]
    x_on_bound = [xi + pi for xi, pi in zip(x, p)]
    to_tr = _to_trust_region(p_h, r_h, delta)
    to_bound, _ = _to_bound(x_on_bound, r, lb, ub)
    r_stride = min(to_bound, to_tr)
    if r_stride > 0:
        r_lo = (1 - theta) * p_stride / r_stride
        r_hi = theta * to_bound if r_stride == to_bound else to_tr
    else:
        r_lo, r_hi = 0.0, -1.0
    if r_lo <= r_hi:
        a, b, c = _quadratic_1d(j_h, g_h, r_h, diag_h, s0=p_h)
        r_stride, r_value = _minimize_1d(a, b, r_lo, r_hi, c)
        r_h = [ri * r_stride + pi for ri, pi in zip(r_h, p_h)]
        r = [ri * di for ri, di in zip(r_h, d)]
    else:
        r_value = math.inf
    p = [pi * theta for pi in p]
    p_h = [pi * theta for pi in p_h]
    p_value = _quadratic(j_h, g_h, p_h, diag_h)
    ag_h = [-gi for gi in g_h]
    ag = [di * ai for di, ai in zip(d, ag_h)]
    to_tr = delta / _norm(ag_h)
    to_bound, _ = _to_bound(x, ag, lb, ub)
    ag_stride = theta * to_bound if to_bound < to_tr else to_tr
    a, b, _ = _quadratic_1d(j_h, g_h, ag_h, diag_h)
    ag_stride, ag_value = _minimize_1d(a, b, 0.0, ag_stride)
    ag_h = [ai * ag_stride for ai in ag_h]
    ag = [ai * ag_stride for ai in ag]
    if p_value < r_value and p_value < ag_value:
        return p, p_h, -p_value
    if r_value < p_value and r_value < ag_value:
        return r, r_h, -r_value
    return ag, ag_h, -ag_value


def _update_radius(delta, reduction, predicted, step_norm, bound_hit) -> tuple[float, float]:
    """The trust radius after a step (scipy's update_tr_radius)."""
    if predicted > 0:
        ratio = reduction / predicted
    elif predicted == reduction == 0:
        ratio = 1.0
    else:
        ratio = 0.0
    if ratio < 0.25:
        delta = 0.25 * step_norm
    elif ratio > 0.75 and bound_hit:
        delta *= 2.0
    return delta, ratio


def _termination(reduction, cost, step_norm, x_norm, ratio, ftol, xtol) -> int | None:
    """scipy's check_termination: 2 (ftol), 3 (xtol), 4 (both) or None."""
    f_ok = reduction < ftol * cost and ratio > 0.25
    x_ok = step_norm < xtol * (xtol + x_norm)
    if f_ok and x_ok:
        return 4
    return 2 if f_ok else (3 if x_ok else None)
