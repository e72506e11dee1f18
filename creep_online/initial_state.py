"""The free response of a record taken in operation: basis functions for an unknown initial state.

A record cut out of longer operation starts with the plant moving: the
resonance carries a state, and the fractional integrator remembers the whole
past input. By linearity the output is the response to the in-record input
changes (measured from the first sample's level) plus the free response of the
past, which is a superposition of

* steps before the record: S(t + T) for unknown T > 0, with S the exact
  unit-step response. S(t + T) varies smoothly with log T, so a geometric grid
  of T (ratio 3, from one sample to a few record lengths) spans it; steps
  further back are close to a constant plus a slow ramp, which the longest
  columns and the constant carry;
* the resonance's own homogeneous solutions (two exponential modes), for the
  part of a recent step's ringing the grid misses.

All are linear in their unknown weights and are projected out of the fit
(variable projection), so the nonlinear search stays (alpha, a1, a2).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .discretize import resonance_poles

#: Ratio of the geometric grid of past step instants.
GRID_RATIO = 3.0
#: The longest past step instant, in record lengths.
LONGEST_PAST = 3.0


def past_offsets(n: int) -> np.ndarray:
    """Sample offsets m of the past steps (T = m h): 0, 1, 3, 9, ... up to LONGEST_PAST n."""
    top = max(int(LONGEST_PAST * n), 2)
    m = np.unique(np.round(GRID_RATIO ** np.arange(0, np.log(top) / np.log(GRID_RATIO) + 1)).astype(np.int64))
    return np.concatenate(([0], m[m <= top]))


def step_columns(step_long: np.ndarray, n: int, offsets: np.ndarray) -> np.ndarray:
    """Columns S(t + m h) on the record's n samples from one long step response (length >= n + max m)."""
    return np.column_stack([step_long[m:m + n] for m in offsets])


def homogeneous_columns(a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """The two free modes of 1 + a1 s + a2 s^2 on n samples (Re/Im of e^(p t) for a complex pair).

    Modes that have decayed below 1e-300 within a sample are returned as zeros;
    the caller drops empty columns.
    """
    slow, fast = resonance_poles(a1, a2)
    t = np.arange(n) * h
    if abs(slow.imag) > 0.0:
        e = np.exp(np.clip(slow.real * t, -700.0, 0.0)) * np.exp(1j * slow.imag * t)
        return np.column_stack((e.real, e.imag))
    return np.column_stack((np.exp(np.clip(slow.real * t, -700.0, 0.0)),
                            np.exp(np.clip(fast.real * t, -700.0, 0.0))))


def free_columns(step_long: np.ndarray, a1: float, a2: float, h: float, n: int) -> np.ndarray:
    """All free-response columns (steps in the past and the resonance modes), without the constant."""
    return np.hstack((step_columns(step_long, n, past_offsets(n)), homogeneous_columns(a1, a2, h, n)))


def creep_columns(alpha: float, h: float, n: int) -> np.ndarray:
    """The fractional integrator's part alone, (t + T)^alpha, for starting grids that skip the resonance."""
    t = np.arange(n) * h
    m = past_offsets(n)
    return np.column_stack([(t + k * h) ** alpha for k in m[1:]])


@dataclass(frozen=True)
class FreeResponse:
    """The fitted free response of the state a record started in, as a function of time since its first sample.

    ``sum_k past_weights[k] S(tau + past_s[k]) + mode_weights . modes(tau)``: the weighted columns of
    ``free_columns`` (S the unit-gain step response of (alpha, a1, a2), the modes those of the
    resonance), so that a result can give its fitted output again for any time vector. On the grid it
    was fitted on (step ``h``) the columns are computed exactly as the fit computed them; elsewhere
    the step response is evaluated at arbitrary times.
    """

    alpha: float
    a1: float
    a2: float
    h: float
    past_s: tuple[float, ...]
    past_weights: tuple[float, ...]
    mode_weights: tuple[float, float]

    @classmethod
    def from_weights(cls, alpha: float, a1: float, a2: float, h: float, n: int, weights: np.ndarray) -> "FreeResponse":
        """From the weights of ``free_columns(.., n)`` (past steps first, then the two modes) fitted on n samples."""
        offsets = past_offsets(n)
        weights = np.asarray(weights, dtype=float)
        return cls(alpha, a1, a2, h, tuple(float(m * h) for m in offsets),
                   tuple(float(w) for w in weights[:offsets.size]), (float(weights[-2]), float(weights[-1])))

    def scaled(self, factor: float) -> "FreeResponse":
        """The same response times ``factor`` (an output rescaled)."""
        return FreeResponse(self.alpha, self.a1, self.a2, self.h, self.past_s,
                            tuple(w * factor for w in self.past_weights),
                            (self.mode_weights[0] * factor, self.mode_weights[1] * factor))

    def __call__(self, tau: np.ndarray) -> np.ndarray:
        """The free response at times ``tau`` (s) since the record's first sample."""
        tau = np.asarray(tau, dtype=float)
        offsets = np.rint(np.asarray(self.past_s) / self.h).astype(np.int64)
        k = np.rint(tau / self.h)
        if tau.size and np.allclose(tau, k * self.h, rtol=0.0, atol=1e-9 * self.h) and k.min() >= 0:
            from .discretize import step_response_grid
            idx = k.astype(np.int64)
            step = step_response_grid(self.alpha, self.a1, self.a2, self.h, int(idx.max() + offsets.max()) + 1)
            cols = np.column_stack([step[idx + m] for m in offsets])
            tau = idx * self.h
        else:
            from .effects.responses import base_step_at
            cols = np.column_stack([base_step_at(self.alpha, self.a1, self.a2, tau + s) for s in self.past_s])
        return cols @ np.asarray(self.past_weights) + modes_at(self.a1, self.a2, tau) @ np.asarray(self.mode_weights)

    def to_dict(self) -> dict:
        """JSON-ready: the past step instants (s before the first sample), their weights, the modes' weights."""
        return {"past_s": list(self.past_s), "past_weights": list(self.past_weights),
                "mode_weights": list(self.mode_weights), "h": self.h}


def modes_at(a1: float, a2: float, tau: np.ndarray) -> np.ndarray:
    """``homogeneous_columns`` at arbitrary times tau (s), shape (len(tau), 2)."""
    slow, fast = resonance_poles(a1, a2)
    tau = np.asarray(tau, dtype=float)
    if abs(slow.imag) > 0.0:
        e = np.exp(np.clip(slow.real * tau, -700.0, 700.0)) * np.exp(1j * slow.imag * tau)
        return np.column_stack((e.real, e.imag))
    return np.column_stack((np.exp(np.clip(slow.real * tau, -700.0, 700.0)),
                            np.exp(np.clip(fast.real * tau, -700.0, 700.0))))
