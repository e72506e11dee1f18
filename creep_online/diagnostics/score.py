"""The pair search's trigger: does a record one effect explains hold a second one? A score test per partner.

When the best single fit explains the record (``pairs.explains``: RMS at the
noise floor, white residual) a weak second effect can still be there: its
trace in the residual's RMS or autocorrelation is far below what the
omnibus tests see, while its own template shows it (1.3-3x pairs bench: 23
records whose hidden pair beat the best single effect by a BIC drop of
13-300 were never searched). Fitting the best effect with every partner
answers that (branch ``pairs13-partner``) but costs k - 1 pair fits on
every single-effect record (2-2.6x the CPU of ``diagnose``). This module
asks the same question without a fit: for each partner, the score
(Lagrange multiplier) statistic of its parameters at the best single fit.

For a partner at a point ``x`` of its nonlinear parameters (``Effect.score_points``)
the pair's design is evaluated at (the single fit's parameters, ``x``):
the linear coefficients (the partner's, at 0 under the null, with every
other) are solved in closed form, as in every variable-projection
evaluation, and one Gauss-Newton step on all nonlinear parameters (the base
model's, the fitted effect's, the partner's) is taken from there on the
pair's exact projected Jacobian (``Design.jacobian``). The statistic is the
likelihood-ratio form of that step, n ln(RSS_single / RSS_step): for the
linear parameters exactly the score test, for the nonlinear ones its
first-order form. The reference RSS_single gets the same step on the single
effect's own design, so a fit that is not quite at its optimum on the
compared window (a long record's) does not count as a partner's evidence.
The points are ranked by the linear solve alone (one evaluation each); the
Jacobian is taken at the best point of each partner only.

A partner whose nonlinear parameter has no null (a second mode's frequency)
is tested at every point and the largest statistic counts: the trigger
requires, besides the evidence threshold, a Bonferroni p-value below
``SCORE_ALPHA`` over every point of every partner tried.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..effects import get_effect
from ..errors import ModelError
from . import extended as ext
from .bic import chi2_sf

#: Family-wise false-alarm rate of the trigger on a record one effect explains (Bonferroni over every point of
#: every partner, on top of the BIC threshold; with the BIC's dk ln N it rarely binds on records of 1000+ samples).
SCORE_ALPHA = 0.01


@dataclass
class PartnerScore:
    """One partner's score test at the best single fit."""

    effect: str
    evidence: float            # lr - dk ln n, as ``bic.evidence`` weighs a fitted pair
    lr: float                  # n ln(RSS_single / RSS_step)
    dk: int                    # the partner's parameters (nonlinear and linear)
    points: int                # points of its nonlinear parameters tried
    at: dict[str, float] = field(default_factory=dict)    # the best point, after the step (fitting scale)
    beside: str = ""           # the single effect it was tested beside
    against: str = ""          # the single effect the pair must beat (``beside`` unless the test ran beside another)

    def p_value(self) -> float:
        return chi2_sf(self.lr, self.dk)


