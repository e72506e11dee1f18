"""The forward model: the base creep model extended by effects, for a zero-order-held input.

Signal flow, stage by stage (``base.Stage``; within a stage, registry order):
input effects -> the linear paths in parallel (base model and parallel
effects) -> delay -> output filters -> the offset and additive effects. Each
stage's work is done by the effects' own hooks; this module only wires them.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import DataError
from .base import Stage, StepFn, check_effect_names, in_forward_order
from .responses import Superposer, base_step_at, base_step_grid, delayed_grid, is_uniform

if TYPE_CHECKING:  # the model layer's domain type; effects need only its four parameters
    from ..model import CreepModel

#: Time stamps whose step varies by less than this (relative) are a uniform grid with jitter: the forward
#: model and the extended fit both snap them to the grid (``snapped_time``).
SNAP_RTOL = 1e-2


def snapped_time(t: np.ndarray) -> tuple[np.ndarray, float]:
    """(time on the uniform grid, jitter) for time stamps within ``SNAP_RTOL`` of a uniform grid; else (t, 0).

    ``jitter`` is the largest deviation of a step from the mean step, relative to it (0: t is returned as
    given, uniform already or genuinely non-uniform such as log-spaced). A logger's time stamps jitter
    (rounding, clock reads); the exact uniform-grid superposition then applies, the fit and the
    simulation of a fitted model alike.
    """
    t = np.asarray(t, dtype=float)
    if t.size < 3 or is_uniform(t) or not is_uniform(t, rtol=SNAP_RTOL):
        return t, 0.0
    h = (t[-1] - t[0]) / (t.size - 1)
    jitter = float(np.max(np.abs(np.diff(t) - h)) / h)
    return t[0] + np.arange(t.size) * h, jitter


def simulate_with_effects(model: "CreepModel", t: np.ndarray, u: np.ndarray, effects: dict[str, dict] | None = None,
                          *, offset: float = 0.0, u_pre: float | None = 0.0, t_pre: float | None = None) -> np.ndarray:
    """Output of the base model extended by catalogue effects, for a zero-order-held input.

    ``effects`` maps effect names to their parameter dicts (see each module of
    ``creep_online.effects`` and docs/diagnostics.md), e.g.
    ``{"delay": {"delay_s": 2.5e-3}, "drift": {"rate": 1e-3}}``.
    ``u_pre`` is the input before the record (0: from rest, as ``simulate``
    assumes; None: the first sample, i.e. the record starts in equilibrium)
    and ``t_pre`` the time of the jump from ``u_pre`` to ``u[0]`` (default
    t[0]). Works for uniform and non-uniform (e.g. log-spaced) time; time stamps
    that jitter around a uniform grid (``snapped_time``) are simulated on that grid,
    as the extended fit reads them. With no effects and uniform time it equals
    ``simulate(model, t, u)`` to rounding.
    """
    effects = dict(effects or {})
    check_effect_names(effects)
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    if t.shape != u.shape or t.ndim != 1:
        raise DataError(f"t and u must be 1-D of equal length (got {t.shape}, {u.shape})")
    t = snapped_time(t)[0] if t_pre is None or t_pre == t[0] else t

    def stage(s: Stage) -> list:
        return in_forward_order(effects, s)

    v, pre = u, u_pre
    for e in stage(Stage.INPUT):
        v = e.transform_input(v, effects[e.name])
        if pre is not None:
            pre = e.transform_before(pre, effects[e.name])
    sup = Superposer(t, v, x_pre=pre, t_pre=t_pre)
    d = 0.0
    for e in stage(Stage.DELAY):
        d = d + e.delay_s(effects[e.name])
    if sup.uniform:
        s = model.b * delayed_grid(base_step_grid(model.alpha, model.a1, model.a2, sup.h, sup.n), sup.h, d)
    parts: list[StepFn] = [e.parallel_step(effects[e.name]) for e in stage(Stage.PARALLEL)]

    def extra(tau: np.ndarray) -> np.ndarray:
        out = np.zeros(np.shape(tau))
        for part in parts:
            out = out + part(tau)
        return out

    if sup.uniform:
        total = s + (extra(sup.grid_tau - d) if parts else 0.0)
        y = sup.apply(total)[0]
    else:
        def total_fn(tau: np.ndarray) -> np.ndarray:
            tt = np.asarray(tau) - d
            return model.b * base_step_at(model.alpha, model.a1, model.a2, tt) + extra(tt)
        y = sup.apply(total_fn)[0]
    for e in stage(Stage.OUTPUT_FILTER):
        y = e.filter_output(t, y, effects[e.name])
    y = y + offset
    for e in stage(Stage.ADDITIVE):
        y = e.add_to_output(t, y, effects[e.name])
    return y
