"""The window tracker's arrays: the state and statistics, their parts, and the work arrays its jobs reuse."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .._kernels import fit_machine as RF
from .._kernels import window as W
from ..search import SearchScratch
from .common import KEPT_SNAPSHOTS, SNAP_SLOTS, ZETA_BOUNDS

if TYPE_CHECKING:
    from .window import WindowTracker


def allocate_work(tr: WindowTracker) -> None:
    """The periodic jobs' work arrays, allocated once.

    A re-fit or a change test runs every few hundred samples: by then the
    interpreter's and numpy's code paths are cold, and each numpy call from
    Python (an allocation, a copy, a mask) costs 5-40 us at 10 kHz against
    ~1 us warm. The jobs therefore call fused kernels on these arrays. Only
    one re-fit is queued at a time (``Scheduler.schedule``), and the periodic jobs
    run one after the other (``Scheduler.next_job``), so each owns its arrays.
    """
    p, k, r0 = tr.p, tr.theta.size, tr.r0
    policy = {"LO": tr.alpha_bounds[0], "HI": tr.alpha_bounds[1], "DRIFT_ON": tr.settings.drift_on,
              "DRIFT_OFF": tr.settings.drift_off, "DRIFT_MAX": tr.settings.drift_max, "HOLD_N": tr.settings.alpha_hold_s / tr.h,
              "DRIFT_MIN_N": tr.settings.drift_min_s / tr.h, "DRIFT_EVERY": tr.settings.drift_test_every, "NRATE": tr.n_rate,
              "LN_A2_MIN": 2.0 * math.log(tr.h / (2.0 * math.pi * tr.settings.fn_max_fs)),
              "LN_ZETA_LO": math.log(ZETA_BOUNDS[0]), "LN_ZETA_HI": math.log(ZETA_BOUNDS[1]),
              "RELINEARIZE": tr.settings.relinearize, "WIDE_ON": tr.settings.wide_on}
    extra = tuple(5 + i for i, rate in enumerate(tr.settings.window_free_rates[:tr.n_free]) if rate not in tr.settings.window_free_start)
    works = [RF.allocate(p, k, r0, tr.settings.refit_steps, {**policy, "TRUST": tr.settings.trust}, extra=extra),
             RF.allocate(p, k, r0, tr.settings.test_steps, policy, SNAP_SLOTS + 2 * KEPT_SNAPSHOTS, tr._shift.shape)]
    # one array for what the per-sample kernel's slices need (``fit_machine.context``): theta, the shift and
    # the work arrays become views into it
    tr._ctx, tr.theta, tr._shift, (tr._wk, tr._test_wk) = RF.context(
        tr.theta, tr._shift, tr.basis.lam, tr.basis.dx, works)
    tr._refit_queued = False
    # the change test's snapshots, in slots reused in turn (a test holds its snapshot for ~15
    # units, ``_theta_at`` keeps the last five estimates), inside the test's work array: its first slice reads
    # the snapshot there, in the per-sample kernel (``fit_machine.queue_test``)
    slots = RF.snapshot_slots(tr._test_wk, p, k)
    tr._snap_slots = slots[:SNAP_SLOTS]
    tr._snap_next = 0
    # a replay's snapshots at the test instants it passes (the last three kept), written by one kernel
    # (``window.snapshot``: four numpy copies from cold Python cost ~20 us on a replay's unit) into slots of
    # their own (the test on one starts in the per-sample kernel too: from Python, ``fit_machine.start_test``, it
    # was 25-26 us cold in one update()); two sets, one per replay in turn: a change test queued on one
    # replay's snapshot reads it after that replay swapped in, while the next replay writes the other set
    tr._replay_snaps = [[(i, *slots[i]) for i in range(SNAP_SLOTS + j * KEPT_SNAPSHOTS,
                                                            SNAP_SLOTS + (j + 1) * KEPT_SNAPSHOTS)]
                          for j in range(2)]
    tr._replay_set = 0
    tr._replay_work = W.replay_scratch(p)     # (a replay's unit leaves nothing in it: shared by the jobs)
    # a search's segment (``Replayer.ring_segment``) and the states-only fast-forward before it (``Replayer.nodes_at``), made
    # and pre-faulted here: one search at a time
    rows = min(tr.ring.shape[1], 1 << 15 if tr.work_memory is None else tr.work_memory.shape[0])
    tr._segment = np.zeros((2, rows))
    tr._segment.fill(0.0)
    tr._nodes_state = (np.zeros(tr.lay["size"]), np.zeros((p, p)))
    # the nodes' state marked every ``settings.node_mark_s`` (``Replayer.mark_nodes``): one row per mark the history
    # can hold, and the sample each was taken before (-1: none)
    every = max(1, int(round(tr.settings.node_mark_s / tr.h)))
    tr._node_mark_every = every
    tr._node_marks = np.zeros((tr.ring.shape[1] // every + 2, tr.q))
    tr._node_mark_at = np.full(tr._node_marks.shape[0], -1, dtype=np.int64)
    tr._next_node_mark = every
    # the replays' state and statistics: a spare pair, swapped with the live one by each replay (``Replayer.arrays``)
    spare = np.full(tr.lay["size"], 0.0)
    tr._spare = (spare, np.full((p, p), 0.0), views(tr, spare))
    tr._search_scratch = SearchScratch(tr.q)   # (one search at a time: ``Researcher.researching``)
    tr._search_scratch.prepare_judge(tr._free_decays, tr.basis.h)    # (``Researcher.take_if_better``'s judge)
    tr._search_scratch.prepare_judge(tr.settings.research_trends, tr.basis.h)   # (a drifting re-search's)


def fresh(tr: WindowTracker, a1l: float, a2l: float, arrays: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Empty statistics and zero states for a linearization point (weight 1), in ``arrays`` (st, S) or new ones."""
    if arrays is None:
        st, S = np.zeros(tr.lay["size"]), np.zeros((tr.p, tr.p))
    else:
        st, S = arrays
        st.fill(0.0)
        S.fill(0.0)
    W.start_state(st, tr.basis.decay, tr.basis.gain, tr._free_decay, tr.forget, tr.h, a1l, a2l,
                  tr.n_rate, tr.n_hyst)
    return st, S


def views(tr: WindowTracker, st: np.ndarray) -> tuple:
    """The parts of a state array: sc, phi, m, sy, co, ztail, md."""
    lay = tr.lay
    return (st[:W.SC_SIZE], st[lay["phi"]:lay["m"]], st[lay["m"]:lay["sy"]], st[lay["sy"]:lay["co"]],
            st[lay["co"]:lay["ztail"]], st[lay["ztail"]:lay["md"]], st[lay["md"]:lay["hyst"]])


def settling_samples(tr: WindowTracker, a1: float, a2: float) -> int:
    """Two settling times of the resonance (a1, a2), in samples: 16 a2 / a1 = 8 / (zeta wn)."""
    return int(16.0 * a2 / a1 / tr.h)


def noise_variance(tr: WindowTracker, r: RF.Accepted) -> float:
    """The noise variance an accepted re-fit's window estimates (its cost over the degrees of freedom left): the
    scale of its parameter variances."""
    return max(r.cost, 0.0) / max(r.neff - tr.theta.size, 1.0)
