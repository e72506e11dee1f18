"""The window tracker's searches of the resonance: after a declared change (on post-change samples), and
when the window misfits (the re-search trigger, ``policy.research``): the search on remembered samples,
the live estimate competing, and the switch when the result is clearly better."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Generator

from .._kernels import fit_machine as RF
from .._kernels import window as W
from ..policy.research import likelihood_ratio as _likelihood_ratio
from ..search import ResonanceSearch
from .common import WAIT, Fit
from . import workspace as WS

if TYPE_CHECKING:
    from .window import WindowTracker


class Researcher:
    """The window tracker's re-search watch and jobs (no state of its own: it works on the tracker it is given)."""

    def research_job(self, tr: WindowTracker, n_from: int) -> Generator:
        """Wait for post-change samples, search the resonance on them, rebuild the window there. Alpha is held (creep
        does not jump) unless the change corrected a start-up estimate that had not settled (``_alpha_known``
        False): that alpha is no plant's, and held it kept two plants resting on a branch at 2.7x and 6.8x the
        noise floor; freed, the live alpha joins the grid's exponents.

        Samples from ``n_from`` on are all post-change (``ChangeDetection.post_change_start``): the search gets
        ``settings.research_s`` seconds of them (longer if the input has not moved), starting from the exact node
        state; before an input move inside the test's window, the hold before it settles the resonance
        states (the search's lead).
        """
        tr.fitting = False
        n_detect = tr.n
        cap = min(tr.ring.shape[1] // 2, 1 << 15 if tr.work_memory is None else tr.work_memory.shape[0])
        settle = WS.settling_samples(tr, tr.a1, tr.a2)      # of the old resonance
        # at least one settling time, at most what the search holds: the old resonance may be a wrong one (a
        # 0.27 Hz, zeta 0.005 estimate set a wait of 437 s, and the window stopped fitting for good)
        wait = min(max(int(tr.settings.research_s / tr.h), settle // 2), cap)
        while not tr._draining and (tr.n < n_from + wait
                                      or (not self.input_moved(tr, n_from) and tr.n < n_from + 3 * wait)):
            yield WAIT
        oldest = int(tr.sc[W.SC_RSTART])
        n0 = max(n_from - settle if n_from < n_detect else n_from, oldest)
        zeta0 = yield from tr.replayer.nodes_at(tr, n0)
        yield                              # (the fast-forward's end and the segment's first copy: 26-27 us cold)
        search: ResonanceSearch | None = None
        seg = 0
        for _ in range(tr.settings.research_passes):
            starts = None
            if search is not None:         # another pass on twice the samples, from the last one's basins
                while not tr._draining and tr.n < n0 + min(2 * seg, cap):
                    yield WAIT
                starts = [c[1:] for c in search.candidates]
            u, y = yield from tr.replayer.ring_segment(tr, n0, min(tr.n, n0 + cap))
            yield                          # (the segment's last copy and the search's construction: 24-25 us cold)
            seg = u.size
            lead = n_from - n0 if n_from < n_detect else min(settle, u.size // 4)
            # the live estimate competes with the grid: the window re-fits often follow a change
            # before the test confirms it, and the grid's best basin can be a wrong one
            search = ResonanceSearch(tr.basis, u, y, zeta0=zeta0, lead=lead,
                                     fixed_alpha=tr.alpha if tr._alpha_known else None, alphas=(tr.alpha,),
                                     work=tr.work_memory, extra=((tr.alpha, tr.a1, tr.a2),),
                                     starts=starts, scratch=tr._search_scratch)
            yield
            yield from run_search(search, tr)
            # each pass's result is reported as soon as it is clearly better than the live estimate; a
            # longer pass may still replace it (at 80 dB the first pass's own cost, the resonance at rest
            # at the segment's start, sat at 1.5-2x the floor with the right resonance, and the estimate
            # waited ~1.6 s for the third)
            took = yield from self.take_if_better(tr, search)
            # (with a shortened lead the misfit may be the unknown resonance state at the segment's start)
            if self.resolved(tr, search) or u.size >= cap or lead < settle:
                break
            if took and not tr.predicts_estimate():
                # another pass waits for twice the samples (up to ~2 s): predict with the result meanwhile (the
                # old resonance's ringing, out of phase after a payload change, missed each step by the step's
                # own spread until the last pass's replay)
                yield from tr.replayer.relinearize_job(tr, max(n_from, oldest))
        # re-fits wait for the replay from the change: until it is swapped in, the live statistics
        # still hold the pre-change window, and a fit of them would report a second change
        yield from tr.replayer.relinearize_job(tr, max(n_from, oldest))
        tr.fitting = True

    def take_if_better(self, tr: WindowTracker, search: ResonanceSearch) -> Generator[object, None, bool]:
        """The post-change search's result replaces the estimate when clearly better on its segment (both judged
        with the resonance state at the segment's start unknown, as a re-search): where every candidate fits at
        the noise floor (one small step) the re-fits do better from the estimate. Returns whether it did."""
        r = search.result
        if r is None or not (math.isfinite(r.cost) and r.a1 > 0 and r.a2 > 0 and r.b != 0):
            return False
        if not self.agrees_with_change(tr, r.b):
            return False
        yield                              # (the search's last unit ended this call)
        c_live = yield from search.judged_cost(tr.alpha, tr.a1, tr.a2, tr._free_decays)
        c_new = yield from search.judged_cost(r.alpha, r.a1, r.a2, tr._free_decays)
        rows = search.judged_rows()
        yield
        if _likelihood_ratio(rows, c_live, c_new) > tr.settings.research.lr and not search.at_bound(r):
            tr.theta[1:4] = (math.log(r.a1), math.log(r.a2), r.b)
            tr._take_resonance()
            yield
            return True
        return False

    def agrees_with_change(self, tr: WindowTracker, b: float) -> bool:
        """Does a post-change search's gain ``b`` agree with the change the test declared, from the gain before it
        (``policy.research.ResearchRule.agrees_with_change``)?"""
        event = tr.events[-1] if tr.events else None
        before = float(event["_before"][3]) if event is not None and "_before" in event else 0.0
        if not before:
            return True
        declared, move = event["relative_change"], tr.settings.change_rule.move
        resonance_moved = abs(declared.get("a1", 0.0)) > move["a1"] or abs(declared.get("a2", 0.0)) > move["a2"]
        return tr.settings.research.agrees_with_change(b / before - 1.0, declared["b"], move["b"], resonance_moved)

    def misfit_from_start(self, tr: WindowTracker) -> bool:
        """Has the window misfit (``Researcher.watch``) since its first re-fit? Then its estimate was wrong, not the plant
        changed: the re-search trigger goes first (a start-up search in a wrong basin is not a plant change)."""
        return tr._misfit_since is not None and tr._first_fit is not None and tr._misfit_since <= tr._first_fit

    def researching(self, tr: WindowTracker) -> bool:
        """Is a search of the resonance queued (after a change, or by the re-search trigger)?"""
        return tr.scheduler.queued(tr, "research_job", "research_again_job")

    def resolved(self, tr: WindowTracker, search: ResonanceSearch) -> bool:
        """Does the post-change search's result fit its samples near the noise floor? If not, the segment
        carries too little information (a single small input step) or a transient: search a longer one.
        (Not also while another basin's candidate is close in likelihood: on a well damped mode neighbouring
        candidates are one broad valley the re-fits settle, and extra passes only delay re-convergence.)
        """
        noise = float(tr.sc[W.SC_NOISE])
        return search.result.cost <= (tr.settings.research.ratio * noise) ** 2

    def resonance_determined(self, tr: WindowTracker, raw: tuple) -> bool:
        """Did an accepted re-fit (``fit_machine.accept``'s tuple) determine alpha, a1 and a2 (``settings.determined``)?"""
        r = RF.Accepted._make(raw)
        sigma2 = WS.noise_variance(tr, r)
        return (abs(r.var_alpha) * sigma2 <= (tr.settings.determined["alpha"] * r.alpha) ** 2
                and abs(r.var_ln_a1) * sigma2 <= tr.settings.determined["a1"] ** 2
                and abs(r.var_ln_a2) * sigma2 <= tr.settings.determined["a2"] ** 2)

    def sudden_misfit(self, tr: WindowTracker) -> bool:
        """Did the current misfit run come suddenly (``settings.research.sudden_ratio``) after a window at the floor whose
        fit determined the resonance and alpha? (The plant changed before the re-fit that saw it.)"""
        return tr._misfit_sudden and self.resonance_determined(tr, tr._misfit_floor_raw)

    def watch(self, tr: WindowTracker, rms: float, broken: bool, n: int, floor: float, raw: tuple | None = None) -> None:
        """After each re-fit (at sample n; the output's noise level ``floor``; ``raw`` the accepted fit's tuple):
        start a re-search once the error has sat above the noise floor (or the fit has been broken) for
        ``settings.research.after_s``, and note the last converged fit at the floor (``settings.research.sudden_ratio``)
        (plain floats: runs at every re-fit)."""
        if not tr.fitting or self.researching(tr):
            return
        rule = tr.settings.research
        if not (broken or rule.misfits(rms, floor)):
            if rule.clears(rms, floor):
                tr._misfit_since = None
                if tr.converged and raw is not None:
                    tr._floor_at, tr._floor_raw = n, raw     # (judged at a misfit's onset only: rare)
            return
        if tr._misfit_since is None:
            tr._misfit_since = n
            # (whether that floor's fit determined the resonance is asked by the re-search, ``sudden_misfit``: judged
            # here, in the re-fit's call, it was ~30 us cold)
            tr._misfit_sudden = not broken and tr._floor_at is not None \
                and rule.sudden(rms, floor, n - tr._floor_at, int(rule.sudden_within_s / tr.h))
            tr._misfit_floor_raw = tr._floor_raw
        span = int(rule.after_s / tr.h)
        if n - tr._misfit_since >= span and n - tr.window_start >= span and n >= tr._next_research:
            reason = "fit broken" if broken else f"window error {rms / floor:.1f}x the noise floor"
            gross = rule.gross(rms, floor, broken)
            tr._jobs.append(self.research_again_job(tr, reason, gross))

    def research_again_job(self, tr: WindowTracker, reason: str, gross: bool = False) -> Generator:
        """Search the resonance (and alpha, unless it is held after a change) on the recent samples with the
        live estimate competing; switch to the result only if its likelihood ratio says it is clearly better.
        ``gross``: the live estimate misfits grossly (``settings.research.gross_misfit``), so its gain's sign is no reference.

        The samples: those since the window start that the ring and the search's work memory hold (the
        newest ones). Both candidates are judged by the same exact projected cost on them.
        """
        n1 = tr.n
        cap = min(tr.work_memory.shape[0] if tr.work_memory is not None else 1 << 15,
                  int(tr.settings.research_segment_s / tr.h))
        # a sudden misfit: the plant changed before the re-fit that saw it, so only the samples since are searched
        suspect = tr._misfit_since if tr._misfit_since is not None and self.sudden_misfit(tr) else None
        yield                              # (with the fast-forward's set-up below: ~30 us cold in one update())
        n0 = max(tr.window_start, int(tr.sc[W.SC_RSTART]), n1 - cap, suspect or 0)
        zeta0 = yield from tr.replayer.nodes_at(tr, n0)
        u, y = yield from tr.replayer.ring_segment(tr, n0, n1)
        lead = min(WS.settling_samples(tr, tr.a1, tr.a2), u.size // 4)
        drifting = tr.drift_on and not tr._free_decays
        trends = tr._free_decays or (tr.settings.research_trends if drifting else ())
        # after a change alpha was determined before it (creep does not jump): the resonance only, 7x cheaper;
        # in operation the candidates are ranked with the unknown start projected out, as they are judged (a cost
        # from rest would rank them by the past input's fading memory)
        search = ResonanceSearch(tr.basis, u, y, zeta0=zeta0, lead=lead, work=tr.work_memory,
                                 fixed_alpha=tr.alpha if (tr.window_start and tr._alpha_known) or suspect
                                 else None,
                                 alphas=(tr.alpha,),
                                 extra=((tr.alpha, tr.a1, tr.a2),), scratch=tr._search_scratch,
                                 free=trends or None)
        yield
        yield from run_search(search, tr)
        yield                              # (the search's last unit ended this call)
        r = search.result
        live = (tr.alpha, tr.a1, tr.a2)
        # both judged with the resonance state at the segment's start unknown (``judged_cost``), trends out
        c_live = yield from search.judged_cost(*live, trends)
        c_new = yield from search.judged_cost(r.alpha, r.a1, r.a2, trends)
        rows = search.judged_rows()
        yield
        lr = _likelihood_ratio(rows, c_live, c_new)
        change = {"alpha": r.alpha / live[0] - 1, "a1": r.a1 / live[1] - 1, "a2": r.a2 / live[2] - 1,
                  "b": r.b / tr.b - 1 if tr.b else 0.0}
        rule = tr.settings.research
        moved = rule.moved(change, tr.settings.change_rule.move)
        gain_ratio = r.b / tr.b if tr.b else 0.0
        # a candidate on the search box's edge is the box's, not the data's (its free responses, projected out by
        # the judge, can fit a segment's sinusoids)
        switch = rule.switch(lr, moved, r.cost, gain_ratio, gross, drifting, change["alpha"]) and not search.at_bound(r)
        tr.researches = (tr.researches + [{
            "t": n1 * tr.h, "done_t": tr.n * tr.h, "reason": reason, "segment_s": (n1 - n0) * tr.h,
            "lr": float(lr), "switched": switch, "moved": moved if switch else [],
            "relative_change": {k: float(v) for k, v in change.items()}}])[-50:]
        tr._misfit_since = None
        if switch and suspect is not None:
            yield
            yield from self.declare_found_change(tr, suspect, r, change, moved, lr)
            return
        if not switch:                     # the data cannot do better here: search less often
            tr._next_research = tr.n + tr._research_wait
            tr._research_wait = min(2 * tr._research_wait, int(tr.settings.research.max_wait_s / tr.h))
            return
        tr._research_wait = int(tr.settings.research.after_s / tr.h)
        tr.scheduler.pace_refits(tr, False)
        tr.theta[0:4] = (r.alpha, math.log(r.a1), math.log(r.a2), r.b)
        # the drift rates stay: no change of the plant was declared, and a drifting window fitted without them
        # misfits grossly, and the re-fits would then pull alpha and b
        tr._take_resonance()
        tr.converged = False
        tr._lr_recent = []
        tr.fit = Fit(theta=tr.theta.copy())   # quality: "first window fit pending" until the next re-fit
        tr._first_fit = None
        tr.fitting = False               # the old statistics belong to the old resonance: rebuild first
        yield
        yield from tr.replayer.relinearize_job(tr, None)
        tr.fitting = True

    def declare_found_change(self, tr: WindowTracker, n_seen: int, r, change: dict, moved: list[str], lr: float) -> Generator:
        """A sudden misfit's re-search found the plant changed (``settings.research.sudden_ratio``): a change event as the change
        test's (its time the last re-fit at the noise floor: the change came after it), the search's resonance
        and gain taken, and the window restarted after the re-fit that saw the misfit, as for a change the test
        found (``ChangeDetection.restart_window``: the post-change search, with this result competing, then the replay)."""
        t_floor = (tr._floor_at if tr._floor_at is not None else n_seen) * tr.h
        tr.detection.open_event(tr, t_floor, moved, change, lr, tr.theta, estimate_settled=True, found_by="re-search")
        yield                              # (each part on its own call, as the change test's: cold Python)
        tr.theta[1:4] = (math.log(r.a1), math.log(r.a2), r.b)
        tr._take_resonance()
        yield
        tr.detection.restart_window(tr, n_seen, abs(change["b"]) > tr.settings.change_rule.move["b"], alpha_known=True)

    def input_moved(self, tr: WindowTracker, since: int) -> bool:
        """Did the input change after sample ``since`` (is there something to fit)? O(1): the kernel
        counts the samples since the last input change."""
        return tr.n - tr.sc[W.SC_SINCE] > since + 1


def run_search(search: ResonanceSearch, tr: WindowTracker) -> Generator:
    """A search to its result, one ``ResonanceSearch.step`` per unit of background work (in block mode each
    candidate's rows in one unit: ``WindowTracker.eager``)."""
    while True:
        search.eager = tr.eager
        if search.step():
            return
        yield
