"""Compile (or load from numba's cache) every kernel the online estimator's Python calls, before a stream starts.

It drives the kernels on a throw-away estimator's tracker arrays directly: the one place outside the trackers that
knows their state (compilation is the kernels' concern, not the estimator's).
"""
from __future__ import annotations

import numpy as np

from . import rest
from ._kernels import fit_machine as RF
from ._kernels import hysteresis as HK
from ._kernels import window as W
from .search import ResonanceSearch
from .trackers import recursive as R


def warm_kernels() -> None:
    """Compile (or load from numba's cache) every kernel that Python calls, so no update() pays for it."""
    from .estimator import OnlineEstimator
    from .trackers import window as T
    est = OnlineEstimator(1e-3, horizon_s=10.0, t_c=0.05)
    t = np.arange(3000) * 1e-3
    u = np.floor(t * 4) % 2
    est.update_block(u, u * 0.5 + 0.01 * np.sin(t * 50))
    for k in range(20):
        est.update(1.0, 0.5)
    est.predict_one(1.0)
    tr = est._tracker                # (the kernels' own arrays: this exercises them directly)
    # what the tracker's Python calls; the re-fit's stages (their kernels compiled into the machine's) run
    # once, through begin, run and accept, and once through the per-sample kernel
    W.replay(tr.ring, 0, 4, 1, tr.st.copy(), tr.S.copy(), *W.replay_scratch(tr.p))
    W.drift_coefficients(tr.theta, tr.a1l, tr.a2l, tr.basis.lam, tr.basis.dx, np.empty(tr.q + W.ONE))
    st, S, shift = tr.st.copy(), tr.S.copy(), tr._shift.copy()
    W.set_estimate(tr.theta.copy(), st, tr.basis.lam, tr.basis.dx)
    W.snapshot(st, S, shift, tr.theta, S.copy(), np.empty(tr.p), shift.copy(), tr.theta.copy())
    RF.queue_test(tr._test_wk.copy(), 0, 1.0, True)
    RF.snapshot(st, S, tr._ctx.copy(), T.MACHINE_TEST, 0, 1.0)
    wk = tr._wk.copy()
    RF.begin(st, S, shift, wk, 1, False, True, 0, True)
    RF.weight_variances(wk, tr.p, tr.theta.size, 5 + tr.n_free, tr.hyst_var.copy())
    RF.run(st, S, shift, tr.theta.copy(), wk, tr.basis.lam, tr.basis.dx)
    RF.accept(st, tr.theta.copy(), wk, tr.basis.lam, tr.basis.dx)
    RF.test_outcome(wk, tr.theta)
    # the drift score test's LAPACK calls (eigvalsh, solve) bind their routines on first use, inside the
    # first score test's slice otherwise: 0.6 ms in one update() at 5.4 s of the latency stream
    k = tr.theta.size
    W.drift_score(np.eye(k) + 0.1, np.ones(k), np.ones(k), k - 2)
    RF.begin(tr.st, tr.S, tr._shift, tr._wk, 1, False, True, 0, True)      # (this estimator is thrown away)
    RF.sample_work(0.0, 0.0, tr.st, tr.S, tr.ring, tr._ctx, T.MACHINE_REFIT, 1)
    W.ring_copy(tr.ring, 0, np.empty(4), np.empty(4))
    W.swap_into(tr.st.copy(), tr.st.copy(), tr.theta, tr.basis.lam, tr.basis.dx)
    W.replay_origin(tr.st.copy(), tr.ztail, tr._free_rates, 0, 0.0)
    # a post-change search (alpha fixed) and its judged costs: their kernels otherwise load at the first change
    search = ResonanceSearch(tr.basis, u[:300] - u[0], u[:300] * 0.5, fixed_alpha=0.1,
                             extra=((0.1, 2e-3, 1e-6),), work=None)
    search.run()
    for decays in ((), T.FREE_RATES):
        for _ in search.judged_cost(0.1, 2e-3, 1e-6, decays):
            pass
    # a search of a stream taken in operation (its costs by ``search._free_fit``): the start-up search's kernels
    search = ResonanceSearch(tr.basis, u[:300] - u[0], u[:300] * 0.5, fixed_alpha=0.1, free=T.FREE_RATES,
                             starts=[(0.1, 20.0, 0.5)], work=None)
    search.run()
    for a1 in (2e-3, 3e-3):            # (the strided rows, ``_rows_free_sparse``: the first candidate at a stride fills
        for _ in search._free_gram(0.1, a1, 1e-6, search.free, 2):   # the shared rows' cache, the next reads it)
            pass
    T.WindowTracker  # noqa: B018 - imported for its kernels
    R.warm()
    _warm_hysteresis(u)
    rest.reading(np.linspace(0.0, 1.0, 64))          # the start's reading (a stream whose first input is not 0)
    W.noise_seed(t, t.size, np.empty(W.NOISE_SEED_ROWS))
    scratch = np.empty(W.NOISE_SEED_ROWS)
    W.noise_level(scratch, W.noise_differences(t, t.size, scratch))
    W.newest_mark(np.full(4, -1, dtype=np.int64), 0, 10)
    W.oldest_mark(np.full(4, -1, dtype=np.int64))


def _warm_hysteresis(u: np.ndarray) -> None:
    """The hysteresis columns' kernels that the tracker's Python calls (new thresholds, a replay's start and swap, a
    re-search's corrected input), and a tracker with the columns through its per-sample, replay and re-fit kernels:
    loaded at a stream's first new thresholds otherwise (6 ms in one update())."""
    from .estimator import OnlineEstimator
    est = OnlineEstimator(1e-3, horizon_s=10.0, t_c=0.05, effects=("hysteresis",))
    t = np.arange(3000) * 1e-3
    est.update_block(u[:3000] * (1.0 + t), u[:3000] * 0.5 + 0.01 * np.sin(t * 50))
    tr = est._tracker
    if tr is None:
        return
    o, k, q = tr.lay["hyst"], tr.n_hyst, tr.q
    st = tr.st.copy()
    HK.rethreshold(st, o, k, q, tr.hyst_r.copy(), 0.0, tr.ztail)
    HK.set_gain(st, o, k, tr.theta, 5 + tr.n_free)
    HK.replay_origin(st, tr.st, o, k, q)
    HK.swap_block(tr.st, st, o, k, q)
    W.swap_into(tr.st.copy(), st, tr.theta, tr.basis.lam, tr.basis.dx)
    W.replay(tr.ring, 0, 4, 1, st, tr.S.copy(), *W.replay_scratch(tr.p))
    plays = HK.corrected_nodes(st, o, k, q, np.zeros(k), np.zeros(q))
    HK.correct_input(np.zeros(4), tr.hyst_r, plays, np.zeros(k))
    wk = tr._wk.copy()
    S, shift = tr.S.copy(), tr._shift.copy()
    RF.begin(st, S, shift, wk, 1, False, True, 0, True)
    RF.run(st, S, shift, tr.theta.copy(), wk, tr.basis.lam, tr.basis.dx)
    tr.follow_input_range()
