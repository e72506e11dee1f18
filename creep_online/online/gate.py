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

An estimate is taken only once alpha and b have stayed determined for ``DWELL_S``. The rule and its thresholds
are the quality rule's (``online/policy/quality.py``: ``model_source``); this class keeps what it must remember.

The hysteresis loop (an estimator with ``effects=("hysteresis",)``: ``OnlineEstimate.hysteresis``) travels
with the creep part of the same estimate: ``ExtendedModel(creep, {"hysteresis": loop})``. Never a new loop with
an older creep part: the window fits b and the weights together, and they trade off (the large-signal gain
``b (1 + sum w)`` is what the data fix), so only the pair is a model. An estimate whose loop is not invertible with
the fit's margin (``effects.hysteresis.flattest_branch`` below ``SLOPE_FLOOR``: a branch of the inverse unbounded)
gives nothing. The model with a loop also carries the estimate's output ``offset``: the window fits
``y = b G1[u + sum_i w_i p_i] + offset`` over the stream's whole input history, and on a periodic scan (one
frequency, one amplitude) the creep of the scan's mean level (how far alpha and b carry the history) is set by that
offset as much as by alpha and b, which move with the loop's width there. The compensator inverts the model the window
fitted, offset included (``CreepCompensator`` subtracts it from the reference); without it, on a scanning plant whose
loop drifts, the live model's mean level misses by up to 11 % of the stroke.

The offset must hold still, too: while the model has a loop, a re-fit whose offset moved by more than
``OFFSET_STEP_NOISE`` times the output noise's level from the last estimate restarts the dwell (``DWELL_S``). A window
whose creep, loop and offset trade along a ridge swings its offset from re-fit to re-fit (by the whole stroke on a
staircase plant with a wide loop, alpha and b determined all the while): such a fit is in transit, and its offset,
inverted, would move the output by as much. The mean level a scan's creep puts into the offset moves by a small
fraction of the noise per re-fit.

The estimator's ``quality`` is not touched: it still says ``provisional`` and why.
"""
from __future__ import annotations

import math

from ..effects.hysteresis import SLOPE_FLOOR, flattest_branch
from ..model import CreepModel, ExtendedModel
from .policy.quality import CREEP, DWELL_S, RESONANCE, ROUGH, model_source
from .stored_params import StoredParams

__all__ = ["ModelGate", "CREEP", "DWELL_S", "OFFSET_STEP_NOISE", "RESONANCE", "ROUGH"]

#: Largest move of the offset from one estimate to the next (times the output noise's standard deviation) that a model
#: with a loop may make and keep its dwell (module docstring).
OFFSET_STEP_NOISE = 5.0


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
        self._offset: float | None = None      # the last estimate's offset (with a loop: ``OFFSET_STEP_NOISE``)
        self.source = ""
        return self

    def model(self, estimate) -> CreepModel | ExtendedModel | None:
        """The model a compensator may take from ``estimate`` (an ``OnlineEstimate``), or None: keep what it has.

        With a live loop in the estimate: the creep part extended by that loop and the estimate's offset (None if the
        loop is not invertible).
        """
        creep = self._creep_model(estimate)
        loop = getattr(estimate, "hysteresis", None)
        if creep is None or loop is None:
            return creep
        if not _invertible(loop):
            return None
        offset = getattr(estimate, "offset", None)
        return ExtendedModel(creep, {"hysteresis": loop}, float(offset) if offset is not None else 0.0)

    def _creep_model(self, estimate) -> CreepModel | None:
        """The creep part (alpha, b and a resonance) the rule gives now, or None."""
        determined = set(getattr(estimate, "determined", ()))
        offset_jumped = self._offset_jumped(estimate)
        if not set(CREEP) <= determined:
            self._since = None
            return None
        if self._since is None or estimate.t < self._since or offset_jumped:
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

    def _offset_jumped(self, estimate) -> bool:
        """Did the offset of an estimate with a loop move by more than ``OFFSET_STEP_NOISE`` noise levels since the
        last estimate? (Remembers this one's.)"""
        if getattr(estimate, "hysteresis", None) is None or estimate.offset is None:
            self._offset = None
            return False
        offset, last = float(estimate.offset), self._offset
        self._offset = offset
        noise = estimate.noise_rms
        return last is not None and noise is not None and math.isfinite(noise) and \
            abs(offset - last) > OFFSET_STEP_NOISE * noise

    def _choose(self, estimate, determined: set) -> tuple[tuple[float, float] | None, str]:
        """(a1, a2) and where they came from (``policy.quality.model_source``)."""
        own = (float(estimate.a1), float(estimate.a2))
        rel = {} if set(RESONANCE) <= determined or self._resonance is not None else \
            {name: _relative_std(estimate, name) for name in RESONANCE}
        source = model_source(determined, rel, self._resonance is not None)
        return {"determined": own, "held": self._resonance, "rough": own}.get(source), source


def _relative_std(estimate, name: str) -> float:
    """The estimate's relative 1-sigma of parameter ``name`` (inf when unknown)."""
    value = abs(float(getattr(estimate, name)))
    std = float(estimate.uncertainty.get(name, math.inf))
    return std / value if value > 0 else math.inf


def _invertible(loop: dict) -> bool:
    """Does the loop's inverse have every branch within 1 / SLOPE_FLOOR of its mean (the fit's own rule)?"""
    r, w = loop.get("r") or [], loop.get("w") or []
    return len(r) == len(w) and (not r or flattest_branch(r, w) >= SLOPE_FLOOR)
