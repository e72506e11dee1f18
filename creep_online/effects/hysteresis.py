"""``hysteresis``: rate-independent memory of input reversals, a Prandtl-Ishlinskii model on the input.

``v = u + sum_i w_i play_{r_i}[u]``. The fit uses ``HYSTERESIS_THRESHOLDS``
(fractions of the input range) and chooses the operators' state before the
record (``INITIAL_STATES``) by a short polish of each. Its search for the
plant's parameters fits the weights in the plays' leading singular directions
(``HYSTERESIS_COMPONENTS`` linear columns); the reported weights are then
solved on the plays themselves (``PlayWeights``): every branch of the loop
at least ``SLOPE_FLOOR`` times as steep as the mean branch (the loop is
invertible, ``pi_inverse``), a
Gaussian prior of scale ``WEIGHT_SCALE`` on each weight (combinations the
record cannot tell apart share their weight instead of cancelling), and an
operator the record never opens pinned at 0. Signature: the residual depends
on the direction of the last input change.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import ModelError
from .base import FitView, InputCompensator, InputEffect

#: Play-operator thresholds the fit uses, as fractions of the input range: 24 evenly spaced
#: over (0, 1/2) (an operator whose threshold exceeds half the range never opens a loop).
#: A PI loop with a smooth threshold density is an integral over r; with free weights the
#: sum is a quadrature of it, and its error is what the fit misses: ten uneven thresholds
#: (0.02 ... 0.48) left 0.3-4 % of the noise on hysteresis 10-100x the noise (enough for
#: a false second effect to close the gap: 18 of 100 such records); sixteen left it on one
#: record in 18 at 80x; twenty-four reach the true model's residual on all of them.
HYSTERESIS_THRESHOLDS = tuple((k + 0.5) / 48 for k in range(24))


def threshold_fractions(count: int = len(HYSTERESIS_THRESHOLDS)) -> np.ndarray:
    """``count`` play thresholds as fractions of the input range, evenly spaced over (0, 1/2) like the fit's
    (``count`` 24: ``HYSTERESIS_THRESHOLDS``); times the input range they are a record's thresholds."""
    return (np.arange(count) + 0.5) / (2 * count)


#: The search's linear columns: the leading singular directions of the record's own 24 play outputs
#: (``Hysteresis.components``), not the plays themselves: nearly collinear, and each column is filtered
#: through the plant at every evaluation (24 doubled diagnose's time on a 30,000-sample hysteresis record).
#: On the 18 records above, 8 components already give the 24 plays' residual to four decimals; 12 keep a margin
#: (and the parameters the BIC counts near the old 10).
HYSTERESIS_COMPONENTS = 12
#: A direction of the record's plays whose singular value is below COMPONENT_RCOND x the largest is numerically
#: null (a staircase with L levels has at most L - 1 independent plays); its column is left at zero. The plays'
#: Gram matrix resolves singular values down to ~1e-8 of the largest (a three-level staircase: 1, 0.22, 0.046,
#: then 4e-8 and below, where the exact ones are 1e-13): fitted, such a column is rounding noise the least squares
#: scales up, its weight ~1e14, and it fitted what the true loop could not (the wrong initial state) to the noise.
COMPONENT_RCOND = 1e-6
#: Play-operator states before the record, as multiples of the threshold added to u[0]: centred on u[0],
#: or as left by a rise to u[0] (p = u[0] - r) or a fall to u[0] (p = u[0] + r).
INITIAL_STATES = {"centred": 0.0, "ascending": -1.0, "descending": 1.0}
#: The flattest branch of a fitted loop, relative to the mean branch: after a reversal the loop's slope is S_0 = 1
#: (u alone) and, once the input has travelled 2 r_j, S_j = 1 + w_1 + ... + w_j (thresholds ascending). S_j > 0 on
#: every branch is what makes the loop invertible (``pi_inverse``); S_j >= SLOPE_FLOOR mean(S_0 .. S_K) keeps every
#: branch of the inverse within 1 / SLOPE_FLOOR of its mean. (Relative to S_0 alone, a fit could make the first
#: branch flat instead: b -> 0, its weights ~1e300, on a loop whose large-signal branch falls.)
SLOPE_FLOOR = 0.05
#: An operator's output counts as an affine function of the input (``opened_operators``: its weight only trades
#: with the gain) within this fraction of the input's range: rounding in the plays' sums, with a wide margin.
AFFINE_RTOL = 1e-9
#: ``solve_pi_weights`` works on the design's triangular factor when it has more than this many rows per column.
COMPRESS_ROWS = 4
#: Prior scale of each weight (a Gaussian of this standard deviation around 0): a weight the data determine
#: better than this is theirs; a combination of weights the record cannot see (operators it opens the same way)
#: is held near 0, so the weights share what the data say instead of cancelling in +-1e12 pairs. On 12 random
#: plants (staircases, sines, triangles; loops 2-20 % of the stroke) the fitted loop's error on another input,
#: over the true loop's width, had the median 0.95 % at a scale of 0.01, 0.85 % at 0.03, 1.35 % at 0.1, 1.85 %
#: at 0.3, 2.2 % at 1 (the worst, 6 %, a three-level staircase at every scale); the residual moved < 0.3 %.
WEIGHT_SCALE = 0.03
#: The prior's noise variance is at least (PRIOR_FLOOR x the output's RMS)^2: a noise-free record still pins
#: what it does not determine.
PRIOR_FLOOR = 1e-6
#: The prior's scale needs |b| (it is on the weights w = (b w) / b): from the search, then from the solution, at
#: most PRIOR_ITERATIONS times, until it moves by less than PRIOR_RTOL.
PRIOR_ITERATIONS = 3
PRIOR_RTOL = 1e-3


