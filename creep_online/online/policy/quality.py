"""The quality rule: what ``OnlineEstimate.quality`` says, why, and which parameters the data determine.

One pure function, ``assess``, on a read-only view of the estimator (``QualityView``), in this order:

1. no tracker yet: ``none``, with what the start-up waits for (``waiting_reason``);
2. the start-up buffer still being replayed: ``provisional``;
3. an internal fault not yet re-converged from: ``degraded``, the fault named (``fault_reason``);
4. a frozen estimate: ``provisional``, or ``degraded`` if it misses the new samples (``frozen_quality``);
5. the checks (``checks``): output stuck, a recent change, a disagreeing change test, no window fit yet, an input
   held too long, a window error above ``floor_ratio`` x the noise floor;
6. every parameter within its ``determined`` limit and alpha off its bounds, else ``provisional`` naming the first
   one that is not;
7. the window error within ``good_ratio`` x the noise floor: ``good``; else ``provisional``.

``determined`` lists the parameters within their limits once steps 1-5 pass (empty before): a ``provisional``
estimate with alpha and b in it has a trustworthy creep part. One check contests only the resonance: a last second
that disagrees with the window on a1 or a2 alone (``resonance_only``; on a scan far below the resonance its fit of
the last second does not determine them), or a change event that moved a1 or a2 alone and has not settled past its
first seconds. The estimate then reads ``changing`` (or ``provisional``, an estimate's correction) and ``determined``
keeps alpha and b where they are within their limits (the model gate takes them with the last determined
resonance). The thresholds are ``OnlineSettings.quality`` (``online/settings.py``).

What a compensator may take from an estimate follows from the same verdict (``model_source``; the model gate,
``online/gate.py``, keeps the dwell and the remembered resonance): creep compensation needs alpha and b, which
must have stayed determined for ``DWELL_S``; the resonance is the estimate's own when determined, else the last
determined one, else the estimate's own if the data at least show it (``ROUGH``), else none.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from ..settings import QualitySettings

#: The default limits of "determined" (relative 1-sigma), by parameter, in the order the quality names them.
DETERMINED = dict(QualitySettings().determined.items())
#: Seconds (estimate time) alpha and b must have stayed determined before a compensator takes a model: a window fit
#: that passes the checks for one re-fit between failing ones is a fit in transit (two re-fits at the default 0.1 s).
DWELL_S = 0.2
#: The creep part: a model is taken only when the estimate determines these.
CREEP = ("alpha", "b")
#: What a window that lags a drifting plant needs (the window's lag costs about drift rate x window_s of the moving
#: part of the output; docs/online.md, "A plant that drifts faster than the window").
SHORTER = "a shorter window_s follows faster"
#: The resonance's coefficients.
RESONANCE = ("a1", "a2")
#: An undetermined resonance is used (when no determined one was seen) if each coefficient's relative 1-sigma is
#: below this: the data show it at 2 sigma (inverting it errs by less than not inverting it would).
ROUGH = 0.5


@dataclass(frozen=True)
class StartView:
    """What the start-up is doing before the first tracker (for ``waiting_reason``)."""

    competing: bool                  #: both readings of the start are being searched
    start: str | None                #: "rest", "step", "operation" or None (not read yet)
    u_first: float | None            #: the stream's input reference (its first level; None before any sample)
    moved: bool                      #: the input has moved


@dataclass(frozen=True)
class FaultView:
    """The open internal fault (the newest one not yet re-converged from)."""

    t: float                         #: stream time of the fault
    error: str
    where: str
    message: str
    recovery: str
    fit_after: int                   #: a window fit after this tracker sample is one after the recovery


@dataclass(frozen=True)
class TrackerView:
    """The tracker's state the rule reads (``online/trackers/protocol.py``)."""

    replaying: bool                  #: the start-up buffer is being replayed into it
    alpha: float
    a1: float
    a2: float
    b: float
    std: dict                        #: 1-sigma by parameter name
    fit_sample: int                  #: tracker sample of the last window fit (0: none yet)
    fit_cost: float
    fit_neff: float
    noise: float                     #: the output noise monitor
    live_error_power: float          #: mean square live prediction error
    output_stuck: bool
    input_held_samples: float
    last_event: dict | None          #: the newest detected change (tracker time)
    disagreement: dict | None        #: the last change test that disagreed with the window
    last_research: dict | None       #: the newest re-search of the resonance


@dataclass(frozen=True)
class QualityView:
    """Everything ``assess`` reads."""

    settings: QualitySettings
    dt: float
    samples: int                     #: stream samples taken
    n_shift: int                     #: stream samples before the tracker's first
    window_s: float | None
    alpha_bounds: tuple[float, float]
    u_span: float                    #: the input's range seen so far
    frozen: bool
    frozen_t: float
    start: StartView
    tracker: TrackerView | None
    fault: FaultView | None


class Verdict(NamedTuple):
    quality: str
    reason: str
    determined: list
    fault_cleared: bool = False      #: the open fault has been re-converged from (the estimator forgets it)


