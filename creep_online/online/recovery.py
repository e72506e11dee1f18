"""Internal faults and long outages: counted, recorded, recovered from; never raised into the caller's loop.

The error contract (docs/online.md): bad input raises ``DataError``; any other exception inside ``update()``,
``update_block()`` or ``gap()`` is the library's own fault (a numerical bug), and so is a non-finite estimate or
statistic found at a scheduled check. ``Recovery.fault`` counts it (``internal_faults``), records it as an event of
kind ``"internal_fault"`` and recovers (``recover``):

* a fault while the estimate was read: nothing to repair (a read never changes the estimator: what it finds is
  recorded, and a non-finite state recovered from, at the next sample fed: ``defer``, ``settle_pending``);
* during the start-up (search, tracker start, replay of the buffer): the search again; after
  ``recovery.startup_faults`` in a row, on new samples (``restart_startup``);
* a live tracker with a finite state whose fault ended a periodic job (re-fit, snapshot, change test): the job is
  dropped, the next one is scheduled as usual;
* otherwise (a non-finite state, a fault in the per-sample kernel or a long job): the tracker is dropped and the
  estimator restarts from a search of the samples the tracker remembers (``restart``);
* if the recovery itself fails: a fresh estimator, the fault record and counters kept (``start_over``).

Until the estimator has re-converged the quality reads ``degraded`` with the fault as reason
(``online/policy/quality.py``). A run of lost samples longer than ``recovery.gap_replay_max`` restarts the tracker
in constant time (``outage``). Thresholds: ``OnlineSettings.recovery``.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

from ..errors import DataError, one_line
from .policy.quality import FaultView, fault_reason
from .report import bare_estimate, build_estimate, shifted

if TYPE_CHECKING:
    from .estimator import OnlineEstimator

#: Exceptions the error contract lets through to the caller: the caller's own errors (bad input: a one-line
#: ``DataError``) and exhaustion of memory. Every other exception is an internal fault.
PASS_THROUGH = (DataError, MemoryError)
#: What a non-finite state is recorded as.
NON_FINITE = ("NonFiniteState", "non-finite estimate, statistics or prediction")
#: The recovery of a fault while the estimate was read with a finite state.
READ_ONLY = "estimate reported without the model's details"


class Recovery:
    """The fault record and the recoveries of one estimator (``est``: the stream's shared state)."""

    def __init__(self, est: "OnlineEstimator") -> None:
        self.est = est
        self.cfg = est._settings.recovery
        self.faults: list[dict] = []       # the internal-fault events, the newest ``max_fault_events``
        self.open: dict | None = None      # the last fault while the estimator re-converges
        self.fit_after = 0                 # ... a window fit after this tracker sample is one after the recovery
        self.startup_faults = 0            # consecutive faults of the start-up
        self.kept = None                   # the estimate before a long outage (``outage``), until live again
        self.past_events: list[dict] = []      # events and re-searches of trackers a restart dropped, in stream time
        self.past_researches: list[dict] = []
        self.block_progress: tuple | None = None   # update_block()'s tracker loop (``block_resync``)
        #: a fault a read of the estimate found, recorded at the next sample fed: (non-finite, error, message)
        self.pending: tuple[bool, str, str] | None = None

    # ------------------------------------------------------------------ recording
    def fault(self, exc: BaseException | None, where: str) -> None:
        """An internal fault in ``where`` (``exc``; None: a non-finite state found): counted, recorded as an event,
        recovered from. Never raises but ``PASS_THROUGH``."""
        error, message = NON_FINITE if exc is None else (type(exc).__name__, one_line(exc))
        self.record(exc is None, error, message, where)

    def record(self, nonfinite: bool, error: str, message: str, where: str) -> None:
        """``fault``'s work, the fault named by ``error`` and ``message``. If the recovery itself fails, the estimator
        starts over from nothing (``start_over``), its counters and events kept."""
        est = self.est
        est.internal_faults += 1
        self.block_resync()
        try:
            recovery = self.recover(nonfinite, where)
        except PASS_THROUGH:
            raise
        except Exception as again:  # noqa: BLE001 - the recovery's own fault: the last resort
            recovery = self.start_over(again)
        t = est.samples * est._h
        event = {"kind": "internal_fault", "t": t, "detected_t": t, "where": where, "error": error,
                 "message": message, "recovery": recovery, "moved": [], "relative_change": {}, "settled": True}
        rec = est._recovery                # (a new one after ``start_over``)
        rec.faults = (rec.faults + [event])[-rec.cfg.max_fault_events:]
        rec.open = event

    def defer(self, exc: BaseException | None):
        """A read of the estimate found a fault (``exc``; None: a non-finite state): the bare estimate, degraded with
        the fault named; the fault is recorded, and recovered from, at the next sample fed (``settle_pending``)."""
        est = self.est
        error, message = NON_FINITE if exc is None else (type(exc).__name__, one_line(exc))
        if self.pending is None:
            self.pending = (exc is None, error, message)
            est._deferred = True           # (update()'s slow path settles it)
        nonfinite = self.pending[0]
        fault = FaultView(t=est.samples * est._h, error=error, where="estimate", message=message,
                          recovery="recovering at the next sample" if nonfinite else READ_ONLY, fit_after=0)
        return bare_estimate(est, *fault_reason(fault))

    def settle_pending(self) -> None:
        """Record (and recover from) the fault a read of the estimate found, before the next sample is fed."""
        est = self.est
        nonfinite, error, message = self.pending
        self.pending = None
        est._deferred = bool(est._held or est._backlog)
        self.record(nonfinite, error, message, "estimate")

    def view(self) -> FaultView | None:
        """The open fault for the quality rule."""
        ev = self.open
        if ev is None:
            return None
        return FaultView(t=ev["t"], error=ev["error"], where=ev["where"], message=ev["message"],
                         recovery=ev["recovery"], fit_after=self.fit_after)

    def went_live(self) -> None:
        """The tracker is live: the start-up's faults are over, the estimate kept over an outage is replaced."""
        self.kept = None
        self.startup_faults = 0

    # ------------------------------------------------------------------ recovering
    def block_resync(self) -> None:
        """After a fault inside update_block()'s tracker loop: ``samples`` and the block's position from the
        tracker's own count (its kernel moves it per sample taken), so no sample is lost or fed twice."""
        est = self.est
        progress, self.block_progress = self.block_progress, None
        if progress is None:
            return
        tr, n0, s0, i, done, classified = progress
        try:
            taken = tr.n - n0
        except (TypeError, ValueError, OverflowError):     # (a non-finite count: the position stays)
            return
        if classified is None:
            est.samples = s0 + taken
            done[0] = i + taken
            return
        du, yy, n = classified           # all of the block was taken: what the tracker has not, waits
        est._backlog.extendleft(reversed(list(zip(du[taken:].tolist(), yy[taken:].tolist()))))
        est._deferred = bool(est._held or est._backlog)
        est.samples = s0 + (n - i)
        done[0] = n

    def recover(self, nonfinite: bool, where: str) -> str:
        """Back to a safe state (module docstring); returns what was done (the event's ``recovery``)."""
        est = self.est
        tr = est._tracker
        if where == "estimate" and not nonfinite:
            return READ_ONLY
        if tr is None or est._startup.starting is not None or est._catchup:
            return self.restart_startup()
        if nonfinite or not tr.state_finite():
            return self.restart()
        dropped = tr.drop_failed_jobs()
        if dropped:
            self.fit_after = tr.n
            return "dropped the " + ", ".join(dropped)
        return self.restart()

    def restart_startup(self) -> str:
        """A fault before the tracker went live: the search starts again on the buffered samples; after
        ``startup_faults`` in a row, on new ones (the buffer dropped; the plant is then not at rest)."""
        est = self.est
        self.startup_faults += 1
        self.drop_tracker()
        self.fit_after = 0
        if self.startup_faults < self.cfg.startup_faults and not est._startup.competing:   # (between two frames)
            return "the start-up search starts again on the buffered samples"
        est._startup.restart_empty()
        est._n_shift = est.samples
        self.startup_faults = 0
        return (f"the start-up buffer dropped after {self.cfg.startup_faults} faults: the search starts again on "
                "new samples")

    def restart(self) -> str:
        """The tracker is not trustworthy: dropped, and the newest remembered samples of its window (up to the
        search's ``max_search_samples``) become the start-up buffer of a stream in operation: a fresh search, a
        fresh tracker, the replay of the buffer. A tracker that remembers no samples starts from new ones."""
        est = self.est
        st = est._startup
        tr = est._tracker
        self.keep_hint(tr)                 # the estimate before the fault competes in the new search
        k = min(tr.remembered_window, st.cfg.max_search_samples)
        if k:
            tr.copy_recent(st.bu[:k], st.by[:k])
        self.drop_tracker()
        st.restart_on(k)
        est._n_shift = est.samples - k
        self.fit_after = 0
        return (f"tracker restarted: a new search on the {k} remembered samples ({k * est._h:.3g} s)" if k else
                "tracker restarted: a new search on new samples")

    def keep_hint(self, tr) -> None:
        """The tracker's estimate as a candidate of the next search, if it is a model."""
        hint = (tr.alpha, tr.a1, tr.a2)
        if all(math.isfinite(v) for v in hint) and hint[1] > 0.0 and hint[2] > 0.0:
            self.est._startup.hint = hint

    def drop_tracker(self) -> None:
        """Forget the tracker and any start-up under way (their events and re-searches kept, in stream time)."""
        est = self.est
        tr, est._tracker = est._tracker, None
        if tr is not None:
            shift = est._n_shift * est._h
            self.past_events += [shifted(ev, shift, "change") for ev in tr.report_events()]
            self.past_researches = (self.past_researches
                                    + [shifted(r, shift) for r in tr.researches])[-self.cfg.max_past_researches:]
        st = est._startup
        st.starting = None
        st.search = None
        st.grid_plan = None
        est._catchup = 0
        est._phase = "buffering"

    def start_over(self, again: BaseException) -> str:
        """The last resort when a recovery itself fails: ``reset()``, the fault record and counters kept."""
        est = self.est
        keep = (est.samples, est.skipped_nonfinite, est.gaps, est.input_outliers, est.internal_faults,
                self.faults, self.past_events, self.past_researches)
        est.reset()
        rec = est._recovery
        (est.samples, est.skipped_nonfinite, est.gaps, est.input_outliers, est.internal_faults,
         rec.faults, rec.past_events, rec.past_researches) = keep
        est._n_shift = est.samples
        return f"the recovery failed ({type(again).__name__}: {one_line(again)}): started over from nothing"

    def outage(self, n: int) -> None:
        """A stretch of ``n`` > ``gap_replay_max`` lost samples: a restart, not a replay (work independent of n).

        The plant's state after a long outage is unknown, so the tracker is dropped and the search starts again
        on new samples, in operation, with the estimate before the outage as a candidate; until the new tracker
        is live that estimate is reported (quality provisional, the reason says why)."""
        est = self.est
        st = est._startup
        est.gaps += n
        est.samples += n
        est._inputs.forget_held()
        kept = build_estimate(est) if est._tracker is not None and est._phase == "tracking" else self.kept
        tr = est._tracker
        if tr is not None:
            self.keep_hint(tr)
        self.drop_tracker()
        st.restarted = st.restarted or st.first_change is not None or tr is not None
        st.nbuf = 0
        st.first_change = None
        est._n_shift = est.samples
        self.startup_faults = 0
        if kept is not None:
            why = (f"restarting after {n} lost samples ({n * est._h:.3g} s): the estimate before the outage, "
                   f"until the search on new samples ends")
            self.kept = replace(kept, quality="provisional" if kept.quality != "none" else "none", reason=why,
                                determined=[])
