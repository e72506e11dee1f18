"""The window tracker's replays: the remembered samples run again into fresh statistics at a new
linearization point (swapped in whole once caught up), the node state fast-forwarded to a remembered
sample, and copies of a stretch of remembered samples for a search."""
from __future__ import annotations

from typing import TYPE_CHECKING, Generator

import numpy as np

from .._kernels import hysteresis as HK
from .._kernels import window as W
from .common import KEPT_SNAPSHOTS, MACHINE_TEST, WAIT
from . import workspace as WS

if TYPE_CHECKING:
    from .window import WindowTracker


class Replayer:
    """The window tracker's replay jobs (no state of its own: it works on the tracker it is given)."""

    def arrays(self, tr: WindowTracker, a1l: float, a2l: float) -> tuple:
        """``workspace.fresh`` state and statistics for a replay, with their views, in the spare pair (the one the last swap
        retired, or made and touched at construction). One replay runs at a time (the long jobs run in order, and a
        replay dropped by a restart never resumes), so the next replay may take the pair again. In new arrays the
        replay's first accumulating unit wrote the statistics' pages for the first time: 60-65 us of page faults in
        one update() (the statistics are p x p, ~28 kB at p = 59)."""
        st, S, views = tr._spare
        WS.fresh(tr, a1l, a2l, (st, S))
        return st, S, views

    def relinearize_job(self, tr: WindowTracker, start: int | None, after_test: bool = False) -> Generator:
        """Replay the remembered samples (from ``start``, default the oldest) for the current resonance.

        ``after_test``: first wait for the change test due next to finish (``settings.replay_after_test``).
        """
        if after_test:
            due = tr.scheduler.test_after(tr, tr.n)
            while not tr._draining and (tr.n <= due or tr.machine == MACHINE_TEST
                                          or tr.scheduler.queued(tr, "snapshot_job", "change_job")):
                yield WAIT
        yield                              # (a caller's last work and the arrays below were 23 us cold in one)
        a1, a2 = tr.a1, tr.a2
        st, S, views = self.arrays(tr, a1, a2)
        yield                              # (with the set-up below, ~55-65 us cold)
        lay = tr.lay
        oldest = int(tr.sc[W.SC_RSTART])
        begin = max(tr.window_start if start is None else start, oldest, tr.loop_from)
        settle = WS.settling_samples(tr, a1, a2)
        origin, nodes = self.replay_start(tr, begin - settle, oldest)
        # the states are replayed from the origin, exact for the nodes; the resonance states start at
        # zero, which is exact only at the record's start: otherwise they are not trusted before two
        # settling times
        skip = begin - origin
        if origin > 0:
            skip = max(skip, settle)
        # the nodes, the free responses, the drift columns' time at the origin (and, after the yield, their
        # coefficients at the new point)
        W.replay_origin(st, nodes, tr._free_rates, origin, float(tr.sc[W.SC_TREF]))
        if tr.n_hyst:                      # the plays and their nodes at the oldest sample, from the live tails
            HK.replay_origin(st, tr.st, lay["hyst"], tr.n_hyst, tr.q)
        yield
        if tr.n_rate or tr.n_hyst:        # (the drift and hysteresis columns are computed with them)
            W.full_coefficients(tr.theta, a1, a2, tr.basis.lam, tr.basis.dx, st[lay["m"]:lay["sy"]])
            if tr.n_hyst:                  # (the unit-gain hysteresis columns divide by b; the start columns weigh)
                HK.set_gain(st, lay["hyst"], tr.n_hyst, tr.theta, 5 + tr.n_free)
            if tr.n_rate > 1:
                W.drift_coefficients(tr.theta, a1, a2, tr.basis.lam, tr.basis.dx, st[lay["md"]:lay["hyst"]])
        chunk = tr.replay_chunk
        snaps: list[tuple] = []
        buffers, taken = tr._replay_snaps[tr._replay_set], 0
        tr._replay_set ^= 1
        yield
        lin = (a1, a2)
        slot = tr._ring_position(origin) - origin
        i = origin
        deferred = False
        while i < tr.n:                  # the live stream keeps appending: catch up
            stop = tr.scheduler.test_after(tr, i) if tr.detect else tr.n   # (stop at the test's snapshot instants)
            units = 1 << 30 if tr.eager else 1     # (a checkpoint: every unit up to that stop in one call)
            i, n = W.replay_units(tr.ring, slot, origin, i, min(stop, tr.n), skip, chunk, tr.settings.cold_replay_rows,
                                  units, st, S, *tr._replay_work)
            if tr.detect and i % tr.test_every == 0 and i - origin > skip:
                index, S0, sy0, shift0, theta0 = buffers[taken % KEPT_SNAPSHOTS]  # (the slot of the one dropped now)
                taken += 1                 # shift0 stays zero: a replay's snapshots are at its own origin
                theta_i = tr._theta_at.get(i, tr.theta)
                yield                      # (the snapshot in a unit of its own: with a chunk's rows, 25-27 us)
                syy0, g0 = W.snapshot(st, S, shift0, theta_i, S0, sy0, shift0, theta0)
                snaps = (snaps + [(i, S0, sy0, syy0, g0, lin, theta0, shift0, index)])[-KEPT_SNAPSHOTS:]
            if i >= tr.n:                # caught up: swap now (a yield lets a new sample in) if this unit was
                if n <= tr.settings.swap_with or deferred:  # light; else on the next one, with the samples that came in
                    break                  # (once: fed in blocks, more than settings.swap_with may come in per unit)
                deferred = True
            yield
        # swap: the live scalars and tail, the replayed states and statistics; the live pair is the next spare
        W.swap_into(tr.st, st, tr.theta, tr.basis.lam, tr.basis.dx)
        tr._spare = (tr.st, tr.S, (tr.sc, tr.phi, tr.m, tr.sy, tr.co, tr.ztail, tr.md))
        tr._adopt(st, S, views)
        tr._snaps = snaps                # the change test keeps its reference through a replay
        tr._shift[:] = 0.0               # (replayed at one origin: the snapshots' and the statistics' own)
        yield                              # (the swap and the pace below: 25 us cold in one)
        tr.relinearizations += 1
        tr.scheduler.pace_refits(tr, False)

    def replay_start(self, tr: WindowTracker, latest: int, oldest: int) -> tuple[int, np.ndarray]:
        """Where a replay starts: (sample, the node state before it). The newest node mark at or before ``latest``
        (the replay's first counted sample less the resonance's settling), else the history's oldest sample and its
        tail state. The nodes are exact from either; starting at a mark replays only what the new statistics and
        the settling need, not the whole history, so the prediction at a new resonance (``WindowTracker._take_resonance``)
        comes sooner. With hysteresis columns the plays' states come from the history's tail: the oldest sample."""
        row = self.nearest_mark(tr, latest, oldest) if not tr.n_hyst else -1
        if row < 0:
            return oldest, tr.ztail
        return int(tr._node_mark_at[row]), tr._node_marks[row]

    def mark_nodes(self, tr: WindowTracker, n: int) -> None:
        """Mark the live node state (before sample n, now) in the row of the oldest mark, and set the next mark's sample.
        The nodes are the input's exact history (the same recursion as the history's tail state), so a mark is as
        good a start for a fast-forward as the tail, and much nearer a search's segment."""
        row = W.oldest_mark(tr._node_mark_at)
        tr._node_marks[row] = tr.phi[:tr.q]
        tr._node_mark_at[row] = n
        tr._next_node_mark = n + tr._node_mark_every

    def nearest_mark(self, tr: WindowTracker, n0: int, oldest: int) -> int:
        """The row of the newest node mark taken at or before sample n0 and not before the history's oldest, or -1."""
        return W.newest_mark(tr._node_mark_at, oldest, n0)     # (numpy's ufuncs here, cold: 40-60 us of one update())

    def nodes_at(self, tr: WindowTracker, n0: int) -> Generator:
        """The exact node state before remembered sample n0: fast-forwarded, in units, from the newest node mark
        before it (``mark_nodes``), else from the history's oldest sample and its tail state."""
        st, S = tr._nodes_state          # node states only (no statistics: S is not touched)
        st.fill(0.0)
        W.start_state(st, tr.basis.decay, tr.basis.gain, tr._free_decay, tr.forget, tr.h, tr.a1l,
                      tr.a2l, tr.n_rate, tr.n_hyst)
        yield                              # (with the caller's set-up and the rest below, ~28 us cold in one call)
        oldest = int(tr.sc[W.SC_RSTART])  # (the ring's oldest and its tail, read together)
        start, nodes = self.replay_start(tr, n0, oldest)
        st[tr.lay["phi"]:tr.lay["phi"] + tr.q] = nodes
        st[W.SC_N] = start
        if tr.n_hyst:                      # the plays and their nodes too, from the live tails
            HK.replay_origin(st, tr.st, tr.lay["hyst"], tr.n_hyst, tr.q)
        chunk = max(16, tr.settings.unit_macs // (4 * tr.q * (1 + tr.n_hyst)))   # states only: ~0.04 us per sample at Q = 42
        size, slot = tr.ring.shape[1], tr._ring_position(start) - start
        i = start
        yield                              # (the set-up and a first chunk in one update(): 45-55 us)
        while i < n0:                      # (n0 is remembered: a search's segment starts well after the oldest)
            n = min(chunk, n0 - i)
            W.replay(tr.ring, (slot + i) % size, n, n, st, S, *tr._replay_work)
            i += n
            yield
        zeta = st[tr.lay["phi"]:tr.lay["phi"] + tr.q].copy()
        if tr.n_hyst:                      # the corrected input's nodes, and the plays at n0 for ``ring_segment``
            tr._segment_plays = HK.corrected_nodes(st, tr.lay["hyst"], tr.n_hyst, tr.q, tr.hysteresis_coefficients, zeta)
        return zeta

    def ring_segment(self, tr: WindowTracker, n0: int, n1: int) -> Generator:
        """Copies of the remembered u, y for samples n0..n1 (``settings.segment_chunk`` per unit); returns (u, y), views of
        the tracker's segment buffer (``workspace.allocate_work``: one search at a time uses it; allocating them here,
        up to 2 x 256 kB, and numpy's fancy indexing cost ~80 us in one update())."""
        u, y = tr._segment[0, :n1 - n0], tr._segment[1, :n1 - n0]
        size, slot = tr.ring.shape[1], tr._ring_position(n0)
        if tr.n_hyst:                      # the search sees the input corrected by the live loop (``nodes_at``'s plays)
            plays, w = tr._segment_plays.copy(), tr.hysteresis_coefficients
        for k0 in range(0, n1 - n0, tr.settings.segment_chunk):
            k1 = min(n1 - n0, k0 + tr.settings.segment_chunk)
            W.ring_copy(tr.ring, (slot + k0) % size, u[k0:k1], y[k0:k1])
            if tr.n_hyst:
                HK.correct_input(u[k0:k1], tr.hyst_r, plays, w, HK.in_equilibrium(tr.st, tr.lay["hyst"]))
            yield
        return u, y
