"""Online estimation with an extended model: stream-compensate the fitted effects, watch the live error fall.

``EffectCompensator`` undoes fitted effects sample by sample, turning a
measured pair (u, y) into the pair (v, y_base) the *base* creep model would
see, with each effect's own compensator (``Effect.compensator`` in
``creep_online/effects/``): input effects are applied to the input
(hysteresis, nonlinear gain, delay), additive and parallel ones are removed
from the output (drift, periodic disturbance, second mode, second creep) and
leakage is inverted (``(1 + tau s)/(tau s) = 1 + 1/(tau s)``: add the running
integral of the output over tau). ``ExtendedOnlineEstimator`` feeds the
compensated stream to the project's ``OnlineEstimator`` (unchanged), so the
estimator runs with the extended model, and its live prediction error can be
compared with the plain estimator's (``live_error``; both warm-started from
their batch fits, ``warm_start``; ``hil_sim.online_table`` measures it, docs/measurements.md,
"Online, with the extended model"). Per-sample work is O(1) for every effect except
``second_creep`` (O(number of input changes so far), exact for a staircase).
"""
from __future__ import annotations

import math

import numpy as np

from ..effects import Stage, check_effect_names, in_forward_order

#: Order in which the output-side compensators undo their effects.
OUTPUT_ORDER = (Stage.OUTPUT_FILTER, Stage.ADDITIVE, Stage.PARALLEL)


class EffectCompensator:
    """Per-sample inverse of fitted effects (parameters as in ``ExtendedFit.effect_params``).

    Per sample: the input-stage compensators each add their term to the input; on the
    first sample every other compensator learns the equilibrium the record
    starts in (that input and output); the delay line delays the input; then
    the output-side compensators remove their effects from the output in
    ``OUTPUT_ORDER``.
    """

    def __init__(self, dt: float, effects: dict[str, dict]) -> None:
        check_effect_names(effects)
        self.dt = float(dt)
        self.effects = {k: dict(v) for k, v in effects.items()}
        self.n = 0
        self._started = False

        def built(stage: Stage) -> list:
            return [e.compensator(self.dt, self.effects[e.name]) for e in in_forward_order(self.effects, stage)]

        self._inputs = built(Stage.INPUT)
        self._delays = built(Stage.DELAY)
        self._outputs = [c for stage in OUTPUT_ORDER for c in built(stage)]

    def step(self, u: float, y: float) -> tuple[float, float]:
        """(v, y_base) for one sample."""
        n = self.n
        u = float(u)
        v = u
        for c in self._inputs:  # side by side, as in the forward model (``effects.forward.transformed_input``)
            v += c.input(u) - u
        if not self._started:  # the record starts in equilibrium at its first (transformed) input
            self._started = True
            for c in self._delays + self._outputs:
                c.start(v, float(y))
        for c in self._delays:
            v = c.input(v)
        yb = float(y)
        t = n * self.dt
        for c in self._outputs:
            yb = c.output(yb, v, n, t)
        self.n += 1
        return v, yb


class ExtendedOnlineEstimator:
    """The project's ``OnlineEstimator`` run on the effect-compensated stream: the extended model, online."""

    def __init__(self, dt: float, effects: dict[str, dict], **estimator_kwargs) -> None:
        from ..online.estimator import OnlineEstimator
        self.compensator = EffectCompensator(dt, effects)
        self.estimator = OnlineEstimator(dt, **estimator_kwargs)
        self._last = math.nan

    def update(self, u: float, y: float) -> None:
        v, yb = self.compensator.step(u, y)
        self._last = yb
        self.estimator.update(v, yb)

    @property
    def model(self):
        return self.estimator.model

    @property
    def estimate(self):
        return self.estimator.estimate

    @property
    def prediction_error(self) -> float:
        """Latest output minus the extended model's prediction (NaN before tracking)."""
        p = self.estimator.last_prediction
        if p is None or self.estimator.phase != "tracking":
            return math.nan
        return self._last - p


def warm_start(model, dt: float) -> dict:
    """``OnlineEstimator`` keyword arguments that start it from a batch fit: the fit's alpha as a hint.

    The estimator's start-up search needs no guess (it compares candidates
    over alpha, fn and zeta); the batch alpha is added to its grid so that a
    record too short to settle the search still starts at the batch answer.
    The search window (t_c) is left to the estimator.
    """
    if model is None:
        return {}
    return {"alpha0": float(np.clip(model.alpha, 0.01, 0.95))}


def live_error(t: np.ndarray, u: np.ndarray, y: np.ndarray, effects: dict[str, dict], window_s: float = 1.0,
               base_model=None, extended_model=None, **estimator_kwargs) -> dict:
    """Stream a record through the plain and the extended online estimator; windowed RMS prediction errors.

    ``base_model`` / ``extended_model``: batch fits (``CreepModel``) whose alpha the plain and the
    extended estimator get as a hint (``warm_start``); None runs the estimator's defaults.
    Returns ``{"t": window ends, "base": RMS per window, "extended": RMS per window}`` (NaN while
    an estimator is not tracking yet): the live error display's data.
    """
    from ..online.estimator import OnlineEstimator
    dt = float(t[1] - t[0])
    plain = OnlineEstimator(dt, **{**estimator_kwargs, **warm_start(base_model, dt)})
    ext = ExtendedOnlineEstimator(dt, effects, **{**estimator_kwargs, **warm_start(extended_model, dt)})
    e0 = np.full(len(t), np.nan)
    e1 = np.full(len(t), np.nan)
    for i in range(len(t)):
        plain.update(u[i], y[i])
        p = plain.last_prediction
        if p is not None and plain.phase == "tracking":
            e0[i] = y[i] - p
        ext.update(u[i], y[i])
        e1[i] = ext.prediction_error
    w = max(1, int(round(window_s / dt)))
    ends, r0, r1 = [], [], []
    for a in range(0, len(t), w):
        ends.append(float(t[min(a + w, len(t)) - 1]))
        for src, dst in ((e0, r0), (e1, r1)):
            seg = src[a:a + w]
            seg = seg[np.isfinite(seg)]
            dst.append(float(np.sqrt(np.mean(seg * seg))) if seg.size else math.nan)
    return {"t": ends, "base": r0, "extended": r1}


def format_live_error(table: dict, noise: float | None = None) -> str:
    """The live error display as text: one line per window, base vs extended model."""
    lines = [f"  {'t (s)':>8} {'online error, base':>18} {'extended':>10}" + ("   (x noise floor)" if noise else "")]
    for t, a, b in zip(table["t"], table["base"], table["extended"]):
        sa = "-" if not math.isfinite(a) else (f"{a / noise:.3g}x" if noise else f"{a:.4g}")
        sb = "-" if not math.isfinite(b) else (f"{b / noise:.3g}x" if noise else f"{b:.4g}")
        lines.append(f"  {t:>8.3g} {sa:>18} {sb:>10}")
    return "\n".join(lines)
