"""Explain the misfit: fit every catalogue effect, weigh the evidence, rank, and name the missing one.

Each candidate effect is fitted as an extension of the base model
(warm-started from the base fit, ``extended.fit_extended``). Its evidence is
the drop of the Bayesian information criterion,

    evidence = N ln(RSS_base / RSS_effect) - dk ln N      (dk = extra parameters)

which is also the likelihood-ratio statistic ``N ln(RSS_base/RSS_effect)``
(chi-square with dk degrees of freedom under "no effect") minus the BIC
penalty. An effect counts as *significant* when its evidence exceeds
``EVIDENCE_THRESHOLD`` (Kass-Raftery "very strong" is 10), it lowers the
residual RMS by at least ``MIN_RMS_DROP`` and its fitted parameters do not
contradict its physics (``Effect.contradiction``: e.g. a "disturbance" line on
a harmonic of a periodic input; such fits rank after the others). The
verdict is the best significant effect, or ``none``; two effects at once are
searched by ``pairs.choose_pair``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..effects import effect_names, get_effect
from ..errors import CreepOnlineError, DataError
from ..io.jsonable import jsonable
from ..metrics import noise_std_estimate
from ..record import Record
from .._threads import single_threaded
from . import extended as ext
from .basis import verdict_basis
from .bic import EVIDENCE_THRESHOLD, evidence
from .compare import error_metrics
from .holds import EFFECTS as PHYSICS_EFFECTS
from .holds import physics_check
from .locate import locate
from .pairs import choose_pair, contradicts
from .pool import ordered_map, resolve_workers
from .residuals import autocorrelation, cross_correlation, parameter_uncertainty
from .start import fit_base_by_rule

#: ... and the relative drop of the residual RMS it must achieve.
MIN_RMS_DROP = 0.02
#: Base residual RMS, relative to the output's spread, below which the model already
#: reproduces the data to their numerical precision (noise-free or simulated data):
#: no effect can be missing then, whatever the BIC says about rounding noise.
PRECISION_FLOOR = 1e-7


@dataclass
class Candidate:
    """One catalogue effect fitted as an extension: its evidence, signature and fit."""

    effect: str
    evidence: float
    lr_statistic: float
    lr_pvalue: float
    extra_params: int
    significant: bool
    fit: ext.ExtendedFit
    signature: str = ""
    contradiction: str = ""    # why the fitted parameters contradict the effect's physics ("" if they do not)

    def to_dict(self) -> dict:
        return {"effect": self.effect, "evidence": self.evidence, "significant": self.significant,
                "fit_percent_after": self.fit.fit_percent, "residual_rms_after": self.fit.residual_rms,
                "params": jsonable(self.fit.effect_params.get(self.effect, self.fit.effect_params)),
                "lr_statistic": self.lr_statistic, "lr_pvalue": self.lr_pvalue,
                "extra_params": self.extra_params, "signature": self.signature,
                "contradiction": self.contradiction or None}


@dataclass
class Diagnosis:
    """The whole workflow's answer (``to_dict`` is the ``diagnose --json`` schema; its nested parameters,
    location and residual analysis go through ``io.jsonable``: numpy to Python, non-finite numbers to None)."""

    source: str
    base: ext.ExtendedFit
    noise_rms: float
    candidates: list[Candidate]
    skipped: dict[str, str]
    location: dict
    residual_analysis: dict
    combination: Candidate | None = None
    warnings: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0
    data: ext.Prepared | None = field(default=None, repr=False)
    physics: dict = field(default_factory=dict)   # holds.physics_check: leakage / second creep / drift by hold physics
    pairs_tried: dict = field(default_factory=dict)  # pairs.choose_pair: "a+b" -> (BIC drop over the base, residual RMS)
    pair_rivals: list = field(default_factory=list)  # pairs.rival_pairs: the pairs the record does not tell apart
    #: the pair search's trigger where one effect explains the record (``score.partner_scores``), strongest first
    partner_scores: list = field(default_factory=list)

    @property
    def verdict(self) -> str:
        """The missing effect: the best significant single effect, unless it is a stand-in for a pair.

        When the combination beats the best single fit (``significant``) without
        containing it, that single effect only imitated the two (a second creep
        for leakage + drift): the verdict is then the pair's stronger effect.
        """
        top = self.candidates[0] if self.candidates else None
        if top is None or not top.significant:
            return "none"
        if self.standing_in:
            return self.combination.effect.split("+")[0]
        return top.effect

    @property
    def standing_in(self) -> bool:
        """True when the best single effect is not in the combination that beats it."""
        c = self.combination
        return bool(c is not None and c.significant and self.candidates[0].effect not in c.fit.effects)

    @property
    def best(self) -> ext.ExtendedFit:
        """The extended fit of the verdict (the base fit when the verdict is none)."""
        v = self.verdict
        return next(c.fit for c in self.candidates if c.effect == v) if v != "none" else self.base

    @property
    def verdict_basis(self) -> dict:
        """Which evidence decided the verdict (basis.verdict_basis): BIC alone, confirmed, or against the physics."""
        out = verdict_basis(self.verdict, {c.effect: c.evidence for c in self.candidates}, self.physics)
        if self.standing_in:
            a, b = self.combination.effect.split("+")
            out["stand_in"] = top = self.candidates[0].effect
            out["text"] = (f"pair search: {top} alone imitated {a} + {b}, which beat it "
                           f"({self.combination.signature}); " + out["text"])
        return out

    def to_dict(self) -> dict:
        b = self.base
        return {
            "fit_percent": b.fit_percent, "residual_rms": b.residual_rms, "noise_rms": self.noise_rms,
            "verdict": self.verdict,
            "missing_effects": [c.to_dict() for c in self.candidates],
            "base_model": {**b.model.describe(), "offset": b.offset},
            "combination": None if self.combination is None else {
                "effects": self.combination.effect.split("+"), **self.combination.to_dict(),
                "params": jsonable(self.combination.fit.effect_params),
                "pairs_tried": [{"effects": k.split("+"), "evidence": v[0], "residual_rms": v[1]}
                                for k, v in self.pairs_tried.items()],
                "rivals": jsonable(self.pair_rivals)},
            "skipped": self.skipped, "location": jsonable(self.location),
            "residual_analysis": jsonable(self.residual_analysis),
            "warnings": self.warnings, "elapsed_s": self.elapsed_s, "source": self.source,
            "physics_check": jsonable(self.physics), "verdict_basis": jsonable(self.verdict_basis),
            "partner_scores": [jsonable({"effect": s.effect, "evidence": s.evidence, "lr": s.lr, "dk": s.dk,
                                         "points": s.points, "at": s.at, "beside": s.beside,
                                         "against": s.against}) for s in self.partner_scores],
        }


# --------------------------------------------------------------------------- applicability
def applicable(data: ext.Prepared, effect: str) -> str | None:
    """None if the data can reveal ``effect``; else the reason it cannot (the effect's own rule)."""
    return get_effect(effect).applicable(data)


def signature(effect: str, fit: ext.ExtendedFit, base: ext.ExtendedFit, where: dict, data: ext.Prepared) -> str:
    """The effect's fingerprint in the base residual, in words with the number that carries it."""
    return get_effect(effect).signature(fit.effect_params.get(effect, {}), fit, base, where, data)


# --------------------------------------------------------------------------- the workflow
def _as_arrays(record_or_t_u_y, step_before: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """t, u, y, source from a Record or a tuple, validated (a constant input is allowed after a prior step)."""
    if isinstance(record_or_t_u_y, Record):
        rec = record_or_t_u_y
    else:
        try:
            t, u, y = record_or_t_u_y
        except (TypeError, ValueError):
            raise DataError("diagnose needs a Record or a (t, u, y) tuple") from None
        rec = Record(t, u, y)
    if step_before and rec.t.size and np.ptp(rec.u) == 0.0:
        Record(np.concatenate(([rec.t[0] - 1.0], rec.t)), np.concatenate(([0.0], rec.u)),
               np.concatenate(([0.0], rec.y)), rec.source).validate()
    else:
        rec.validate()
    return rec.t, rec.u, rec.y, rec.source


@single_threaded
def diagnose(record_or_t_u_y, *, candidates: tuple[str, ...] | None = None, use_identify: bool = True,
             u_pre: float | None = None, t_pre: float | None = None, combine: bool = True,
             max_nfev: int = ext.MAX_NFEV, progress: Callable[[str], None] | None = None,
             workers: int | None = None) -> Diagnosis:
    """Compare, locate, explain: fit the base model, every candidate effect, rank them, give the verdict.

    ``record_or_t_u_y`` is a ``Record`` or a ``(t, u, y)`` tuple. ``u_pre`` /
    ``t_pre`` describe an input step before the first sample (e.g. a creep
    test logged from t > 0); by default the start rule decides (from rest for a
    step experiment, in equilibrium at u[0] otherwise, the other reading when it
    fits clearly better: ``creep_online.diagnostics.start``). ``combine`` also fits the two best significant effects together.
    ``candidates``: the effects to try (default: every registered one,
    ``creep_online.effects.effect_names()``). ``progress`` is called with the
    name of each stage as it starts (the CLI shows it on a terminal).
    ``workers``: threads for the candidate fits (default: the available
    cores, or ``CREEP_ONLINE_DIAGNOSE_WORKERS``; 1 = one after the other in
    this thread); the results do not depend on it (``pool.py``).
    """
    start = time.perf_counter()
    report = progress or (lambda _stage: None)
    t, u, y, source = _as_arrays(record_or_t_u_y, step_before=u_pre is not None)
    pre_notes = []
    if u_pre is None and t_pre is None and np.ptp(u) == 0.0:
        u_pre = 0.0  # a constant non-zero input is a step from rest at t[0] (as Record.validate reads it)
        pre_notes.append(f"constant input {u[0]:g}: read as a step from 0 at t = {t[0]:g} s")
    candidates = effect_names() if candidates is None else tuple(candidates)
    n_workers = resolve_workers(workers)
    for name in candidates:
        ext.check_effects([name])
    warnings = pre_notes
    data, base = fit_base_by_rule(t, u, y, source=source, u_pre=u_pre, t_pre=t_pre, use_identify=use_identify,
                                  max_nfev=max_nfev, warnings=warnings, report=report)
    noise = noise_std_estimate(base.residual)
    settle = min(base.model.settling_time, 0.25 * (data.t[-1] - data.t[0]))
    where = locate(data.t, data.u, base.residual, noise, settle)
    analysis = {
        "metrics": error_metrics(data.y, base.y_hat, noise),
        "autocorrelation": autocorrelation(base.residual),
        "cross_correlation": cross_correlation(base.residual, data.u),
    }
    try:
        analysis["parameter_uncertainty"] = parameter_uncertainty(
            data.t, data.u, base.residual, base.model, base.offset, data.u_pre, data.t_pre, data.weights)
    except (CreepOnlineError, ValueError, np.linalg.LinAlgError) as exc:
        warnings.append(f"parameter uncertainty unavailable ({exc})")
    ranked: list[Candidate] = []
    skipped: dict[str, str] = {}
    exact = base.residual_rms < PRECISION_FLOOR * float(np.std(data.y))
    if exact:
        warnings.append(f"the base model reproduces the data to {base.residual_rms / float(np.std(data.y)):.1e} "
                        "of their spread (noise-free data?): nothing is missing")
    todo: list[tuple[int, str]] = []
    for i, name in enumerate(candidates, 1):
        why = applicable(data, name)
        if why is None:
            todo.append((i, name))
        else:
            skipped[name] = why
    # the candidate fits are independent: on several cores at once (pool.py), results in the serial order
    fits = ordered_map(lambda job: ext.fit_extended(data, (job[1],), base, max_nfev=max_nfev, uncertainty=False),
                       todo, n_workers,
                       before=lambda _k, job: report(f"[{job[0]}/{len(candidates)}] fitting the base model + {job[1]}"))
    for (_, name), fit in zip(todo, fits):
        ev, lr, pv, dk = evidence(base, fit, data.n)
        against = contradicts(fit, data)
        sig = (not exact and against is None and ev > EVIDENCE_THRESHOLD
               and fit.residual_rms < (1.0 - MIN_RMS_DROP) * base.residual_rms)
        ranked.append(Candidate(name, ev, lr, pv, dk, bool(sig), fit, signature(name, fit, base, where, data),
                                against or ""))
    ranked.sort(key=lambda c: (bool(c.contradiction), -c.evidence))  # a contradicted fit ranks after the others
    data.release()      # the single fits' remembered responses: the pair search asks for a window's
    if ranked and ranked[0].significant:
        # high-frequency misfit (ringing, a hum) inflates the difference-based noise estimate: re-estimate
        # on the residual of the model that explains it, and keep the smaller
        noise = min(noise, noise_std_estimate(ranked[0].fit.residual))
        analysis["metrics"] = error_metrics(data.y, base.y_hat, noise)
    sig_top = [c for c in ranked if c.significant][:2]
    if len(sig_top) == 2 and sig_top[0].evidence - sig_top[1].evidence < EVIDENCE_THRESHOLD:
        warnings.append(f"{sig_top[0].effect} and {sig_top[1].effect} explain the data about equally well "
                        f"(evidence {sig_top[0].evidence:.4g} vs {sig_top[1].evidence:.4g}): the verdict is not firm")
    partner_scores: list = []
    combo, tried, rivals = (_combination(data, base, ranked, noise, max_nfev, n_workers, report, partner_scores)
                            if combine else (None, {}, []))
    data.release()
    report("hold physics: leakage, second creep or drift")
    physics = _physics(data, base, tuple(c.fit for c in ranked if c.effect in PHYSICS_EFFECTS))
    result = Diagnosis(source, base, noise, ranked, skipped, where, analysis, combo, warnings, 0.0, data, physics,
                       tried, rivals, partner_scores)
    if result.standing_in:
        warnings.append(f"{ranked[0].effect} ranks first alone but the pair {combo.effect} beats it "
                        f"({combo.signature}): the verdict is {result.verdict}")
    if rivals and combo.significant:
        warnings.append(_rivals_note(combo.effect, rivals))
    if result.verdict_basis["decided_by"] == "bic_over_physics":
        warnings.append(result.verdict_basis["text"])
    result.elapsed_s = time.perf_counter() - start
    return result


def _combination(data: ext.Prepared, base: ext.ExtendedFit, ranked: list[Candidate], noise: float, max_nfev: int,
                 workers: int, report: Callable[[str], None],
                 partner_scores: list | None = None) -> tuple[Candidate | None, dict, list[dict]]:
    """The best pair of effects (pairs.choose_pair) as a candidate, significant when it beats the best single
    fit; the pairs tried ("a+b" -> (evidence, residual RMS)); and its rivals (``_rivals``). ``partner_scores``
    receives the partners' score tests when they run."""
    choice = choose_pair(data, base, [(c.effect, c.fit, c.significant) for c in ranked], noise,
                         max_nfev=max_nfev, workers=workers, report=report, partner_scores=partner_scores)
    if choice is None:
        return None, {}, []
    ev, lr, pv, dk = evidence(base, choice.fit, data.n)
    ev1 = evidence(ranked[0].fit, choice.fit, data.n)[0]
    how = (f"the best of {len(choice.tried)} pairs, each effect chosen given the other" if choice.searched
           else "the two best single effects")
    if ev1 > EVIDENCE_THRESHOLD and ranked[0].effect in choice.effects:
        ev1, how = _single_from_pair(data, base, ranked[0], choice.fit, ev1, how, max_nfev, workers, report)
    combo = Candidate("+".join(choice.effects), ev, lr, pv, dk, bool(ev1 > EVIDENCE_THRESHOLD), choice.fit,
                      f"evidence over {ranked[0].effect} alone: {ev1:.3g}; {how}")
    return combo, {"+".join(k): v for k, v in choice.tried.items()}, _rivals(choice)


def _single_from_pair(data: ext.Prepared, base: ext.ExtendedFit, single: Candidate, pair: ext.ExtendedFit,
                      ev1: float, how: str, max_nfev: int, workers: int,
                      report: Callable[[str], None]) -> tuple[float, str]:
    """The pair's evidence over its best single effect refitted warm from the pair (the partner dropped), and the
    signature's note; (ev1, how) unchanged if the refit is no better than the single fit.

    A pair that beats the single fit may only beat its basin: the single fit of a weak effect can lose a
    well-damped resonance (1.3-3x drift seed 58: drift alone at 1.022x the noise with the resonance gone, the
    true model 1.010x; hysteresis seed 77: 1.0066x against 0.9956x) while the pair's fit keeps it, and the
    partner, a delay standing in for the lost resonance's lag or not needed at all, was significant (BIC drops
    145 and 150). The single effect is refitted from the pair's values with its base parameters searched again
    (``fit_extended(restart=True)``: the restart's own gates keep it from fits that explain under half of a
    base misfit of 1.3-3x the noise): 1.0099x and 0.9934x, the pairs' own levels.
    """
    report(f"fitting {single.effect} alone from the pair's plant")
    refit = ext.fit_extended(data, (single.effect,), base, max_nfev=max_nfev, warm=pair, workers=workers,
                             restart=True, uncertainty=False)
    if refit.rss >= single.fit.rss:
        return ev1, how
    ev = evidence(refit, pair, data.n)[0]
    return ev, (f"{how}; {single.effect} alone refitted from the pair's plant reaches "
                f"{refit.residual_rms / single.fit.residual_rms:.4g}x its own single fit's residual")


def _rivals(choice) -> list[dict]:
    """The chosen pair's rivals (pairs.rival_pairs) with the numbers that make them rivals: each one's BIC drop,
    how far it is behind the chosen pair's (negative: ahead, where the chosen pair holds the best single effect),
    and its residual RMS, all on the window the pairs were compared on."""
    def score(pair):
        return choice.tried.get(pair) or choice.tried[pair[::-1]]
    chosen = score(choice.effects)[0]
    return [{"effects": list(k), "evidence": score(k)[0], "behind": chosen - score(k)[0], "residual_rms": score(k)[1]}
            for k in choice.rivals]


def _rivals_note(chosen: str, rivals: list[dict]) -> str:
    """The warning for a pair the record does not tell from others."""
    own = rivals[0]["evidence"] + rivals[0]["behind"]
    others = ", ".join(f"{'+'.join(r['effects'])} ({r['evidence']:.4g})" for r in rivals)
    return (f"the pair {chosen} (evidence {own:.4g}) and {others} explain the data about equally well "
            f"(BIC drops within {EVIDENCE_THRESHOLD:g}): the combination is not firm")


def _physics(data: ext.Prepared, base: ext.ExtendedFit, fits: tuple) -> dict:
    """The hold physics check (holds.py); a record it cannot read gives its reason, never stops the diagnosis."""
    try:
        return physics_check(data, base, fits)
    except (CreepOnlineError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return {"applicable": False, "verdict": "inconclusive", "reason": f"check failed ({exc})", "evidence": {}}