def residual(tr: TrackerView) -> float | None:
    """The window fit's rms error (None before the first window fit)."""
    if not math.isfinite(tr.fit_cost) or tr.fit_neff <= 0:
        return None
    return math.sqrt(max(tr.fit_cost, 0.0) / tr.fit_neff)


def noise_floor(tr: TrackerView, u_span: float) -> float:
    """The noise monitor, at least 1e-9 of the output's span (noiseless data)."""
    return max(tr.noise, 1e-9 * abs(tr.b) * max(u_span, 1e-300))


def floor_ratio(view: QualityView) -> float:
    """The window's error over the noise floor (0 before the first window fit)."""
    floor = noise_floor(view.tracker, view.u_span)
    return (residual(view.tracker) or 0.0) / floor if floor > 0 else math.inf


def waiting_reason(start: StartView) -> str:
    """What the estimator waits for before its first estimate."""
    if start.competing:
        return ("searching the resonance and creep: the input's first level as a step from rest at the first "
                "sample, against a stream in operation")
    if start.start is None and start.u_first is not None:
        return (f"reading the start: the input is at {start.u_first:.4g} from the first sample; waiting for the "
                "output to move from its first value (a step from rest) or for the input to move (a stream in "
                "operation)")
    if not start.moved:
        return "waiting for the input to move" + (
            " (the stream is in operation: its output did not start at rest)" if start.start == "operation" else "")
    return "searching the resonance and creep"


def fault_reason(fault: FaultView | None) -> tuple[str, str]:
    """("degraded", the fault named) while the estimator re-converges after it."""
    if fault is None:
        return "degraded", "internal fault"
    return "degraded", (f"internal fault at t={fault.t:.4g} s ({fault.error} in {fault.where}: {fault.message}); "
                        f"{fault.recovery}; re-converging")


def fault_cleared(view: QualityView, quality: str) -> bool:
    """Has the estimator re-converged after the open fault? A window fit after the recovery, and every check passed
    (or a whole window of stream since: what is wrong then is the checks' to say)."""
    tr = view.tracker
    if tr is None or tr.replaying or tr.fit_sample <= view.fault.fit_after:
        return False
    since = view.samples * view.dt - view.fault.t
    return not quality or since > (view.window_s or view.settings.unwindowed_s)


def frozen_quality(view: QualityView) -> tuple[str, str]:
    """A frozen estimate's quality: never "good" (it no longer follows the plant); "degraded" when the live
    prediction error exceeds ``floor_ratio`` of the noise floor, else "provisional"."""
    tr = view.tracker
    floor = noise_floor(tr, view.u_span)
    live = math.sqrt(max(tr.live_error_power, 0.0)) / floor if floor > 0 else math.inf
    held = f"frozen since t={view.frozen_t:.4g} s: the estimate is held, not adapted"
    if live > view.settings.floor_ratio:
        return "degraded", f"{held}; it misses the data now (live error {live:.3g}x the noise floor)"
    return "provisional", f"{held} (live error {live:.3g}x the noise floor)"


def checks(view: QualityView) -> tuple[str, str, float]:
    """(quality, reason, the window's error over the noise floor) from every check but the parameters'
    determination; ("", "", ratio) if all pass (the ratio NaN before the tracker is live)."""
    tr = view.tracker
    s = view.settings
    if tr is None:
        return "none", waiting_reason(view.start), math.nan
    if tr.replaying:
        return "provisional", "replaying the start-up buffer", math.nan
    ratio = floor_ratio(view)
    if tr.output_stuck:
        return "degraded", "output frozen or clipped while the model says it moves", ratio
    shift = view.n_shift * view.dt    # the tracker's time to stream time (non-zero after a fault's restart)
    now = view.samples * view.dt - shift
    # an unsettled change holds "changing" past its first seconds only while the window is below "degraded": a
    # change whose fit never settles is a window that misses the data
    ev = tr.last_event
    if ev is not None and (now - ev["detected_t"] < s.change_hold_s
                           or (not ev["settled"] and ratio <= s.floor_ratio)):
        if ev.get("estimate_settled") is False:
            return "provisional", (f"estimate corrected at t={ev['t'] + shift:.3g} s "
                                   f"({', '.join(ev['moved'])} moved; "
                                   "it had not settled: a change of the estimate, maybe not of the plant)"), ratio
        return "changing", f"change detected at t={ev['t'] + shift:.3g} s ({', '.join(ev['moved'])} moved)", ratio
    dis = tr.disagreement
    if dis is not None and now - dis["t"] < s.change_hold_s:
        moves = ", ".join(f"{k} {100 * v:+.0f} %" for k, v in dis["moves"].items())
        return "changing", (f"the last second disagrees with the window's estimate ({moves}, likelihood ratio "
                            f"{dis['lr']:.3g}): the plant may be changing"), ratio
    if tr.fit_sample == 0:
        rs = tr.last_research if tr.last_research is not None and tr.last_research["switched"] else None
        return "provisional", ("first window fit pending" if rs is None else
                               f"resonance re-searched at t={rs['t'] + shift:.3g} s "
                               f"({', '.join(rs['moved'])} moved)"), ratio
    held = tr.input_held_samples * view.dt
    if view.window_s is not None and held > s.held_windows * view.window_s:   # < 5 % of the last step's weight left
        return "provisional", (f"input constant for {held:.3g} s: the window no longer holds an input change "
                               "(the estimate is the last one the data determined)"), ratio
    if ratio > s.floor_ratio:
        return "degraded", (f"window error {ratio:.1f}x the noise floor: the model misses part of the data (an "
                            f"effect it lacks, or a plant drifting faster than the window follows: {SHORTER})"), ratio
    return "", "", ratio


