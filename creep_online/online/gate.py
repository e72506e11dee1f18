"""Which model an adaptive compensator may take from a live estimate (``ModelGate``).

Creep compensation needs alpha and b: after the resonance's transient the output
of the compensated plant is ``F r`` whatever resonance the compensator inverts
(``(1 + a1m s + a2m s^2) / (1 + a1 s + a2 s^2)`` tends to 1), so a resonance
error only shapes the transient. The estimator's ``quality`` is ``good`` only
when all four parameters are determined, and on some plants (a small gain, a
well-damped or high resonance under noise) a1 never is: a compensator that waits
for ``good`` never starts. The gate therefore takes alpha and b when the
estimate determines them (``OnlineEstimate.determined``: at the noise floor, no
change pending) and chooses the resonance separately:

1. the estimate's own, when it is determined (and then remembered);
2. otherwise the last determined resonance, if there was one;
3. otherwise the estimate's own if the data at least show it: each of a1, a2
   with a 1-sigma below half its value (``ROUGH``; the coefficient is nonzero at
   2 sigma, and inverting it errs by less than not inverting it would); a
   determined resonance later replaces it;
4. otherwise none: no model yet (the compensator keeps passing the reference
   through, or keeps the model it has).

An estimate is taken only once alpha and b have stayed determined for ``DWELL_S``
(two re-fits at the default 0.1 s period): a window fit that passes the checks for
one re-fit between failing ones is a fit in transit (seen on random drifting plant
13: alpha at 0.95, b 7x too small and a 14 Hz resonance for one 10 ms read, between
``degraded`` and ``changing``).

The estimator's ``quality`` is not touched: it still says ``provisional`` and why.
"""
from __future__ import annotations

import math

from ..model import CreepModel
from .stored_params import StoredParams

#: Seconds (estimate time) alpha and b must have stayed determined before a model is taken.
DWELL_S = 0.2
#: The creep part: a model is taken only when the estimate determines these.
CREEP = ("alpha", "b")
#: The resonance's coefficients.
RESONANCE = ("a1", "a2")
#: An undetermined resonance is used (when no determined one was seen) if each coefficient's relative
#: 1-sigma is below this: the data show it at 2 sigma.
ROUGH = 0.5


class ModelGate(StoredParams):
    """The model to give a compensator from each new estimate (``model``), or None: keep what it has.

    Remembers the last determined resonance. ``source`` says where the resonance of the last
    model came from: ``"determined"``, ``"held"`` (the last determined one), ``"rough"`` (case 3).
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> "ModelGate":
        """Forget the remembered resonance and the dwell."""
        self._resonance: tuple[float, float] | None = None
        self._since: float | None = None       # estimate time since which alpha and b are determined
        self.source = ""
        return self

    def model(self, estimate) -> CreepModel | None:
        """The model a compensator may take from ``estimate`` (an ``OnlineEstimate``), or None."""
        determined = set(getattr(estimate, "determined", ()))
        if not set(CREEP) <= determined:
            self._since = None
            return None
        if self._since is None or estimate.t < self._since:
            self._since = estimate.t
        if estimate.t - self._since < DWELL_S:
            return None
        resonance, source = self._choose(estimate, determined)
        if resonance is None:
            return None
        try:
            model = CreepModel(estimate.alpha, resonance[0], resonance[1], estimate.b)
        except Exception:  # noqa: BLE001 - an out-of-range estimate: nothing to take
            return None
        if source == "determined":
            self._resonance = resonance
        self.source = source
        return model

    def _choose(self, estimate, determined: set) -> tuple[tuple[float, float] | None, str]:
        """(a1, a2) and where they came from, per the order in the module docstring."""
        own = (float(estimate.a1), float(estimate.a2))
        if set(RESONANCE) <= determined:
            return own, "determined"
        if self._resonance is not None:
            return self._resonance, "held"
        if all(_relative_std(estimate, name) < ROUGH for name in RESONANCE):
            return own, "rough"
        return None, ""


def _relative_std(estimate, name: str) -> float:
    """The estimate's relative 1-sigma of parameter ``name`` (inf when unknown)."""
    value = abs(float(getattr(estimate, name)))
    std = float(estimate.uncertainty.get(name, math.inf))
    return std / value if value > 0 else math.inf
