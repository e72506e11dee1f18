"""The window tracker's change detection: snapshots of the statistics at the test instants, the test of
the second before the last against the window's estimate (decided by the settings' ``change_rule``,
``policy.change``), the change events, and the window's restart after a declared change."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Generator

import numpy as np

from .._kernels import fit_machine as RF
from .._kernels import hysteresis as HK
from .._kernels import window as W
from .common import KEPT_SNAPSHOTS, MACHINE, MACHINE_TEST, SNAP_SLOTS, settled_moves

if TYPE_CHECKING:
    from .window import WindowTracker


class ChangeDetection:
    """The window tracker's change test jobs and events (no state of its own: it works on the tracker it is given)."""

    def snapshot(self, tr: WindowTracker, n: int) -> bool:
        """The change test's snapshot of the statistics and the estimate at sample n (now): the copy at this
        instant, the next due count (``Scheduler.set_due``'s) and the state's check in one kernel, its bookkeeping on the
        next call (``ChangeDetection.snapshot_job``; together they were over 25 us). Returns whether the state is finite."""
        index = tr._snap_next
        tr._snap_next = (index + 1) % SNAP_SLOTS
        syy0, g0, finite = RF.snapshot(tr.st, tr.S, tr._ctx, MACHINE_TEST, index, tr.scheduler.due_after(tr, n))
        tr._jobs.append(self.snapshot_job(tr, n, index, syy0, g0, tr.adoptions))
        return finite

    def snapshot_job(self, tr: WindowTracker, n: int, index: int, syy0: float, g0: float, adoptions: int) -> Generator:
        """Record the snapshot taken at sample n (``ChangeDetection.snapshot``) and queue the change test of the second since
        the one before the last. Dropped if the live state was replaced meanwhile (``adoptions`` counts: a replay's
        swap, a restart; ``_adopt`` starts the snapshots afresh; the replays reuse two arrays in turn, so their
        identity would not tell)."""
        if adoptions != tr.adoptions:
            return
        S0, sy0, shift0, theta0 = tr._snap_slots[index]
        tr._snaps.append((n, S0, sy0, syy0, g0, (tr.a1l, tr.a2l), theta0, shift0, index))
        tr._theta_at[n] = theta0         # the estimate at each snapshot instant, the last five
        tr._theta_at.pop(n - 5 * tr.test_every, None)
        if len(tr._theta_at) > 5:        # (an instant without a snapshot: not in a stream fed sample by sample)
            for old in [k for k in tr._theta_at if k < n - 4 * tr.test_every]:
                del tr._theta_at[old]
        if len(tr._snaps) > KEPT_SNAPSHOTS:
            tr._snaps.pop(0)
        if len(tr._snaps) == KEPT_SNAPSHOTS:   # (the oldest is the second before the last)
            tr._jobs.append(self.change_job(tr, tr._snaps[0]))
        yield

    def change_job(self, tr: WindowTracker, snap: tuple) -> Generator:
        """Likelihood-ratio test of the samples since the snapshot against the window's estimate."""
        n0, S0, sy0, syy0, g0, lin0, theta0, shift0, slot = snap
        g = float(tr.sc[W.SC_G])
        if g < g0 or tr._fit_sample < n0 or lin0 != (tr.a1l, tr.a2l) or n0 < tr.window_start \
                or not tr.converged or tr.researcher.researching(tr) or tr.researcher.misfit_from_start(tr):
            return                         # (a misfit being re-searched is not a change of the plant)
        # the drift columns stay in, at the window's rates (the snapshot moved to the live time origin):
        # over a second the drift is not negligible (alpha +0.7 %/s at a 2e-4 noise on a 0.5 output is ~5
        # noise levels), and without it a drifting plant's step looked like a change
        lin = (tr.a1l, tr.a2l)
        wk = tr._test_wk
        free_rates = tr.n_rate > 0 and not tr.drift_on
        RF.queue_test(wk, slot, syy0, free_rates)     # the statistics since the snapshot: the test's first slice
        tr.machine = MACHINE_TEST        # settings.test_steps Levenberg-Marquardt steps, then the covariance, in the
        yield MACHINE                      # per-sample kernel
        # plain floats from here on (numpy from Python is slow here)
        r = RF.TestOutcome._make(RF.test_outcome(wk, tr.theta))
        if not (math.isfinite(r.after) and r.after > 0.0 and math.isfinite(r.before)):
            return
        nr = r.n - n0                      # the rows tested
        sigma2 = r.after / max(nr - 4, 1)
        lr = (r.before - r.after) / sigma2
        # the test is calibrated against its own recent level: a drifting plant (or a model that is
        # slightly off) raises the statistic slowly and evenly, a change makes it jump
        rule = tr.settings.change_rule
        level = rule.level(tr._lr_recent)
        if rule.quiet(lr, level):
            tr.disagreement = None       # the common case, without the dictionaries below (cold Python)
            tr._lr_recent = (tr._lr_recent + [lr])[-rule.history:]
            return
        yield                              # a disagreement: what moved, on the next call (rare, cold Python: with
        # the test's outcome in one call ~30 us)
        moves = {"a1": math.exp(r.ln_a1 - r.live_ln_a1) - 1, "a2": math.exp(r.ln_a2 - r.live_ln_a2) - 1,
                 "b": r.b / r.live_b - 1 if r.live_b else 0.0}
        # relative 1-sigma of the recent fit (ln a1, ln a2 are relative already)
        rel_sd = {"a1": math.sqrt(abs(r.var_ln_a1) * sigma2), "a2": math.sqrt(abs(r.var_ln_a2) * sigma2),
                  "b": math.sqrt(abs(r.var_b) * sigma2) / max(abs(r.b), 1e-300)}
        # significant on the scale the 1-sigma is on (ln a1, ln a2; b relative): for a large move of an
        # undetermined resonance exp(d) - 1 is far larger than d (a flat compensated hold: a2 +232 % against a
        # 40 % 1-sigma passed as 5.9 sigma, it is 3.0 in ln a2, and the window restarted on no change)
        size = {"a1": abs(r.ln_a1 - r.live_ln_a1), "a2": abs(r.ln_a2 - r.live_ln_a2), "b": abs(moves["b"])}
        moved = rule.moved(moves, size, rel_sd)
        if moved:                          # (with the moves above, the checks below were ~26 us cold in one call)
            yield
        if moved and self.misfit_explains(tr, r.before / max(nr, 1)) and self.settled_before(tr, n0, theta0):
            moved = {}                     # (an estimate still settling is corrected, however large the misfit)
        tr.disagreement = {"t": tr.n * tr.h, "lr": float(lr), "moves": {k: float(v) for k, v in moved.items()}} \
            if rule.disagrees(lr, moved) else None
        if not rule.is_change(lr, level, moved) or lin != (tr.a1l, tr.a2l):
            tr._lr_recent = (tr._lr_recent + [float(lr)])[-rule.history:]
            return
        yield                              # the event on the next calls, the restart on the one after (with the
        settled = bool(self.settled_before(tr, n0, theta0))      # test's result all in one call: ~90-130 us; the
        yield                              # settled check and the event together ~30 us)
        last = tr.events[-1] if tr.events else None
        if last is not None and not last["settled"]:
            # the same change seen again from a cleaner window: one event, restarted later
            last["restarts"] += 1
            last["lr"] = max(last["lr"], float(lr))
        else:
            # estimate_settled False: the estimate it was judged against was still moving (a start-up estimate
            # converging): the event may correct the estimate, not the plant
            self.open_event(tr, n0 * tr.h, sorted(moved), moves, lr, theta0, estimate_settled=settled)
        yield
        if settled:
            tr.theta[0] = theta0[0]      # alpha as it was before the change (the refits chased it since)
        self.restart_window(tr, n0, "b" in moved, alpha_known=settled)

    def misfit_explains(self, tr: WindowTracker, second_ms: float) -> bool:
        """Does the window's misfit explain the tested second (``LikelihoodRatioTest.misfit_explains``)? The
        window's mean square error is its last accepted fit's (cost over effective samples). Asked only of a
        settled estimate (``settled_before``): one still settling misfits because it is wrong, not because the
        model class misses the data (a loop being learned: the start's correction restarts the window)."""
        last = tr._fit_raw
        if last is None:
            return False
        raw = last[0]
        return tr.settings.change_rule.misfit_explains(second_ms, raw[5] / max(raw[6], 1.0), tr.noise_level ** 2)

    def open_event(self, tr: WindowTracker, t: float, moved: list[str], moves: dict, lr: float, before: np.ndarray,
                    **extra) -> None:
        """Record a change event, not yet settled (``ChangeDetection.settle_events`` fills in what moved once the fit has stopped
        moving): when it began (t, s) and was detected, the parameters that moved and by how much, its likelihood
        ratio, and the estimate before it (``before[:4]``, copied)."""
        tr.events.append({"t": t, "detected_t": tr.n * tr.h, "moved": moved,
                            "relative_change": {k: float(v) for k, v in moves.items()}, "lr": float(lr),
                            "settled": False, "restarts": 1, "_before": before[:4].copy(), **extra})

    def settled_before(self, tr: WindowTracker, n0: int, theta0: np.ndarray) -> bool:
        """Was the window's estimate settled over the second before the tested one? Only then is its alpha the
        plant's before a declared change, and restored (creep does not jump with a payload or a stiffness);
        otherwise the live alpha stays for the resonance search but is not held afterwards
        (``ChangeDetection.restart_window``'s ``alpha_known``): neither the unsettled estimate's alpha nor the live one is
        known to be the plant's. Settled: the estimate at the previous snapshot instant and at ``n0`` do not
        differ by a move that would itself count as a change (``settings.change_rule.move``, alpha ``settings.research.alpha_move``);
        in the start-up window both must exist; after a restart the post-change estimate counts from its first
        snapshot on.

        (Why not simpler: restoring an unsettled start-up estimate's alpha leaves the post-change search at a
        wrong alpha for good; declaring no change on such a second loses the corrections of a wrong start;
        holding the live alpha, or searching alpha on the short post-correction segment, ends in wrong basins.)
        """
        n_prev = n0 - tr.test_every
        if n_prev < tr.window_start:
            return tr.window_start > 0       # a restarted window: its first seconds are tested
        prev = tr._theta_at.get(n_prev)
        if prev is None or not prev[3]:
            return False
        return (abs(theta0[0] / prev[0] - 1.0) <= tr.settings.research.alpha_move
                and abs(math.exp(theta0[1] - prev[1]) - 1.0) <= tr.settings.change_rule.move["a1"]
                and abs(math.exp(theta0[2] - prev[2]) - 1.0) <= tr.settings.change_rule.move["a2"]
                and abs(theta0[3] / prev[3] - 1.0) <= tr.settings.change_rule.move["b"])

    def restart_window(self, tr: WindowTracker, n0: int, gain_moved: bool, alpha_known: bool = True) -> None:
        """A change happened between sample n0 and now: the window restarts after it.

        The old window's refits are void. The parameters stay until the
        resonance has been searched afresh on post-change samples only
        (``Researcher.research_job``); the test's own fit is linearized around the old
        resonance and unreliable for a large move. ``alpha_known`` False (a start-up estimate corrected,
        ``ChangeDetection.settled_before``): alpha is not held afterwards, and later re-searches free it.
        """
        tr.window_start = self.post_change_start(tr, n0, gain_moved)
        if tr.n_hyst:                      # (the new window may not hold what told the loop's starts apart)
            HK.drop_start(tr.st, tr.lay["hyst"])
        tr._alpha_known = alpha_known
        tr.converged = False
        # a drift the old window modelled goes on through the change (a payload or a resonance change does not stop
        # the ceramic's thermal drift): its rates stay, fitted in the new window from the start (zeroed, a short
        # window without drift misreads alpha and b, and a re-search may then take a candidate without the resonance)
        if not tr.drift_on:
            tr.theta[tr.r0:] = 0.0
        tr._lr_recent = []
        tr._snaps = []
        tr._misfit_since = None
        tr._floor_at = None
        tr._first_fit = None
        tr._research_wait = int(tr.settings.research.after_s / tr.h)
        tr.machine = None
        # the queued jobs are dropped; a re-fit queued but not yet started would otherwise leave its flag set (its
        # ``finally`` never runs) and no re-fit would be queued again
        tr._refit_queued = False
        tr._jobs = [tr.researcher.research_job(tr, tr.window_start)]
        tr.scheduler.pace_refits(tr, False)

    def post_change_start(self, tr: WindowTracker, n0: int, gain_moved: bool) -> int:
        """The first sample known to follow a change that the test saw between n0 and now.

        A change of a1, a2 alone shows only in the transients an input move excites: when the input moved
        inside the test's window, its last move came after the change, and the samples from it on are
        post-change; otherwise only the samples after the detection are (the samples after a detection may
        hold only small steps, which fit a wrong basin at the noise floor). A gain change also moves the output
        during a hold, at any instant of the window, so then only the samples after the detection are (a window
        restarted before it would fit one model across the jump).
        """
        moved = tr.n - 1 - int(tr.sc[W.SC_SINCE])      # the input's last change
        return moved - 1 if moved - 1 > n0 and not gain_moved else tr.n

    def settle_events(self, tr: WindowTracker, move: float) -> None:
        """Once the fit after a change has stopped moving (the last re-fit's largest relative move of
        alpha, ln a1, ln a2, b), mark the event settled with the estimate before and after it; what moved and by
        how much is worked out when the events are read (``report_events``): built here, in update(), that
        bookkeeping was the slowest Python of a cold call (~10-15 us)."""
        ev = tr.events[-1] if tr.events else None
        if ev is None or ev["settled"]:
            return
        if move < 0.002 and tr.n * tr.h - ev["detected_t"] > 1.0:
            ev["_settled_from"] = ev.pop("_before")
            ev["_settled_at"] = tr.theta[:4].tolist()
            ev["settled"] = True
            ev["settled_t"] = tr.n * tr.h

    def report_events(self, tr: WindowTracker) -> list[dict]:
        """The tracker's events as reported: a settled change's relative moves and the parameters that moved beyond
        the change rule's ``move`` filled in (once) from the estimates ``settle_events`` kept."""
        for ev in tr.events:
            if "_settled_at" in ev:
                ev["relative_change"], ev["moved"] = settled_moves(ev.pop("_settled_from"), ev.pop("_settled_at"),
                                                                   tr.settings.change_rule.move)
        return tr.events

