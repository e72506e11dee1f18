"""The estimator's answer (``OnlineEstimate``) built from its state and the quality rule's verdict."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

from .policy import quality as Q

if TYPE_CHECKING:
    from .estimator import OnlineEstimator


@dataclass
class OnlineEstimate:
    """The estimator's current answer. Every number is finite; a value not yet estimated is None (JSON null).

    Before the first model (phases ``buffering`` and ``searching``) alpha, a1, a2, b, fn_hz, zeta, offset,
    noise_rms, residual_rms, b_rate and alpha_rate are None, and so is t_c until the start-up search has begun;
    residual_rms also until the first window fit. ``frozen`` is True after ``freeze()``: the estimate then stays
    while the samples still run through the model, and ``quality`` says so and judges the frozen model against the
    new samples (``reason`` names the misfit). ``start`` says how the stream was read to start: ``"rest"`` (its first
    input zero), ``"step"`` (its input at a non-zero level from the first sample, read as a step from rest there:
    the input 0 before it), ``"operation"`` (taken in operation: the plant moving from an unknown past input), None
    while the data do not tell yet (``rest.py``). ``hysteresis`` (with ``effects=("hysteresis",)``) is the live
    Prandtl-Ishlinskii loop, ``{"r": thresholds, "w": weights relative to b, "initial": "centred"}`` (the batch fit's
    ``effects["hysteresis"]`` form), None while unknown or without the effect.

    With drift tracking (``track_drift``) alpha and b are the values at the
    newest re-fit (not window averages); ``b_rate`` and ``alpha_rate`` are their
    drift per second, 0 while the data show no significant drift, and
    ``rate_uncertainty`` their 1-sigma (empty while they are 0).
    ``researches`` lists the re-searches of the resonance the tracker ran
    (why, the likelihood ratio, whether it switched and what moved).
    ``determined`` names the parameters the data determine now (relative
    1-sigma within ``OnlineSettings.quality.determined``), and is empty unless the window is at the
    noise floor with no change, degradation or long constant input pending (a last second that disagrees on
    the resonance alone leaves alpha and b in it, the quality ``changing``):
    ``quality`` is ``good`` exactly when it holds all four and the window's
    error is within ``good_ratio`` of the noise floor (``online/policy/quality.py``). A ``provisional``
    estimate with alpha and b in it has a trustworthy creep part and an
    undetermined resonance (the model gate, ``online.gate``: what a compensator may take).
    ``internal_faults`` counts the library's own numerical faults that the
    estimator caught and recovered from (each one also an event of kind
    ``"internal_fault"`` in ``events``; ``online/recovery.py``: the error contract).
    """

    alpha: float | None
    a1: float | None
    a2: float | None
    b: float | None
    phase: str
    quality: str
    uncertainty: dict = field(default_factory=dict)
    t: float = 0.0
    samples: int = 0
    t_c: float | None = None
    fn_hz: float | None = None
    zeta: float | None = None
    offset: float | None = None
    skipped: int = 0
    alpha_updates: int = 0
    divergences: int = 0
    reason: str = ""
    noise_rms: float | None = None
    residual_rms: float | None = None
    outliers: int = 0
    input_outliers: int = 0
    shifts: int = 0
    relinearizations: int = 0
    events: list = field(default_factory=list)
    b_rate: float | None = None
    alpha_rate: float | None = None
    rate_uncertainty: dict = field(default_factory=dict)
    researches: list = field(default_factory=list)
    determined: list = field(default_factory=list)
    internal_faults: int = 0
    frozen: bool = False
    start: str | None = None
    hysteresis: dict | None = None

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return asdict(self)


def quality_view(est: "OnlineEstimator") -> Q.QualityView:
    """What the quality rule reads of the estimator and its tracker."""
    st = est._startup
    tr = est._tracker
    tv = None
    if tr is not None:
        fit = tr.fit
        tv = Q.TrackerView(
            replaying=bool(est._catchup), alpha=tr.alpha, a1=tr.a1, a2=tr.a2, b=tr.b, std=fit.std,
            fit_sample=fit.sample, fit_cost=fit.cost, fit_neff=fit.neff, noise=tr.noise_level,
            live_error_power=tr.live_error_power, output_stuck=tr.output_stuck,
            input_held_samples=tr.input_held_samples, last_event=tr.report_events()[-1] if tr.events else None,
            disagreement=tr.disagreement, last_research=tr.researches[-1] if tr.researches else None)
    return Q.QualityView(
        settings=est._settings.quality, dt=est._h, samples=est.samples, n_shift=est._n_shift,
        window_s=est.window_s, alpha_bounds=est._bounds, u_span=est._u_hi - est._u_lo, frozen=est.frozen,
        frozen_t=est._frozen_t, tracker=tv, fault=est._recovery.view(),
        start=Q.StartView(competing=st.competing, start=st.start, u_first=est._u_ref,
                          moved=st.first_change is not None))


def build_estimate(est: "OnlineEstimator") -> OnlineEstimate:
    """The estimate now. The quality rule's verdict may close the open internal fault (the estimator has
    re-converged): that is the one thing building it changes."""
    tr = est._tracker
    rec = est._recovery
    if rec.kept is not None and est._live is None:    # after a long outage, until the new tracker is live
        return replace(rec.kept, phase=est._phase, t=est.samples * est._h, samples=est.samples,
                       skipped=est.skipped_nonfinite, input_outliers=est.input_outliers, events=est.events,
                       internal_faults=est.internal_faults)
    view = quality_view(est)
    verdict = Q.assess(view)
    if verdict.fault_cleared:
        rec.open = None
    if tr is None:
        return bare_estimate(est, verdict.quality, verdict.reason)
    fit = tr.fit
    a1, a2 = _known(tr.a1), _known(tr.a2)
    wn = 1.0 / math.sqrt(a2) if a2 is not None and a2 > 0.0 else None
    std = {k: _finite(fit.std[k], math.inf) for k in ("alpha", "a1", "a2", "b") if k in fit.std}
    rate_std = {k: _finite(fit.std[k], math.inf) for k in ("b_rate", "alpha_rate") if tr.drift_on and k in fit.std}
    return OnlineEstimate(
        alpha=_known(tr.alpha), a1=a1, a2=a2, b=_known(tr.b), phase=est._phase,
        quality=verdict.quality, reason=verdict.reason, uncertainty=std, t=est.samples * est._h,
        samples=est.samples, t_c=est._startup.tc_used or None, fn_hz=None if wn is None else _known(wn / (2 * math.pi)),
        zeta=None if wn is None or a1 is None else _known(a1 * wn / 2),
        offset=_known(tr.offset), skipped=est.skipped_nonfinite,
        alpha_updates=est.alpha_updates, divergences=est.divergences,
        noise_rms=_known(view.tracker.noise), residual_rms=Q.residual(view.tracker), outliers=tr.outliers,
        shifts=tr.shifts, relinearizations=tr.relinearizations,
        input_outliers=est.input_outliers, events=est.events, b_rate=_known(tr.b_rate),
        alpha_rate=_known(tr.alpha_rate), rate_uncertainty=rate_std,
        researches=est.researches, determined=verdict.determined, internal_faults=est.internal_faults,
        frozen=est.frozen, start=est._startup.start, hysteresis=tr.hysteresis)


def bare_estimate(est: "OnlineEstimator", quality: str, reason: str) -> OnlineEstimate:
    """The estimate without a model (before the first search has ended, or when building it failed)."""
    return OnlineEstimate(alpha=None, a1=None, a2=None, b=None, phase=est._phase, quality=quality,
                          reason=reason, t=est.samples * est._h, samples=est.samples,
                          t_c=est._startup.tc_used or None, skipped=est.skipped_nonfinite,
                          input_outliers=est.input_outliers, events=est.events,
                          internal_faults=est.internal_faults, frozen=est.frozen, start=est._startup.start)


def shifted(item: dict, shift: float, kind: str | None = None) -> dict:
    """A tracker's event or re-search for the caller: private keys dropped, its times moved by ``shift`` (s) to
    stream time (non-zero after a fault's restart), and its ``kind`` if given."""
    out = {} if kind is None else {"kind": kind}
    out.update((k, v) for k, v in item.items() if not k.startswith("_"))
    if shift:
        for key in ("t", "detected_t", "settled_t", "done_t"):
            if key in out:
                out[key] += shift
    return out


def _finite(x: float, default: float = 0.0) -> float:
    x = float(x)
    return x if math.isfinite(x) else default


def _known(x: float) -> float | None:
    """x as a float, or None (not estimated) when it is not finite."""
    x = float(x)
    return x if math.isfinite(x) else None