def resonance_only(view: QualityView, ratio: float) -> bool:
    """Does every failing check contest the resonance (a1, a2) alone, the window at most ``floor_ratio`` x the noise
    floor? The last second disagreeing on a1 or a2 only, or a change event past its first ``change_hold_s`` that
    moved a1 or a2 only and has not settled (on a scan far below the resonance the fit never pins them, so such an
    event never settles, and alpha and b stay what the data determine)."""
    tr = view.tracker
    if tr is None or tr.replaying:
        return False
    held = tr.input_held_samples * view.dt
    if not ratio <= view.settings.floor_ratio or tr.output_stuck or tr.fit_sample == 0 or (
            view.window_s is not None and held > view.settings.held_windows * view.window_s):
        return False
    hold = view.settings.change_hold_s
    now = view.samples * view.dt - view.n_shift * view.dt
    ev, dis = tr.last_event, tr.disagreement
    event_open = ev is not None and (now - ev["detected_t"] < hold or not ev["settled"])
    event_resonance = ev is not None and now - ev["detected_t"] >= hold and bool(ev["moved"]) and \
        set(ev["moved"]) <= set(RESONANCE)
    disagrees = dis is not None and now - dis["t"] < hold
    disagrees_resonance = dis is not None and bool(dis["moves"]) and set(dis["moves"]) <= set(RESONANCE)
    if not (event_open or disagrees):
        return False
    return (not event_open or event_resonance) and (not disagrees or disagrees_resonance)


def determination(view: QualityView) -> tuple[list, str]:
    """(the determined parameters, the reason the first one of the limits' order is not; "" if all are)."""
    tr = view.tracker
    limits = view.settings.determined.items()
    values = {"alpha": tr.alpha, "b": tr.b, "a1": tr.a1, "a2": tr.a2}
    rel = {name: tr.std.get(name, math.inf) / max(abs(values[name]), 1e-300) for name, _ in limits}
    lo, hi = view.alpha_bounds
    tol = view.settings.bound_tol
    pinned = not lo * (1 + tol) < tr.alpha < hi * (1 - tol)
    determined = [name for name, limit in limits if rel[name] < limit and not (name == "alpha" and pinned)]
    for name, _ in limits:
        if name == "alpha" and pinned:
            return determined, f"alpha at its bound {tr.alpha:.4g}: the search interval holds it, not the data"
        if name not in determined:
            return determined, f"{name} not yet determined by the data ({100 * rel[name]:.2g} % 1-sigma)"
    return determined, ""


def assess(view: QualityView) -> Verdict:
    """The quality rule (module docstring): (quality, reason, determined, whether the open fault is cleared)."""
    quality, reason, ratio = checks(view)
    cleared = view.fault is not None and fault_cleared(view, quality)
    if view.fault is not None and not cleared:
        return Verdict(*fault_reason(view.fault), [])
    if view.frozen and view.tracker is not None and not view.tracker.replaying:
        return Verdict(*frozen_quality(view), [], cleared)
    if quality:
        creep = [p for p in determination(view)[0] if p in CREEP] if resonance_only(view, ratio) else []
        return Verdict(quality, reason, creep, cleared)
    determined, why = determination(view)
    if why:
        return Verdict("provisional", why, determined, cleared)
    if ratio > view.settings.good_ratio:
        return Verdict("provisional", (f"window error {ratio:.2f}x the noise floor: the model misses a little of the "
                                       f"data (unmodeled dynamics, or parameters moving within the window: {SHORTER})"),
                       determined, cleared)
    return Verdict("good", "", determined, cleared)


def model_source(determined: set, resonance_rel_std: dict, remembered: bool) -> str:
    """Where a compensator's resonance comes from, given the estimate's ``determined`` parameters (alpha and b
    among them), the relative 1-sigma of a1 and a2 and whether a determined resonance was seen before:
    ``"determined"`` (the estimate's own), ``"held"`` (the last determined one), ``"rough"`` (the estimate's own,
    shown by the data at ``ROUGH``), or "" (none yet)."""
    if set(RESONANCE) <= determined:
        return "determined"
    if remembered:
        return "held"
    if all(resonance_rel_std[name] < ROUGH for name in RESONANCE):
        return "rough"
    return ""
