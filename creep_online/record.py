"""A measured (or simulated) record: time, input and output samples, plus where they came from."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import DataError

#: Fewest samples any identification is attempted on.
MIN_SAMPLES = 20


@dataclass
class Record:
    """Samples t (s), u (input units), y (output units) of one experiment; ``units``: the units of t, u and y
    where the file named them (e.g. {"u": "V", "y": "um"})."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    source: str = "<array>"
    units: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        self.t = np.ascontiguousarray(self.t, dtype=float)
        self.u = np.ascontiguousarray(self.u, dtype=float)
        self.y = np.ascontiguousarray(self.y, dtype=float)
        if not (self.t.shape == self.u.shape == self.y.shape) or self.t.ndim != 1:
            raise DataError(f"{self.source}: t, u and y must be 1-D and of equal length "
                            f"(got {self.t.shape}, {self.u.shape}, {self.y.shape})")

    def __len__(self) -> int:
        return self.t.size

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    @property
    def is_uniform(self) -> bool:
        """True when the step varies by less than UNIFORM_RTOL of the mean step."""
        from .simulate import uniform_step  # local: simulate imports record's neighbours
        try:
            uniform_step(self.t)
        except DataError:
            return False
        return True

    @property
    def h(self) -> float:
        """Mean sampling step (s)."""
        return self.duration / max(self.t.size - 1, 1)

    def validate(self, min_samples: int = MIN_SAMPLES) -> "Record":
        """Check what identification needs; raise DataError naming the source and the problem."""
        name = self.source
        if self.t.size == 0:
            raise DataError(f"{name}: no data rows")
        if self.t.size < min_samples:
            raise DataError(f"{name}: too few samples ({self.t.size}; need at least {min_samples})")
        for col in ("t", "u", "y"):
            bad = ~np.isfinite(getattr(self, col))
            if bad.any():
                i = int(np.argmax(bad))
                raise DataError(f"{name}: column {col} has {int(bad.sum())} NaN/inf value(s), first at data row {i + 1}")
        dt = np.diff(self.t)
        if np.any(dt <= 0):
            i = int(np.argmax(dt <= 0))
            raise DataError(f"{name}: time is not strictly increasing at data row {i + 2} "
                            f"(t={float(self.t[i + 1])!r} after t={float(self.t[i])!r})")
        if not np.any(self.u):
            # zero initial state is assumed: a constant non-zero u is a step at t[0]
            raise DataError(f"{name}: no excitation (input u is zero throughout)")
        return self

    def slice(self, start: int, stop: int) -> "Record":
        """Samples start..stop-1 as a new record (views, not copies)."""
        return Record(self.t[start:stop], self.u[start:stop], self.y[start:stop], self.source, self.units)


#: Time steps and spans the model can be computed on (a2 ~ t^2 must stay far from overflow).
MIN_STEP_S, MAX_SPAN_S = 1e-12, 1e12
#: Amplitudes of u and y the fits compute with directly (squares and sums stay finite).
SAFE_AMPLITUDE = (1e-100, 1e100)


def check_time_and_output(t: np.ndarray, y: np.ndarray, source: str) -> None:
    """DataError when the time axis is out of the computable range or the output is constant."""
    span = float(t[-1] - t[0]) if t.size else 0.0
    step = float(np.min(np.diff(t))) if t.size > 1 else 0.0
    if t.size > 1 and not (step >= MIN_STEP_S and math.isfinite(span) and span <= MAX_SPAN_S):
        raise DataError(f"{source}: time axis out of range (step {step:.3g} s, span {span:.3g} s; supported "
                        f"step >= {MIN_STEP_S:g} s and span <= {MAX_SPAN_S:g} s): are the times in seconds?")
    if y.size and np.ptp(y) == 0.0:
        raise DataError(f"{source}: output y is constant ({float(y[0]) + 0.0:g}): no response to identify")


def check_amplitudes(u: np.ndarray, y: np.ndarray, source: str) -> None:
    """DataError when u or y is so large or small that squares and sums over the record would overflow."""
    lo, hi = SAFE_AMPLITUDE
    for name, v in (("u", u), ("y", y)):
        peak = float(np.max(np.abs(v))) if v.size else 0.0
        if peak and not lo <= peak <= hi:
            raise DataError(f"{source}: {name} reaches {peak:.3g}, outside {lo:g}..{hi:g} where the fit "
                            f"computes without overflow: rescale {name} (e.g. other units)")
