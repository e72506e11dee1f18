"""The trackers' tunables in one frozen, validated object.

``TrackerSettings()`` holds the values the trackers use by default; pass a changed copy
(``dataclasses.replace(TrackerSettings(), change_lr=...)``, or ``TrackerSettings(...)``) to a tracker's
``settings=`` to vary one. Each field says what it controls and why its default is what it is; the
measurements behind the defaults are in the repository's history and bench results.

Times are in seconds, ratios are of the output's noise floor unless a field says otherwise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Mapping

from ..policy.change import GeneralizedLikelihoodRatio, LikelihoodRatioTest
from ..policy.limits import DeterminedLimits
from ..policy.research import ResearchRule


def _determined() -> dict[str, float]:
    return dict(DeterminedLimits().items())     # (the quality rule's limits: one definition)


def _start_sd() -> dict[str, float]:
    return {"alpha": 0.01, "alpha_rel": 0.1, "ln_a": 0.1, "b_rel": 0.1, "offset_rel": 10.0}


def _reset_sd() -> dict[str, float]:
    return {"ln_a": 0.3, "b_rel": 0.3}


@dataclass(frozen=True)
class TrackerSettings:
    """Tunables of the window tracker (``WindowTracker``) and the recursive tracker (``RecursiveTracker``)."""

    # ---------------------------------------------------------------- window tracker: linearization and replay
    #: Relative move of a1 or a2 from the linearization point that triggers a replay of the remembered samples.
    relinearize: float = 0.04
    #: A replay that a converged window's re-fit triggers waits for the change test due next: a settled window
    #: running off is what a change looks like, and a declared change restarts the window (the replay is void).
    replay_after_test: bool = True
    #: While the converged window misfits (above ``misfit_clear_ratio``), a replay at this smaller move: at a
    #: high SNR the expansion's second-order term is itself the misfit on a lightly damped mode.
    relinearize_fine: float = 1e-3
    #: ... rate-limited: the wait starts here (s) and doubles while the misfit stays (up to ``research_max_wait_s``).
    fine_wait_s: float = 1.0
    #: The trust region of the window re-fit in ln a1, ln a2 around the linearization point: the statistics hold
    #: the resonance states only to first order; far from the point the sensitivity columns fit what a
    #: second-order model cannot. Larger: faster re-convergence, worse on close unmodelled modes.
    trust: float = 0.3
    #: Levenberg-Marquardt steps per window re-fit and per change test.
    refit_steps: int = 2
    test_steps: int = 4
    #: A settled re-fit that moved no parameter by more than this (relative) doubles the re-fit period, up to
    #: the change test's; a steady drift is followed with a lag of at most about this move.
    calm_move: float = 1e-3
    #: Multiply-adds in one unit of background work: fewer, larger units lower the p99 of ``update()`` (each
    #: unit's Python costs a few microseconds), smaller ones stretch a replay over more samples.
    unit_macs: int = 80000
    #: A replay swaps in on the unit that catches up with the live stream if that unit replayed at most this many
    #: samples; otherwise on the next unit (a swap and a full unit in one ``update()`` exceed its budget).
    swap_with: int = 4
    #: Remembered samples copied per unit into a search's segment.
    segment_chunk: int = 4096
    #: Samples in a replay's first accumulating unit (the statistics' pages come cold from memory).
    cold_replay_rows: int = 8
    #: The nodes' state is marked this often (s): a search's fast-forward to its segment starts at the newest
    #: mark before it, not at the oldest remembered sample (the history holds several windows; fast-forwarding
    #: all of it spread one search over thousands of ``update()`` calls).
    node_mark_s: float = 0.25

    # ---------------------------------------------------------------- free responses (a stream taken in operation)
    #: Decay rates (1/s) the searches project out: the start-up search's buffer and a re-search's segment.
    free_rates: tuple[float, ...] = (0.03, 0.2, 1.0, 5.0)
    #: The window's free-response columns: the past input's creep is a growing, curved memory; eight rates a
    #: factor ~3 apart fit it to a fraction of the noise over a 10 s window.
    window_free_rates: tuple[float, ...] = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0)
    #: ... of which these are fitted from the start; the others once a score test finds them needed
    #: (``wide_on``: chi-square with 4 degrees of freedom, p ~ 1e-6).
    window_free_start: tuple[float, ...] = (0.03, 0.3, 1.0, 3.0)
    wide_on: float = 30.0

    # ---------------------------------------------------------------- change detection (window tracker)
    #: The window tracker's change detector (``policy.change``; any ``ChangeRule`` with ``quiet`` and
    #: ``disagrees``, as ``LikelihoodRatioTest``).
    change_rule: LikelihoodRatioTest = field(default_factory=LikelihoodRatioTest)
    #: After a detected change alpha is held this long (s): the new window is too short to determine it, and
    #: creep does not jump with a payload or a stiffness change.
    alpha_hold_s: float = 2.0

    # ---------------------------------------------------------------- drift columns
    #: The drift rates enter the fit when they would lower the window cost by this many noise variances (score
    #: test, chi-square with 2 degrees of freedom, p ~ 4e-6) and leave when their Wald statistic falls below
    #: ``drift_off``. Where the data cannot tell drift from creep the rates stay out.
    drift_on: float = 25.0
    drift_off: float = 9.0
    #: The score test waits until the window is converged and spans this long (s).
    drift_min_s: float = 1.0
    #: While the rates are off, the score test runs at every this-many-th re-fit (it costs two units).
    drift_test_every: int = 5
    #: Largest plausible drift relative to the parameter (1/s): faster "drift" is misfit (the rates go off).
    drift_max: float = 0.02

    # ---------------------------------------------------------------- misfit watch and re-search
    #: When and how the resonance is searched again (``policy.research``).
    research: ResearchRule = field(default_factory=ResearchRule)
    #: Relative 1-sigma limits for "determined" parameters (half the accuracy goals): the estimate's
    #: ``determined`` and "good", and the sudden misfit's condition.
    determined: Mapping[str, float] = field(default_factory=_determined)
    #: Post-change samples the resonance search waits for (s, counted from the input's last move inside the
    #: change test's window): one step's transients and its creep.
    research_s: float = 0.5
    #: Post-change searches at most: ``research_s`` of samples, then twice as many while the result misfits.
    research_passes: int = 3
    #: Longest segment a re-search takes (s): its model has constant parameters, and on a drifting plant a
    #: long segment lets a gain drift pass for creep.
    research_segment_s: float = 2.0
    #: While the window models a drift, a re-search's candidates are judged with these slow free responses
    #: (1/s) projected out: a drift's trend over the segment is not the resonance's to explain.
    research_trends: tuple[float, ...] = (0.03, 0.2)
    #: Resonances the window fit may reach: fn <= this fraction of the sampling rate (beyond, the regressor's
    #: coefficients overflow).
    fn_max_fs: float = 0.45

    # ---------------------------------------------------------------- recursive tracker
    #: The recursive tracker's change detector (its decision runs inside the numba kernel).
    recursive_change: GeneralizedLikelihoodRatio = field(default_factory=GeneralizedLikelihoodRatio)
    #: Refresh check period (s) of the linearization point, and its tolerances (alpha absolute; ln a1, ln a2
    #: and b relative): below them the first-order update of the coefficients is exact to ~1e-4 of the output.
    refresh_s: float = 1e-3
    tol_alpha: float = 1e-3
    tol_ln: float = 5e-3
    #: A detection within this long (s) of the last one (or of its restart) restarts that event.
    merge_s: float = 5.0
    #: Prior 1-sigma at the start (from the search): alpha (absolute, plus a share of alpha), ln a1 and ln a2,
    #: b (relative), offset and free responses (relative to the output's span).
    start_sd: Mapping[str, float] = field(default_factory=_start_sd)
    #: ... and in the directions that jumped after a detected change.
    reset_sd: Mapping[str, float] = field(default_factory=_reset_sd)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or f.name in ("change_rule", "recursive_change", "research"):
                continue
            if isinstance(value, (int, float)):
                if math.isnan(value) or value <= 0 or math.isinf(value):
                    raise ValueError(f"TrackerSettings.{f.name} must be a positive finite number, got {value!r}")
                if f.type == "int" and not isinstance(value, int):
                    raise ValueError(f"TrackerSettings.{f.name} must be an integer, got {value!r}")
            elif isinstance(value, tuple):
                if not value or not all(isinstance(v, (int, float)) and v > 0 for v in value):
                    raise ValueError(f"TrackerSettings.{f.name} must be a non-empty tuple of positive rates")
            elif isinstance(value, Mapping):
                if not all(isinstance(v, (int, float)) and v > 0 for v in value.values()):
                    raise ValueError(f"TrackerSettings.{f.name} must map names to positive numbers")
        if not set(self.window_free_start) <= set(self.window_free_rates):
            raise ValueError("TrackerSettings.window_free_start must be a subset of window_free_rates")
        if self.drift_off >= self.drift_on:
            raise ValueError("TrackerSettings.drift_off must be below drift_on (the test's hysteresis)")
        if set(self.determined) != {"alpha", "b", "a1", "a2"}:
            raise ValueError("TrackerSettings.determined must give a limit for alpha, b, a1 and a2")
        if not self.fn_max_fs < 0.5:
            raise ValueError("TrackerSettings.fn_max_fs must be below the Nyquist frequency (0.5)")


#: The defaults (what a tracker built without ``settings=`` uses).
DEFAULT = TrackerSettings()