def play_operators(u: np.ndarray, r: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
    """Play (backlash) operator outputs, one row per threshold r_i >= 0.

    ``p[n] = max(u[n] - r, min(u[n] + r, p[n-1]))`` with ``p[-1] = u[0]``
    (the operators start centred on the first input value unless ``initial``
    is given). A compiled loop (``kernels.play_rows``): a record whose input
    changes at every sample needs one update per sample.
    """
    from ..kernels import play_rows          # numba on first use: importing the effects stays light (``--help``)
    u = np.ascontiguousarray(u, dtype=float)
    r = np.ascontiguousarray(np.atleast_1d(np.asarray(r, dtype=float)))
    p = np.full(r.size, u[0]) if initial is None else np.broadcast_to(np.asarray(initial, dtype=float), r.shape).copy()
    return play_rows(u, r, p)


def initial_plays(u0: float, r: np.ndarray, initial: str = "centred") -> np.ndarray:
    """The operators' states before the record for an ``INITIAL_STATES`` name (ModelError if unknown)."""
    if initial not in INITIAL_STATES:
        raise ModelError(f"hysteresis initial must be one of {', '.join(INITIAL_STATES)}, got {initial!r}")
    return u0 + INITIAL_STATES[initial] * np.atleast_1d(np.asarray(r, dtype=float))


def hysteresis_input(u: np.ndarray, r, w, initial: str = "centred") -> np.ndarray:
    """v = u + sum_i w_i play_{r_i}[u] (Prandtl-Ishlinskii).

    ``initial``: the operators' state before the record -- "centred" on u[0],
    "ascending" (the input last rose to u[0]: p = u[0] - r) or "descending"
    (it last fell to u[0]: p = u[0] + r).
    """
    w = np.atleast_1d(np.asarray(w, dtype=float))
    r = np.atleast_1d(np.asarray(r, dtype=float))
    u = np.asarray(u, dtype=float)
    return u + w @ play_operators(u, r, initial=initial_plays(u[0], r, initial))


def opened_operators(plays: np.ndarray, before: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Which operators' weights the record can tell from the input's own (bool per row of ``plays``).

    An operator whose output is an affine function of the input on the record
    (it never moved, or it followed u - r or u + r at every sample: the input
    only ever pushed it, never within its band) adds nothing a gain and an
    offset do not: its weight would only trade with b. Every other one is
    told apart: one pushed both up and down, and one pushed one way only that
    held still while the input moved (a ratchet: a staircase that turns back
    less than 2 r holds it for a while). ``before``: the states before the
    record (``initial_plays``); ``u``: the record's input. A row at a time:
    every row's steps at once would be two more copies of the plays.
    """
    before = np.broadcast_to(np.asarray(before, dtype=float), (plays.shape[0],))
    affine = _affine_test(u)
    out = np.empty(plays.shape[0], dtype=bool)
    for i, row in enumerate(plays):
        steps = np.diff(row, prepend=before[i])
        up, down = bool(np.any(steps > 0.0)), bool(np.any(steps < 0.0))
        out[i] = (up and down) or ((up or down) and not affine(row))
    return out


def _affine_test(u: np.ndarray) -> Callable[[np.ndarray], bool]:
    """Whether a row is c0 + c1 u on the record, to ``AFFINE_RTOL`` of the input's range (a least squares on
    [1, u]; a constant input: whether the row is constant)."""
    u = np.asarray(u, dtype=float)
    span = max(float(np.ptp(u)), float(np.max(np.abs(u), initial=0.0)), 1e-300)
    basis = np.vstack([np.ones_like(u), u - float(np.mean(u))]) if np.ptp(u) > 0 else np.ones((1, u.size))
    q, _ = np.linalg.qr(basis.T)
    return lambda row: float(np.max(np.abs(row - q @ (q.T @ row)), initial=0.0)) <= AFFINE_RTOL * span


def partial_slopes(r, w) -> np.ndarray:
    """The loop's branch slopes S_0 = 1, S_j = 1 + w_1 + ... + w_j, thresholds ascending (``SLOPE_FLOOR``)."""
    r = np.atleast_1d(np.asarray(r, dtype=float))
    w = np.atleast_1d(np.asarray(w, dtype=float))[np.argsort(r, kind="stable")]
    return 1.0 + np.concatenate(([0.0], np.cumsum(w)))


def flattest_branch(r, w) -> float:
    """The flattest branch's slope over the mean branch slope (``partial_slopes``): >= SLOPE_FLOOR for a fitted
    loop, <= 0 for one that cannot be inverted."""
    s = partial_slopes(r, w)
    return float(s.min() / s.mean())


def loop_width(r, w, u_range: float) -> float:
    """Widest vertical opening (input units, relative to the large-signal slope) of the PI loop.

    A play operator of threshold r cycled over a range >= 2 r opens a loop of
    height 2 r; over a range A < 2 r it never moves. The PI loop over the
    measured input range is therefore ``sum_i w_i 2 min(r_i, A/2) / (1 + sum_i w_i)``.
    """
    r = np.atleast_1d(np.asarray(r, dtype=float))
    w = np.atleast_1d(np.asarray(w, dtype=float))
    slope = 1.0 + float(w.sum())
    if slope == 0.0:
        return float("nan")
    return float(np.sum(w * 2.0 * np.minimum(r, u_range / 2.0)) / slope)


def pi_inverse(r: np.ndarray, w: np.ndarray, w0: float = 1.0) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Analytic inverse of ``v = w0 u + sum_i w_i play_{r_i}[u]`` (thresholds r_i > 0, any order).

    With thresholds sorted and the partial slopes ``S_j = w0 + w_1 + .. + w_j``
    all positive (a monotone loop), the inverse is again a PI operator:
    ``u = v/w0 + sum_j wh_j play_{rh_j}[v]``, ``rh_j = w0 r_j + sum_{i<j} w_i (r_j - r_i)``,
    ``wh_j = -w_j / (S_j S_(j-1))``. Returns (rh, wh, 1/w0, order): sorted by threshold.
    """
    order = np.argsort(r, kind="stable")
    r = np.asarray(r, dtype=float)[order]
    w = np.asarray(w, dtype=float)[order]
    if np.any(r <= 0):
        raise ModelError("hysteresis thresholds must be > 0 (the identity term is the w0 = 1 path)")
    S = w0 + np.cumsum(w)
    S_prev = np.concatenate(([w0], S[:-1]))
    if w0 <= 0 or np.any(S <= 0):
        j = int(np.argmax(S <= 0)) if w0 > 0 else -1
        raise ModelError("hysteresis cannot be inverted: the loop is not monotone (partial slope "
                         f"{S[j] if j >= 0 else w0:.3g} <= 0{'' if j < 0 else f' at threshold {r[j]:.4g}'})")
    rh = w0 * r + np.array([np.sum(w[:j] * (r[j] - r[:j])) for j in range(r.size)])
    wh = -w / (S * S_prev)
    return rh, wh, 1.0 / w0, order


def inverse_params(params: dict) -> dict:
    """The inverse loop of a hysteresis effect as a hysteresis parameter dict: ``hysteresis_input(v, **inverse)``
    is the input u that makes ``hysteresis_input(u, **params)`` equal v (same initial state).

    The effect's identity term has weight 1, so the inverse (``pi_inverse``) is
    again ``u = v + sum_j wh_j play_{rh_j}[v]``. ModelError if a partial slope is
    not positive (a fitted loop's are, ``SLOPE_FLOOR``).
    """
    r = np.atleast_1d(np.asarray(params.get("r", []), dtype=float))
    w = np.atleast_1d(np.asarray(params.get("w", []), dtype=float))
    if r.shape != w.shape:
        raise ModelError(f"hysteresis needs matching r and w lists (got {r.size} and {w.size})")
    initial = params.get("initial", "centred")
    initial_plays(0.0, r, initial)                 # ModelError naming the states if unknown
    r, w = r[w != 0.0], w[w != 0.0]               # an operator of weight 0 (pinned) adds nothing to either loop
    if r.size == 0:
        return {"r": [], "w": [], "initial": initial}
    rh, wh, _, _ = pi_inverse(r, w)
    return {"r": rh.tolist(), "w": wh.tolist(), "initial": initial}


def invert_hysteresis(v: np.ndarray, params: dict) -> np.ndarray:
    """The input u whose hysteresis output (``hysteresis_input(u, **params)``) is v: the analytic PI inverse."""
    inv = inverse_params(params)
    return hysteresis_input(v, inv["r"], inv["w"], inv["initial"])


def last_direction(u: np.ndarray) -> np.ndarray:
    """+1 where the last input change went up, -1 where down, 0 before the first change."""
    du = np.diff(np.asarray(u, dtype=float), prepend=u[0])
    sign = np.sign(du)
    idx = np.flatnonzero(sign)
    out = np.zeros(len(u))
    if idx.size:
        fill = np.zeros(len(u), dtype=int)
        fill[idx] = idx
        np.maximum.accumulate(fill, out=fill)
        out = np.where(np.arange(len(u)) >= idx[0], sign[fill], 0.0)
    return out


def weight_names(count: int) -> list[str]:
    """Names of the reported solution's weight coefficients (``PlayWeights``), thresholds ascending."""
    return [f"w{i}" for i in range(1, count + 1)]


def solve_pi_weights(a: np.ndarray, wy: np.ndarray, gain: int, cols: np.ndarray, opened: np.ndarray,
                     gain_estimate: float, noise_var: float) -> tuple[np.ndarray, dict]:
    """Least squares of ``a x ~ wy`` with the PI loop's weights constrained and regularised; (x, what it found).

    ``a``: the (weighted) design, one column per coefficient; ``gain``: the
    column of the base path's response to u (coefficient b); ``cols``: the
    columns of its responses to the plays, thresholds ascending (coefficients
    b w_i); ``opened``: the operators the record opens (the others' weights are
    0). Every other column is free.

    Constraints: every branch slope q_j = b S_j (j = 0 .. K, ``partial_slopes``;
    a pinned operator's branch repeats the one before) at least ``SLOPE_FLOOR``
    times their mean, with the sign s of b: ``z = s (q - SLOPE_FLOOR mean(q)) >= 0``.
    With z as the variables (q = s (I + c 1 n^T) z, n: how many branches each
    opened operator's slope holds, c = SLOPE_FLOOR / ((K + 1)(1 - SLOPE_FLOOR)))
    these are bounds: a bounded least squares, run only when the plain solution
    breaks one, for either sign s (the better is kept: b's sign is the
    small-signal slope's, which the search's ``gain_estimate`` may not have when
    the loop dominates). Prior: ``w_i ~ N(0, WEIGHT_SCALE^2)``, rows
    ``sqrt(noise_var) / (WEIGHT_SCALE |b|) (b w_i)`` appended, |b| from
    ``gain_estimate`` and then from the solution (``PRIOR_ITERATIONS``), the
    noise variance at least ``PRIOR_FLOOR^2`` times the mean square of ``wy``.
    Also returns ``determined``: the effective
    number of weight combinations the data determine rather than the prior
    (the trace of the resolution matrix, at most the number of opened
    operators), and ``penalty``: the prior rows' sum of squares at the
    solution (with the residual's, the objective minimised).
    """
    n, p = a.shape
    noise_var = max(noise_var, float(PRIOR_FLOOR ** 2 * np.mean(np.square(wy))))
    a, wy = _compressed(a, wy)
    cols = np.asarray(cols, dtype=int)
    live = cols[np.asarray(opened, dtype=bool)]
    others = np.setdiff1d(np.arange(p), np.concatenate(([gain], cols)))
    M = _slope_basis(np.asarray(opened, dtype=bool))
    k = M.shape[0]
    slopes = a[:, np.concatenate(([gain], live))] @ M
    scale_b = abs(gain_estimate) if gain_estimate != 0.0 and np.isfinite(gain_estimate) else 1.0
    for _ in range(PRIOR_ITERATIONS):
        prior = np.sqrt(noise_var) / (WEIGHT_SCALE * scale_b) * M[1:]
        z, s = _bounded_solve(np.hstack([slopes, a[:, others]]), prior, wy, k)
        bw = s * (M @ z[:k])
        if bw[0] == 0.0 or abs(abs(bw[0]) - scale_b) <= PRIOR_RTOL * scale_b:
            break
        scale_b = abs(bw[0])
    x = np.zeros(p)
    x[gain] = bw[0]
    x[live] = bw[1:]
    x[others] = z[k:]
    penalty = prior @ z[:k]
    std = np.full(len(cols), np.nan)
    std[np.asarray(opened, dtype=bool)] = _weight_std(a, gain, live, others, x, noise_var,
                                                      noise_var / (WEIGHT_SCALE * scale_b) ** 2)
    return x, {"determined": _determined(a, gain, live, others, noise_var / (WEIGHT_SCALE * scale_b) ** 2),
               "penalty": float(penalty @ penalty), "w_std": std}


def _weight_std(a: np.ndarray, gain: int, live: np.ndarray, others: np.ndarray, x: np.ndarray, noise_var: float,
                prior_var_ratio: float) -> np.ndarray:
    """1-sigma of the opened operators' weights w_i = (b w_i) / b at the solution ``x``: the covariance
    noise_var (A^T A + L)^-1 of b, the b w_i and the free coefficients (L: the prior on the b w_i), then the
    delta method. The slope bounds are left out (the linearised, unconstrained spread): where a bound holds a
    weight, its spread is smaller than this."""
    if live.size == 0:
        return np.empty(0)
    idx = np.concatenate(([gain], live, others)).astype(int)
    block = a[:, idx]
    norms = np.linalg.norm(block, axis=0)
    norms[norms == 0.0] = 1.0
    info = (block / norms).T @ (block / norms)
    info[1:live.size + 1, 1:live.size + 1] += np.diag(prior_var_ratio / norms[1:live.size + 1] ** 2)
    try:
        cov = np.linalg.inv(info) / np.outer(norms, norms) * noise_var
    except np.linalg.LinAlgError:
        return np.full(live.size, np.nan)
    b = x[gain]
    w = x[live] / b
    j = np.arange(1, live.size + 1)
    var = (cov[j, j] - 2.0 * w * cov[j, 0] + w * w * cov[0, 0]) / (b * b)
    return np.sqrt(np.where(var >= 0.0, var, np.nan))


def _compressed(a: np.ndarray, wy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, Q^T wy) of ``a = Q R`` (economic) where ``a`` has many more rows than columns, else (a, wy).

    Every least squares in ``a`` below (the bounded solve, the resolution matrix) takes linear combinations of
    its columns, and those see the data only through R and Q^T wy (Q orthonormal): the same solutions and
    resolution to rounding, from p x p matrices: on a long record the n x p design's copies (each 10 MB for
    25 columns of 50,000 samples, seven of them at once) would be a diagnosis' peak memory.
    """
    n, p = a.shape
    if n <= COMPRESS_ROWS * p:
        return a, wy
    from scipy.linalg import qr              # scipy on first use: importing the effects stays light
    aug = np.empty((n, p + 1), order="F")
    aug[:, :p] = a
    aug[:, p] = wy
    r = qr(aug, mode="raw", overwrite_a=True, check_finite=False)[1]
    return r[:p, :p], r[:p, p]


def _slope_basis(opened: np.ndarray) -> np.ndarray:
    """M with [b, b w_opened] = s M z (``solve_pi_weights``): z = s (q - SLOPE_FLOOR mean(q)) for the branch slopes
    q (b = q_0, b w_j = q_j - q_(j-1)); q = s (I + c 1 n^T) z, n the branches each distinct slope holds."""
    k = int(opened.sum()) + 1
    first = np.flatnonzero(opened)
    counts = np.diff(np.concatenate(([0], first + 1, [opened.size + 1])))
    c = SLOPE_FLOOR / ((opened.size + 1) * (1.0 - SLOPE_FLOOR))
    return (np.eye(k) - np.eye(k, k=-1)) @ (np.eye(k) + c * np.outer(np.ones(k), counts))


def _bounded_solve(design: np.ndarray, prior: np.ndarray, wy: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    """(z, s): least squares of ``s design[:, :k] z[:k] + design[:, k:] z[k:] ~ wy`` plus the rows ``prior`` on
    z[:k], with z[:k] >= 0, for the better sign s (bounded least squares only where the plain solution breaks a
    bound). One QR for both signs: the other sign negates R's first k columns."""
    from scipy.linalg import qr              # scipy on first use: importing the effects stays light
    from scipy.optimize import lsq_linear
    stacked = np.vstack([design, np.hstack([prior, np.zeros((prior.shape[0], design.shape[1] - k))])])
    norms = np.linalg.norm(stacked, axis=0)
    norms[norms == 0.0] = 1.0
    q, rr = qr(stacked / norms, mode="economic", check_finite=False)
    rhs = q[:wy.size].T @ wy
    best = None
    for s in (1.0, -1.0):
        r_s = rr.copy()
        r_s[:, :k] *= s
        z = np.linalg.lstsq(r_s, rhs, rcond=None)[0]
        if np.any(z[:k] < 0.0):
            lo = np.full(z.size, -np.inf)
            lo[:k] = 0.0
            z = lsq_linear(r_s, rhs, bounds=(lo, np.inf), method="bvls", tol=1e-12).x
            z[:k] = np.maximum(z[:k], 0.0)
        miss = r_s @ z - rhs
        if best is None or miss @ miss < best[0]:
            best = (float(miss @ miss), z / norms, s)
    return best[1], best[2]


def _determined(a: np.ndarray, gain: int, live: np.ndarray, others: np.ndarray, prior_var_ratio: float) -> float:
    """Trace of the weights' resolution matrix (F + L)^-1 F: F the data's information on the weights with b and
    the free coefficients profiled out, L the prior's; ``prior_var_ratio`` = noise variance / prior variance."""
    from scipy.linalg import qr
    if live.size == 0:
        return 0.0
    rest = a[:, np.concatenate(([gain], others)).astype(int)]
    block = np.hstack([rest, a[:, live]])
    norms = np.linalg.norm(block, axis=0)
    norms[norms == 0.0] = 1.0
    rr = qr(block / norms, mode="r", check_finite=False)[0]
    k = rest.shape[1]
    rw = rr[k:, k:] * norms[k:]                   # the weights' part once the rest is projected out
    info = np.linalg.eigvalsh(rw.T @ rw) / max(prior_var_ratio, 1e-300)
    info = np.maximum(info, 0.0)
    return float(np.sum(info / (1.0 + info)))


class PlayWeights:
    """The reported solution of a hysteresis fit's weights (``InputEffect.reported_solution``): the record's plays.

    ``rows``: the plays themselves (the search fits their leading directions);
    ``solve``: ``solve_pi_weights`` with the operators the record never opens
    pinned at 0. Built per record and initial state. The plays are run again
    when asked for rather than kept: the caller copies them into its own rows
    once, and kept they would be 10 MB beside those at 50,000 samples.
    """

    def __init__(self, data, variant: str | None) -> None:
        self.initial = variant or "centred"
        self.r = Hysteresis.thresholds(data)
        self.opened = opened_operators(self.rows(data.u), initial_plays(data.u[0], self.r, self.initial), data.u)
        self.names = weight_names(self.r.size)

    def rows(self, u: np.ndarray, before: bool = False) -> np.ndarray:
        """The plays for input u (the record's own, or ``before``: all resting on the input before the record)."""
        if before:
            return np.repeat(np.asarray(u, dtype=float)[None, :], self.r.size, axis=0)
        return play_operators(u, self.r, initial=initial_plays(u[0], self.r, self.initial))

    def solve(self, a: np.ndarray, wy: np.ndarray, gain: int, cols: np.ndarray, gain_estimate: float,
              noise_var: float) -> tuple[np.ndarray, dict]:
        """``solve_pi_weights`` on this record's opened operators; the dict adds ``opened`` and ``r_opened``."""
        x, found = solve_pi_weights(a, wy, gain, cols, self.opened, gain_estimate, noise_var)
        found["opened"] = int(self.opened.sum())
        found["r_opened"] = float(self.r[self.opened].max()) if self.opened.any() else 0.0
        return x, found


class _PlayCompensator(InputCompensator):
    """The PI operator run sample by sample (its state starts at the first input, as in the fit)."""

    def __init__(self, params: dict) -> None:
        self.r = np.asarray(params["r"], dtype=float)
        self.w = np.asarray(params["w"], dtype=float)
        self.initial = INITIAL_STATES[params.get("initial", "centred")]
        self.p: np.ndarray | None = None

    def input(self, v: float) -> float:
        if self.p is None:
            self.p = v + self.initial * self.r
        self.p = np.maximum(v - self.r, np.minimum(v + self.r, self.p))
        return v + float(self.w @ self.p)


class Hysteresis(InputEffect):
    name = "hysteresis"
    term = "Prandtl-Ishlinskii play operators on the input: v = u + sum_i w_i play_{r_i}[u]"
    variants = tuple(INITIAL_STATES)
    variant_key = "initial"

    def transform_input(self, v: np.ndarray, params: dict) -> np.ndarray:
        return hysteresis_input(v, params.get("r", []), params.get("w", []), params.get("initial", "centred"))

    def transform_before(self, v_pre: float, params: dict) -> float:
        """The operators rest on the input before the record: v = (1 + sum_i w_i) u_pre (as the fit's rows)."""
        return float(v_pre) * (1.0 + float(np.sum(params.get("w", []))))

    @staticmethod
    def thresholds(data) -> np.ndarray:
        """The fit's play-operator thresholds for this record (input units)."""
        return np.asarray(HYSTERESIS_THRESHOLDS) * data.u_range

    def _plays(self, data, u: np.ndarray, variant: str | None) -> np.ndarray:
        r = self.thresholds(data)
        return play_operators(u, r, initial=initial_plays(u[0], r, variant or "centred"))

    def components(self, data, variant: str | None, plays: np.ndarray | None = None) -> np.ndarray:
        """(thresholds, HYSTERESIS_COMPONENTS): the leading left singular vectors of the record's play outputs
        (``plays``, when the caller has them already); a direction below ``COMPONENT_RCOND`` is a zero column.

        The fitted sum ``w @ plays = c @ (U.T @ plays)`` with ``w = U c``: the
        columns are the plays' strongest directions. Signs fixed (largest
        entry positive) so that a record gives the same columns every time.
        """
        if plays is None:
            plays = self._plays(data, data.u, variant)
        vals, vecs = np.linalg.eigh(plays @ plays.T)
        order = np.argsort(vals)[::-1][:HYSTERESIS_COMPONENTS]
        top = vecs[:, order] * np.sign(vecs[np.abs(vecs[:, order]).argmax(axis=0), order])
        top[:, vals[order] <= COMPONENT_RCOND ** 2 * max(vals[order[0]], 0.0)] = 0.0
        return top

    def design_rows(self, data, u: np.ndarray, variant: str | None, before: bool = False) -> np.ndarray:
        own = self._plays(data, data.u, variant)
        U = self.components(data, variant, own)
        if before:  # the operators rest on the input before the record
            return U.sum(axis=0)[:, None] * u[None, :]
        return U.T @ (own if u is data.u else self._plays(data, u, variant))

    def column_names(self) -> list[str]:
        return [f"pi{i}" for i in range(1, HYSTERESIS_COMPONENTS + 1)]

    def reported_solution(self, data, variant: str | None) -> PlayWeights:
        return PlayWeights(data, variant)

    def fitted_params(self, fit: FitView) -> dict:
        """Thresholds r, weights w and the initial state (an ``effects["hysteresis"]`` dict), with what the
        record says about them: ``w_std`` (each weight's 1-sigma, ``_weight_std``; None for an operator the
        record never opens), ``opened`` (how many of the smallest thresholds the record opens; the others'
        weights are 0), ``r_opened`` (the largest of them), ``determined`` (how many weight combinations the
        data determine rather than the prior), ``flattest_branch`` (the flattest branch's slope over the mean
        branch slope, >= SLOPE_FLOOR), the loop width."""
        data = fit.data
        r = self.thresholds(data)
        w = np.array([fit.coef[name] for name in weight_names(r.size)]) / fit.gain
        width = loop_width(r, w, data.u_range)
        found = fit.solution.get(self.name, {})
        std = found.get("w_std")
        std = None if std is None else [float(v) if np.isfinite(v) else None for v in std]
        return {"r": r.tolist(), "w": w.tolist(), "w_std": std, "loop_width": width,
                "loop_width_rel": width / data.u_range if data.u_range else float("nan"),
                "initial": fit.variant or "centred", "opened": found.get("opened"), "r_opened": found.get("r_opened"),
                "determined": found.get("determined"), "flattest_branch": flattest_branch(r, w)}

    def inverse(self, params: dict) -> dict:
        """The analytic inverse loop as a hysteresis parameter dict (``inverse_params``)."""
        return inverse_params(params)

    def compensator(self, dt: float, params: dict) -> InputCompensator:
        return _PlayCompensator(params)

    def applicable(self, data) -> str | None:
        d = last_direction(data.u)
        flips = int(np.sum(np.abs(np.diff(d[d != 0])) > 0))
        return f"needs input reversals (found {flips})" if flips < 2 else None

    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        reg = where.get("input_regimes", {})
        return (f"residual depends on the direction of the last input change (split {reg.get('direction_split', 0):.2f} "
                f"x RMS); loop width {params.get('loop_width', float('nan')):.3g} input units "
                f"({100 * params.get('loop_width_rel', float('nan')):.2g} % of the range)")

    def example_params(self, model, t, u, y_base, rng) -> dict:
        u_range = float(np.ptp(u))
        r = np.linspace(0.0, 0.5, 31)[1:] * u_range
        w = np.exp(-r / (rng.uniform(0.08, 0.25) * u_range))
        w *= rng.uniform(0.2, 0.5) / w.sum()  # loop ~ 5-20 % of the range
        return {"r": r.tolist(), "w": w.tolist()}
