"""``hysteresis``: rate-independent memory of input reversals, a Prandtl-Ishlinskii model on the input.

``v = u + sum_i w_i play_{r_i}[u]``. The fit uses ``HYSTERESIS_THRESHOLDS``
(fractions of the input range), their weights fitted in the plays' leading
singular directions (``HYSTERESIS_COMPONENTS`` linear columns), and chooses the
operators' state before the record (``INITIAL_STATES``) by a short polish of
each. Signature: the residual depends on the direction of the last input change.
"""
from __future__ import annotations

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
#: The fit's linear columns: the leading singular directions of the record's own 24 play outputs
#: (``Hysteresis.components``), not the plays themselves: nearly collinear, and each column is filtered
#: through the plant at every evaluation (24 doubled diagnose's time on a 30,000-sample hysteresis record).
#: On the 18 records above, 8 components already give the 24 plays' residual to four decimals; 12 keep a margin
#: (and the parameters the BIC counts near the old 10).
HYSTERESIS_COMPONENTS = 12
#: A component whose eigenvalue (its column's squared norm) is below this fraction of the largest is left
#: out (its column set to zero, its weight 0): a staircase of a few levels moves only a few distinct plays,
#: the rest of the directions are rounding noise, and a weight fitted to noise (1e13 on one record) makes
#: ``w = U c`` cancel so badly that the saved weights no longer give the fitted output (relative 1e-2).
#: Kept directions down to 1e-12 (singular value 1e-6) lose at most ~1e-10 of the output that way.
COMPONENT_FLOOR = 1e-12
#: Play-operator states before the record, as multiples of the threshold added to u[0]: centred on u[0],
#: or as left by a rise to u[0] (p = u[0] - r) or a fall to u[0] (p = u[0] + r).
INITIAL_STATES = {"centred": 0.0, "ascending": -1.0, "descending": 1.0}


def play_operators(u: np.ndarray, r: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
    """Play (backlash) operator outputs, one row per threshold r_i >= 0.

    ``p[n] = max(u[n] - r, min(u[n] + r, p[n-1]))`` with ``p[-1] = u[0]``
    (the operators start centred on the first input value unless ``initial``
    is given). Work is done only where the input changes.
    """
    u = np.asarray(u, dtype=float)
    r = np.atleast_1d(np.asarray(r, dtype=float))
    out = np.empty((r.size, u.size))
    p = np.full(r.size, u[0]) if initial is None else np.asarray(initial, dtype=float).copy()
    change = np.flatnonzero(np.diff(u, prepend=u[0] - 1.0) != 0.0)
    stops = np.append(change[1:], u.size)
    for i0, i1 in zip(change, stops):
        p = np.maximum(u[i0] - r, np.minimum(u[i0] + r, p))
        out[:, i0:i1] = p[:, None]
    return out


def hysteresis_input(u: np.ndarray, r, w, initial: str = "centred") -> np.ndarray:
    """v = u + sum_i w_i play_{r_i}[u] (Prandtl-Ishlinskii).

    ``initial``: the operators' state before the record -- "centred" on u[0],
    "ascending" (the input last rose to u[0]: p = u[0] - r) or "descending"
    (it last fell to u[0]: p = u[0] + r).
    """
    w = np.atleast_1d(np.asarray(w, dtype=float))
    r = np.atleast_1d(np.asarray(r, dtype=float))
    u = np.asarray(u, dtype=float)
    if initial not in INITIAL_STATES:
        raise ModelError(f"hysteresis initial must be one of {', '.join(INITIAL_STATES)}, got {initial!r}")
    return u + w @ play_operators(u, r, initial=u[0] + INITIAL_STATES[initial] * r)


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
        """At rest before the record every operator rests on that input: ``(1 + sum_i w_i) u_pre``."""
        return float(v_pre * (1.0 + np.sum(np.asarray(params.get("w", []), dtype=float))))

    @staticmethod
    def thresholds(data) -> np.ndarray:
        """The fit's play-operator thresholds for this record (input units)."""
        return np.asarray(HYSTERESIS_THRESHOLDS) * data.u_range

    def _plays(self, data, u: np.ndarray, variant: str | None) -> np.ndarray:
        r = self.thresholds(data)
        return play_operators(u, r, initial=u[0] + INITIAL_STATES[variant or "centred"] * r)

    def components(self, data, variant: str | None, plays: np.ndarray | None = None) -> np.ndarray:
        """(thresholds, HYSTERESIS_COMPONENTS): the leading left singular vectors of the record's play outputs
        (``plays``, when the caller has them already).

        The fitted sum ``w @ plays = c @ (U.T @ plays)`` with ``w = U c``: the
        columns are the plays' strongest directions, and the weights of the
        thresholds come back as ``U c``. Signs fixed (largest entry positive)
        so that a record gives the same columns every time; directions below
        ``COMPONENT_FLOOR`` are zero columns.
        """
        if plays is None:
            plays = self._plays(data, data.u, variant)
        vals, vecs = np.linalg.eigh(plays @ plays.T)
        order = np.argsort(vals)[::-1][:HYSTERESIS_COMPONENTS]
        top = vecs[:, order] * np.sign(vecs[np.abs(vecs[:, order]).argmax(axis=0), order])
        top[:, vals[order] < COMPONENT_FLOOR * max(vals[order[0]], 0.0)] = 0.0
        return top

    def design_rows(self, data, u: np.ndarray, variant: str | None, before: bool = False) -> np.ndarray:
        own = self._plays(data, data.u, variant)
        U = self.components(data, variant, own)
        if before:  # the operators rest on the input before the record
            return U.sum(axis=0)[:, None] * u[None, :]
        return U.T @ (own if u is data.u else self._plays(data, u, variant))

    def column_names(self) -> list[str]:
        return [f"pi{i}" for i in range(1, HYSTERESIS_COMPONENTS + 1)]

    def fitted_params(self, fit: FitView) -> dict:
        data = fit.data
        c = np.array([fit.coef[name] for name in self.column_names()]) / fit.gain
        w = self.components(data, fit.variant) @ c
        r = self.thresholds(data)
        width = loop_width(r, w, data.u_range)
        return {"r": r.tolist(), "w": w.tolist(), "loop_width": width,
                "loop_width_rel": width / data.u_range if data.u_range else float("nan"),
                "initial": fit.variant or "centred"}

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