def partner_scores(data: ext.Prepared, first: str, fit: ext.ExtendedFit, partners: list[str],
                   peaks: list[float], against: tuple[str, ext.ExtendedFit] | None = None) -> list[PartnerScore]:
    """The score test of each of ``partners`` beside ``first`` (fitted alone: ``fit``) on ``data``, best first.

    ``peaks``: spectral peaks (Hz) of what the single fit left, for partners whose points sit on lines.
    ``against``: another single effect and its fit that the pair must beat instead of ``first`` alone (the
    pair's evidence is then over that fit, its dk the pair's parameters beyond that fit's, at least 1): a
    pair without the best single effect, which stands in for both of it (leakage + drift 1.3-3x seed 0: a
    second creep at 1.002x the noise; leakage + drift beats it by 15 once fitted, drift beside the second
    creep scores 8.4). A partner whose design fails at every point is left out."""
    variants = _variants(first, fit)
    rss0 = _single_rss(data, first, fit)
    rss_ref, ref = (rss0, fit) if against is None else (_single_rss(data, *against), against[1])
    out = []
    for name in partners:
        effect = get_effect(name)
        points = effect.score_points(data, peaks)
        best = None
        for variant in effect.variants or (None,):
            design = ext.Design(data, (first, name), variants={**variants, **({name: variant} if variant else {})})
            own = design.own[name]
            for x in points:
                th = _theta(design, fit, dict(zip(own, x)))
                try:
                    cost = design.cost(th)
                except (ValueError, ModelError, np.linalg.LinAlgError):
                    continue
                if np.isfinite(cost) and (best is None or cost < best[0]):
                    best = (cost, design, th)
        if best is None:
            continue
        _, design, th = best
        rss1, moved = _stepped(design, th)
        rss1 = min(rss1, rss0)
        lr = data.n * math.log(max(rss_ref, 1e-300) / max(rss1, 1e-300))
        dk = max(len(th) + len(design.project(th)[0]) - ref.n_params, 1)
        nv = max(len(effect.variants), 1)
        out.append(PartnerScore(name, lr - dk * math.log(data.n), lr, dk, len(points) * nv,
                                {k: float(v) for k, v in zip(design.names, moved) if k in design.own[name]},
                                first, first if against is None else against[0]))
    return sorted(out, key=lambda s: -s.evidence)


def _single_rss(data: ext.Prepared, name: str, fit: ext.ExtendedFit) -> float:
    """RSS of effect ``name``'s single fit on ``data`` after one Gauss-Newton step (``_stepped``)."""
    single = ext.Design(data, (name,), variants=_variants(name, fit))
    return _stepped(single, _theta(single, fit, {}))[0]


def fires(scores: list[PartnerScore], threshold: float) -> PartnerScore | None:
    """The strongest partner whose score passes both ``threshold`` (BIC drop) and the Bonferroni bound, or None."""
    tried = sum(s.points for s in scores) or 1
    for s in scores:
        if s.evidence > threshold and tried * s.p_value() < SCORE_ALPHA:
            return s
    return None


def _variants(first: str, fit: ext.ExtendedFit) -> dict[str, str]:
    """The fitted effect's discrete variant (e.g. hysteresis' initial state), as the single fit chose it."""
    effect = get_effect(first)
    if not effect.variants:
        return {}
    known = (fit.effect_params.get(first) or {}).get(effect.variant_key)
    return {first: known} if known in effect.variants else {}


def _theta(design: ext.Design, fit: ext.ExtendedFit, partner: dict[str, float]) -> np.ndarray:
    """The design's parameters: the single fit's where it has them, the partner's point, mid-range otherwise."""
    th = 0.5 * (design.lo + design.hi)
    for name, value in [*zip(fit.names, fit.theta), *partner.items()]:
        if name in design.names:
            th[design.index(name)] = value
    return np.clip(th, design.lo, design.hi)


def _stepped(design: ext.Design, theta: np.ndarray) -> tuple[float, np.ndarray]:
    """RSS after one Gauss-Newton step from ``theta`` (linear coefficients solved exactly; the step's
    linearized RSS), a parameter on a bound not stepped across it, and the stepped theta (``theta`` itself
    where no Jacobian could be had)."""
    r = np.array(design.residual(theta))
    rss = float(r @ r)
    try:
        jac = design.jacobian(theta) if design.analytic else None
    except (ValueError, ModelError, np.linalg.LinAlgError):
        jac = None
    if jac is None or not np.all(np.isfinite(jac)):
        return rss, theta
    free = np.ones(theta.size, dtype=bool)
    step = np.zeros(theta.size)
    for _ in range(3):                        # drop the columns that would step out of the bounds
        step[:] = 0.0
        if not free.any():
            break
        j = jac[:, free]
        scale = np.linalg.norm(j, axis=0)
        scale[scale == 0] = 1.0
        dx = np.linalg.lstsq(j / scale, -r, rcond=1e-10)[0] / scale
        step[free] = dx
        out = ((theta <= design.lo) & (step < 0)) | ((theta >= design.hi) & (step > 0))
        if not out.any():
            break
        free &= ~out
    rest = r + jac @ step
    stepped = float(rest @ rest)
    rss = min(rss, stepped)
    return rss, np.clip(theta + step, design.lo, design.hi)
