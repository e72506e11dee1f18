"""The window tracker's job queue: when the periodic jobs (re-fit, change-test snapshot) are due, the order
jobs run in, one unit of background work at a time, and the re-fit job itself (started, its slices run by
the per-sample kernel, its result swapped in and what it triggers)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Generator

from .._kernels import fit_machine as RF
from .._kernels import window as W
from .common import MACHINE, MACHINE_REFIT, PERIODIC_JOBS, WAIT

if TYPE_CHECKING:
    from .window import WindowTracker


class Scheduler:
    """The window tracker's scheduling and re-fit jobs (no state of its own: it works on the tracker it is given)."""

    def schedule(self, tr: WindowTracker) -> bool | None:
        """Queue the jobs that are due at this sample and set the next due count. Returns whether the state is
        finite when a change test's snapshot was taken (its kernel checks it, ``fit_machine.snapshot``), else None."""
        n = tr.n
        if n >= tr._next_node_mark and not tr.n_hyst:   # (with hysteresis columns a search starts from the tail)
            tr.replayer.mark_nodes(tr, n)
        due = n >= tr._next_refit
        if due:
            tr._next_refit = n + tr._refit_period
        if due and tr.fitting and not tr._refit_queued:
            tr._refit_queued = True      # (a backlog would only re-fit the same statistics again)
            tr._refit_n = n
            # started by its job's first unit, on a later call: this one has run the sample and Python already
            tr._jobs.append(self.refit_job(tr))
        if tr.detect and n and n % tr.test_every == 0:
            return tr.detection.snapshot(tr, n)       # (it sets the next due count too)
        self.set_due(tr, n)
        return None

    def set_due(self, tr: WindowTracker, n: int) -> None:
        """Set the sample at which the per-sample kernel calls back (``Scheduler.due_after``)."""
        tr.sc[W.SC_DUE] = self.due_after(tr, n)

    def due_after(self, tr: WindowTracker, n: int) -> int:
        """The sample at which the per-sample kernel calls back (``Scheduler.schedule``) after sample n (now): the next re-fit
        or change test. (n passed in: ``tr.n`` reads the state array, each read a numpy call from cold Python.)"""
        return min(tr._next_refit, self.test_after(tr, n)) if tr.detect else tr._next_refit

    def test_after(self, tr: WindowTracker, n: int) -> int:
        """The first change-test (snapshot) instant after sample n."""
        return (n // tr.test_every + 1) * tr.test_every

    def pace_refits(self, tr: WindowTracker, calm: bool) -> None:
        """After a re-fit: double the period while the window is calm, else back to ``refit_every`` (``settings.calm_move``)."""
        period = min(2 * tr._refit_period, max(tr.refit_every, tr.test_every)) if calm else tr.refit_every
        if period != tr._refit_period:
            tr._refit_period = period
            n = tr.n
            tr._next_refit = max(tr._refit_n + period, n + 1)
            self.set_due(tr, n)

    def queued(self, tr: WindowTracker, *names: str) -> bool:
        """Is a job of one of these kinds (generator function names) queued? (A plain loop: a generator
        expression's frame costs a few microseconds from cold Python, at every re-fit and test.)"""
        for job in tr._jobs:
            if job.__name__ in names:
                return True
        return False

    def work(self, tr: WindowTracker, units: int = 1) -> bool:
        """Run up to ``units`` units of the queued jobs in order (each unit a few microseconds).

        Returns False when the job at the head waits for more samples (nothing to do now).
        """
        while units > 0 and tr._jobs:
            if tr.machine is not None:
                return False               # the per-sample kernel runs it (``feed``), or ``finish``
            units -= 1
            job = self.next_job(tr)
            step = next(job, StopIteration)
            if step is StopIteration:
                if job in tr._jobs:
                    tr._jobs.remove(job)
            elif step is WAIT:
                return False
        return True

    def next_job(self, tr: WindowTracker) -> Generator:
        """The periodic short jobs (re-fit, change test) first, then the long ones (replay, search) in order.

        A replay takes seconds of stream time in light units; meanwhile the
        re-fits and change tests keep running on the live statistics (their
        linearization point is a few percent off, which costs accuracy, not
        correctness), instead of waiting behind it.
        """
        for job in tr._jobs:
            if job.__name__ in PERIODIC_JOBS:
                return job
        return tr._jobs[0]

    def finish(self, tr: WindowTracker) -> None:
        """Run the queued jobs to completion, or until the one at the head waits for samples (a checkpoint's
        ``drain``: the jobs' searches run each candidate's rows in one kernel call, ``WindowTracker.eager``)."""
        tr.eager = True
        try:
            while tr._jobs:
                if tr.machine is not None:
                    wk = (tr._wk, tr._test_wk)[tr.machine]
                    RF.run(tr.st, tr.S, tr._shift, tr.theta, wk, tr.basis.lam, tr.basis.dx)
                    tr.machine = None
                elif not self.work(tr, 1 << 30) and tr.machine is None:
                    break
        finally:
            tr.eager = False

    def drain(self, tr: WindowTracker) -> None:
        """Run every queued job to its end now; one that waits for samples goes on with those already here.

        For a checkpoint (pickle, deepcopy: ``checkpoint.Checkpointable``): jobs are generators, which cannot be
        pickled, so none may remain; the original is drained too, and original and copy go on alike."""
        tr._draining = True
        try:
            self.finish(tr)
        finally:
            tr._draining = False

    def refit_job(self, tr: WindowTracker) -> Generator:
        """A re-fit of the window: ``Scheduler.begin_refit``, its slices in the per-sample kernel, then the result swapped in
        (``Scheduler.accept``) and what it triggers (``Scheduler.after_accept``, then ``after_accept_jobs``), each on its own call: with cold caches each of these
        Python visits costs 10-25 us, together they were over 25 us. While it is queued no other is (``Scheduler.schedule``)."""
        try:
            self.begin_refit(tr)
            yield MACHINE
            raw = self.accept(tr)
            if raw is not None:
                yield
                replay_due = self.after_accept(tr, raw)
                yield
                self.after_accept_jobs(tr, raw, replay_due)
        finally:
            tr._refit_queued = False

    def begin_refit(self, tr: WindowTracker) -> None:
        """Start a re-fit (``fit_machine.begin``) and hand it to the per-sample kernel."""
        RF.begin(tr.st, tr.S, tr._shift, tr._wk, tr.window_start, tr.drift_on, tr.converged,
                 tr.refits, tr._alpha_known)
        tr.machine = MACHINE_REFIT

    def accept(self, tr: WindowTracker) -> tuple | None:
        """Swap a finished re-fit in (``fit_machine.accept``, one kernel) and record it; returns its numbers for
        ``Scheduler.after_accept`` (None if it was not swapped in).

        Plain floats from one tuple: numpy from Python is slow here (cold code paths). The ``Fit``
        with its 1-sigma dictionary is built when someone asks for it (``fit``), not in update().
        """
        raw = RF.accept(tr.st, tr.theta, tr._wk, tr.basis.lam, tr.basis.dx)
        verdict, drift, drift_stat, drift_switch = raw[0], raw[8], raw[9], raw[10]
        if drift:
            tr.drift_stat = drift_stat
            if drift_switch:
                tr.drift_on = drift_switch > 0.0
        if verdict == RF.STALE:
            return None                    # re-linearized meanwhile: the next refit decides
        if verdict == RF.REJECTED:
            tr.rejected += 1             # a failed fit is never swapped in
            self.pace_refits(tr, False)
            tr.researcher.watch(tr, math.inf, True, raw[18], raw[19])
            return None
        n = raw[18]
        tr.converged = tr.converged or raw[7] < 0.01
        tr.refits += 1
        tr._fit, tr._fit_raw, tr._fit_sample = None, (raw, tr.drift_on), n
        if tr.n_hyst:                      # (the weights' variances from this fit's covariance: ``hysteresis``)
            RF.weight_variances(tr._wk, tr.p, tr.theta.size, 5 + tr.n_free, tr.hyst_var)
        if tr._first_fit is None:
            tr._first_fit = n
        return raw

    def after_accept(self, tr: WindowTracker, raw: tuple) -> bool:
        """What an accepted re-fit triggers first (on the call after ``Scheduler.accept``): the re-search watch and the
        re-fit pace. Returns whether a replay at the new resonance is due (``after_accept_jobs`` queues it)."""
        (_, _, _, _, _, cost, neff, move, *_, n, noise, relinearize) = raw
        rms = _fit_rms(raw)
        fine = not relinearize and self.fine_relinearization_due(tr, rms, noise, n)
        if not fine:
            tr.researcher.watch(tr, rms, False, n, noise, raw)
        self.pace_refits(tr, tr.converged and move < tr.settings.calm_move and rms <= tr.settings.research.clear_ratio * noise
                          and not (relinearize or fine) and not (tr.events and not tr.events[-1]["settled"]))
        return relinearize or fine

    def after_accept_jobs(self, tr: WindowTracker, raw: tuple, replay_due: bool) -> None:
        """The jobs an accepted re-fit queues (on the call after ``Scheduler.after_accept``: together ~30 us cold in one
        update()): a replay when the resonance left the linearization point or the loop's plays need new thresholds,
        else the settling of a change event."""
        move, noise = raw[7], raw[-2]      # (the fit's largest relative move, the noise level: ``after_accept``)
        if not self.queued(tr, "relinearize_job") and (tr.follow_input_range() | tr.settle_loop(_fit_rms(raw), noise)):
            replay_due = True              # (the plays' thresholds follow the input's range: a replay rebuilds them)
        if replay_due:
            if not self.queued(tr, "relinearize_job"):
                # a settled window whose resonance runs off is what a change looks like: the test due next
                # decides first, and a declared change drops the replay with the old window
                tr._jobs.append(tr.replayer.relinearize_job(tr, None, after_test=tr.settings.replay_after_test and tr.converged
                                                        and tr.detect))
        elif tr.events:
            tr.detection.settle_events(tr, move)

    def fine_relinearization_due(self, tr: WindowTracker, rms: float, noise: float, n: int) -> bool:
        """Replay at the estimate although it is within tr.settings.relinearize of the point? When the converged window
        misfits and a1 or a2 is more than tr.settings.relinearize_fine from the point (``settings.relinearize_fine``); the
        re-search trigger skips that re-fit (a misfit the replay removes is not a wrong basin)."""
        if noise > 0.0 and rms <= tr.settings.research.clear_ratio * noise:     # at the floor: the backoff starts over
            tr._fine_wait = int(tr.settings.fine_wait_s / tr.h)
            return False
        if not (tr.converged and tr.fitting and n >= tr._next_fine and noise > 0.0):
            return False
        if max(abs(tr.a1 / tr.a1l - 1.0), abs(tr.a2 / tr.a2l - 1.0)) <= tr.settings.relinearize_fine:
            return False
        tr._next_fine = n + tr._fine_wait
        tr._fine_wait = min(2 * tr._fine_wait, int(tr.settings.research.max_wait_s / tr.h))
        return True


def _fit_rms(raw: tuple) -> float:
    """An accepted re-fit's rms error (``fit_machine.accept``'s cost over its effective samples)."""
    return math.sqrt(max(raw[5], 0.0) / max(raw[6], 1.0))
