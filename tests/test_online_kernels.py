"""Streaming kernels of the online estimator against independent references.

References: the closed form t^alpha / Gamma(1+alpha), the exact simulator
(``simulate(method="exact")``, closed-form step response superposed), the
lead's direct truncated sum (``simulate.fractional_integral``), central
differences and brute-force residual sums.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from creep_online.model import ONLINE_ALPHA_BOUNDS, CreepModel
from creep_online.online._kernels import coefficients as K
from creep_online.online._kernels import fit_machine as RF
from creep_online.online.trackers import window as T
from creep_online.online._kernels import window as W
from hil_sim.varying_plant import simulate_varying
from creep_online.online.search import ResonanceSearch
from creep_online.online.soe import SOE_TOP, SoeBasis, resonance_zoh
from creep_online.online.trackers import workspace as WS
from creep_online.online.trackers.settings import DEFAULT, TrackerSettings
from creep_online.online.trackers.window import WindowTracker
from creep_online.simulate import fractional_integral, simulate



def _tracker(model: CreepModel, h: float, lin: tuple[float, float] | None = None, free: bool = False,
             window_s: float | None = None, history: int = 1 << 14, drift: int = 0,
             settings: TrackerSettings = DEFAULT) -> WindowTracker:
    """A tracker whose parameters are the model's (linearized at ``lin``, default the model's resonance)."""
    basis = SoeBasis.build(h, top=SOE_TOP)
    a1l, a2l = lin or (model.a1, model.a2)
    theta = np.array([model.alpha, math.log(a1l), math.log(a2l), model.b, 0.0])
    tr = WindowTracker(basis, theta, window_s=window_s, free=free, ring=np.zeros((2, history)), gate=0.0,
                       burst=3, stuck=10**9, alpha_bounds=ONLINE_ALPHA_BOUNDS, refit_every=10**9,
                       test_every=10**9, detect=False, drift=drift, settings=settings)
    tr.theta[1:3] = np.log([model.a1, model.a2])
    tr._coefficients()
    return tr


def _feed(tr: WindowTracker, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    pred = np.empty(u.size)
    for k in range(u.size):
        tr.feed(float(u[k]), float(y[k]))
        pred[k] = tr.prediction
    return pred


def _staircase(n: int, every: int, seed: int = 0) -> np.ndarray:
    return np.repeat(np.random.default_rng(seed).normal(size=n // every + 1), every)[:n]


@pytest.mark.parametrize("alpha, tol", [(0.0133, 2e-6), (0.06, 5e-6), (0.3, 2e-5), (0.7, 5e-5), (0.95, 2e-4)])
def test_soe_step_response_matches_closed_form(alpha, tol):
    basis = SoeBasis.build(1e-4, horizon_s=3600.0)
    t = np.geomspace(1e-4, 3600.0, 800)
    exact = t**alpha / math.gamma(1 + alpha)
    assert np.max(np.abs(basis.step_response(alpha, t) / exact - 1)) < tol


def test_model_coefficient_derivative_matches_central_difference():
    basis = SoeBasis.build(1e-3)
    p = basis.size + 2
    v, dv, vp, vm, tmp = (np.empty(p) for _ in range(5))
    for alpha in (0.02, 0.4, 0.9):
        K.model_coefficients(alpha, basis.lam, basis.dx, 2e-3, 1e-5, v, dv)
        K.model_coefficients(alpha + 1e-6, basis.lam, basis.dx, 2e-3, 1e-5, vp, tmp)
        K.model_coefficients(alpha - 1e-6, basis.lam, basis.dx, 2e-3, 1e-5, vm, tmp)
        assert np.max(np.abs((vp - vm) / 2e-6 - dv)) < 1e-7 * np.max(np.abs(dv))


def test_resonance_zoh_matches_scipy_lsim_of_a_step():
    from scipy.signal import lti
    a1, a2, h = 2e-3, 3e-6, 1e-4
    phi, gam = resonance_zoh(a1, a2, h)
    x = np.zeros(2)
    ys = []
    for _ in range(50):
        ys.append(x[0])
        x = phi @ x + gam
    t = np.arange(50) * h
    _, ref = lti([1.0], [a2, a1, 1.0]).step(T=t)
    assert np.max(np.abs(np.array(ys) - ref)) < 1e-9


@pytest.mark.parametrize("alpha, fn, zeta, h, n", [(0.02, 300.0, 0.05, 1e-4, 6000), (0.06, 6.0, 0.1, 5e-3, 3000),
                                                  (0.7, 10.0, 0.05, 1e-3, 3000), (0.3, 40.0, 1.0, 1e-3, 3000)])
def test_tracker_prediction_equals_exact_simulator(alpha, fn, zeta, h, n):
    model = CreepModel.from_resonance(alpha, fn, zeta, 1.7)
    t = np.arange(n) * h
    u = _staircase(n, 500)
    y = simulate(model, t, u)
    pred = _feed(_tracker(model, h), u, np.full(n, np.nan))
    assert np.max(np.abs(pred - y)) < 2e-5 * np.ptp(y)


def test_first_order_resonance_expansion_is_second_order_accurate():
    """Linearized 1 % away, the prediction error is O(delta^2): ~1e-4 of the range, ~25x less at 0.2 %."""
    model = CreepModel.from_resonance(0.05, 50.0, 0.1, 1.0)
    h, n = 1e-3, 3000
    t = np.arange(n) * h
    u = _staircase(n, 400, 1)
    y = simulate(model, t, u)
    errs = []
    for d in (0.01, 0.002):
        pred = _feed(_tracker(model, h, lin=(model.a1 * (1 + d), model.a2 * (1 - d))), u, np.full(n, np.nan))
        errs.append(np.max(np.abs(pred - y)) / np.ptp(y))
    assert errs[0] < 3e-3
    assert errs[1] < errs[0] / 15


def test_resonance_step_matches_matrix_exponential():
    for a1, a2 in ((2e-3, 3e-6), (0.05, 1e-4), (2.0, 1.0), (2e-2, 1e-4)):    # under-, over-, critically damped
        out = np.empty(6)
        W.resonance_step(a1, a2, 1e-3, out)
        phi, gam = resonance_zoh(a1, a2, 1e-3)
        assert np.allclose(out[:4], phi.ravel(), rtol=1e-9, atol=1e-12)
        assert np.allclose(out[4:], gam, rtol=1e-9, atol=1e-15)


def test_window_cost_and_gradient_equal_brute_force():
    """cost_of from the statistics = sum of squared residuals of the exact simulator; the Jacobian's
    normal equations match central differences of that cost."""
    model = CreepModel.from_resonance(0.05, 20.0, 0.2, 2.0)
    h, n = 2e-3, 4000
    t = np.arange(n) * h
    u = _staircase(n, 700, 2)
    y = simulate(model, t, u) + 0.3 + np.random.default_rng(2).normal(0, 1e-3, n)
    tr = _tracker(model, h)
    _feed(tr, u, y)
    F = np.empty((tr.p, tr.p))
    W.symmetrize(tr.S, F, 1.0 / tr.sc[W.SC_G])
    fy, fyy = tr.sy / tr.sc[W.SC_G], tr.sc[W.SC_SYY] / tr.sc[W.SC_G]
    lam, dx = tr.basis.lam, tr.basis.dx

    def brute(theta):
        m = CreepModel(theta[0], math.exp(theta[1]), math.exp(theta[2]), theta[3])
        r = y - simulate(m, t, u) - theta[4]
        return r @ r

    for theta in (np.array([0.05, math.log(model.a1), math.log(model.a2), 2.0, 0.3]),
                  np.array([0.06, math.log(model.a1), math.log(model.a2), 1.9, 0.2])):
        cost = W.cost_of(theta, tr.a1l, tr.a2l, lam, dx, F, fy, fyy)
        assert cost == pytest.approx(brute(theta), rel=2e-3, abs=1e-3 * n * 1e-6)
    theta = np.array([0.06, math.log(model.a1), math.log(model.a2), 1.9, 0.2])
    C = np.empty((tr.p, theta.size))
    W.jacobian_coefficients(theta, tr.a1l, tr.a2l, lam, dx, C)
    H, g, cost = W.normal_equations(theta, C, F, fy, fyy)
    for j in range(5):
        e = np.zeros(5)
        e[j] = 1e-5 * max(abs(theta[j]), 1.0)
        numeric = (W.cost_of(theta + e, tr.a1l, tr.a2l, lam, dx, F, fy, fyy)
                   - W.cost_of(theta - e, tr.a1l, tr.a2l, lam, dx, F, fy, fyy)) / (2 * e[j])
        assert -2 * g[j] == pytest.approx(numeric, rel=1e-4, abs=1e-6 * abs(cost))


def test_block_normal_equations_equal_the_dense_products():
    """The block-diagonal normal equations = the dense C^T F C, C^T (fy - F m) and the cost, with free
    responses and both drift columns (the unit-vector block in use)."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 3000
    u = _staircase(n, 300, 8)
    y = simulate(model, np.arange(n) * h, u) + np.random.default_rng(8).normal(0, 1e-3, n)
    tr = _tracker(model, h, free=True, drift=2)
    _feed(tr, u, y)
    F = np.empty((tr.p, tr.p))
    W.symmetrize(tr.S, F, 1.0 / tr.sc[W.SC_G])
    fy, fyy = tr.sy / tr.sc[W.SC_G], tr.sc[W.SC_SYY] / tr.sc[W.SC_G]
    theta = tr.theta.copy()
    theta[0] = 0.12
    theta[4:] = np.linspace(0.1, -0.2, theta.size - 4)
    C = np.empty((tr.p, theta.size))
    W.jacobian_coefficients(theta, tr.a1l, tr.a2l, tr.basis.lam, tr.basis.dx, C)
    H, g, cost = W.normal_equations(theta, C, F, fy, fyy)
    m = C[:, 3:] @ theta[3:]
    scale = np.abs(C.T @ np.abs(F) @ np.abs(C)).max()
    assert np.allclose(H, C.T @ F @ C, rtol=1e-12, atol=1e-13 * scale)
    assert np.allclose(g, C.T @ (fy - F @ m), rtol=1e-10, atol=1e-12 * np.abs(C.T @ np.abs(fy)).max())
    assert cost == pytest.approx(fyy - 2 * m @ fy + m @ F @ m, rel=1e-9, abs=1e-12 * fyy)
    assert cost == pytest.approx(W.cost_of(theta, tr.a1l, tr.a2l, tr.basis.lam, tr.basis.dx, F, fy, fyy),
                                 rel=1e-9, abs=1e-12 * fyy)


def test_replay_reproduces_the_statistics():
    """Statistics rebuilt by replaying the ring equal those accumulated live (same linearization): S's upper
    triangle, where they are held."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 3000
    u = _staircase(n, 300, 3)
    y = simulate(model, np.arange(n) * h, u)
    tr = _tracker(model, h)
    _feed(tr, u, y)
    job = tr.replayer.relinearize_job(tr, None)
    for _ in job:
        pass
    fresh = _tracker(model, h, lin=(tr.a1l, tr.a2l))
    _feed(fresh, u, y)
    assert np.allclose(np.triu(tr.S), np.triu(fresh.S), rtol=1e-9, atol=1e-12 * np.abs(fresh.S).max())
    assert np.allclose(tr.sy, fresh.sy, rtol=1e-9, atol=1e-12 * np.abs(fresh.sy).max())




def test_replays_swap_two_state_arrays_in_turn_and_each_equals_a_tracker_fed_live():
    """Each replay writes the spare pair (state, statistics) and swaps it in (``window.swap_into``); the live pair it
    retires is the next replay's. Three replays in turn, the stream going on between them: after each, the
    statistics and the next predictions equal those of a tracker fed live at the replay's linearization point,
    and the live arrays alternate between the same two."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 4000
    u = _staircase(n, 300, 5)
    y = simulate(model, np.arange(n) * h, u) + 1e-3 * np.random.default_rng(3).normal(size=n)
    tr = _tracker(model, h, lin=(model.a1 * 1.1, model.a2 * 0.9))
    fresh = _tracker(model, h)
    arrays = []
    done = 0
    for upto in (2000, 3000, 3500):
        _feed(tr, u[done:upto], y[done:upto])
        _feed(fresh, u[done:upto], y[done:upto])
        done = upto
        for _ in tr.replayer.relinearize_job(tr, None):
            pass
        arrays.append((tr.st, tr.S))
        assert (tr.a1l, tr.a2l) == (fresh.a1l, fresh.a2l)
        assert np.allclose(np.triu(tr.S), np.triu(fresh.S), rtol=1e-9, atol=1e-12 * np.abs(fresh.S).max())
        assert np.allclose(tr.sy, fresh.sy, rtol=1e-9, atol=1e-12 * np.abs(fresh.sy).max())
        assert tr.sc[W.SC_SYY] == pytest.approx(float(fresh.sc[W.SC_SYY]), rel=1e-9)
        ahead = slice(upto, upto + 50)
        assert np.allclose(_feed(tr, u[ahead], y[ahead]), _feed(fresh, u[ahead], y[ahead]), rtol=0, atol=1e-12)
        done = upto + 50
    assert arrays[0][0] is arrays[2][0] and arrays[0][1] is arrays[2][1]
    assert arrays[1][0] is not arrays[0][0] and arrays[1][1] is not arrays[0][1]
    assert tr.adoptions == 4                       # (the start and three swaps)


def test_replay_snapshots_equal_the_statistics_at_their_instants_and_survive_the_next_replay():
    """A replay passes the change test's instants and keeps the last three snapshots (``window.snapshot`` into
    slots of their own in the change test's work array): each equals the statistics a tracker fed live at that
    linearization point had at that sample (S's upper triangle, sy, syy, the weight), and the test queued on its
    slot (``refit.queue_test``: the per-sample kernel's slices) ends as the test started from Python on it
    (``refit.start_test``). The next replay writes the other set of slots: a change test queued on the first
    replay's snapshot still reads what it was."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n, every = 1e-3, 3000, 500
    u = _staircase(n, 300, 4)
    y = simulate(model, np.arange(n) * h, u) + 1e-3 * np.random.default_rng(2).normal(size=n)
    tr = _tracker(model, h)
    tr.detect, tr.test_every = True, every
    _feed(tr, u, y)
    tr._jobs.clear()                               # (the live snapshots' jobs: not what is tested)
    for _ in tr.replayer.relinearize_job(tr, None):
        pass
    snaps = tr._snaps
    assert [s[0] for s in snaps] == [2000, 2500, 3000]
    fresh = _tracker(model, h, lin=(tr.a1l, tr.a2l))
    upper = np.triu(np.ones((tr.p, tr.p), dtype=bool))
    done = 0
    kept = []
    for i, S0, sy0, syy0, g0, lin, theta0, shift0, slot in snaps:
        _feed(fresh, u[done:i], y[done:i])
        done = i
        scale = np.abs(fresh.S).max()
        assert np.allclose(S0[upper], fresh.S[upper], rtol=1e-9, atol=1e-12 * scale)
        assert np.allclose(sy0, fresh.sy, rtol=1e-9, atol=1e-12 * np.abs(fresh.sy).max())
        assert syy0 == pytest.approx(float(fresh.sc[W.SC_SYY]), rel=1e-9)
        assert g0 == pytest.approx(float(fresh.sc[W.SC_G]), rel=1e-12)
        assert T.SNAP_SLOTS <= slot < T.SNAP_SLOTS + 2 * T.KEPT_SNAPSHOTS
        assert not shift0.any() and lin == (tr.a1l, tr.a2l)
        assert all(np.shares_memory(a, b) for a, b in zip(RF.snapshot_slots(tr._test_wk, tr.p, tr.theta.size)[slot],
                                                          (S0, sy0, shift0, theta0)))
        kept.append((S0[upper].copy(), sy0.copy()))
    outcomes = []
    for queued in (True, False):                   # the last snapshot's test, both ways, on copies
        st, S, shift, wk = tr.st.copy(), tr.S.copy(), tr._shift.copy(), tr._test_wk.copy()
        i, S0, sy0, syy0, g0, lin, theta0, shift0, slot = snaps[0]
        if queued:
            RF.queue_test(wk, slot, syy0, False)
        else:
            RF.start_test(st, S, S0, sy0, syy0, shift, shift0, tr.theta, wk, False)
        RF.run(st, S, shift, tr.theta.copy(), wk, tr.basis.lam, tr.basis.dx)
        outcomes.append(np.array(RF.test_outcome(wk, tr.theta)))
    assert outcomes[0][0] > 0 and np.allclose(outcomes[0], outcomes[1], rtol=1e-12, atol=0)
    for _ in tr.replayer.relinearize_job(tr, None):            # the next replay: the first one's snapshots untouched
        pass
    for (i, S0, sy0, *_), (S_then, sy_then) in zip(snaps, kept):
        assert np.array_equal(S0[upper], S_then) and np.array_equal(sy0, sy_then)
    assert all(a[1] is not b[1] for a, b in zip(snaps, tr._snaps))


def test_a_replay_unit_does_at_most_one_chunk_of_work():
    """``replay_unit``: a unit only advances up to 8 chunks (1/8 the work each) or accumulates ``chunk`` samples;
    no unit does both, the last advancing one ends at the skip, the first accumulating one adds only
    ``COLD_REPLAY_ROWS`` (cold statistics), and the units cover every sample."""
    chunk = 54
    for skip in (0, 1, 7, 135, 431, 432, 433, 5000):
        done, units = 0, []
        while done < skip + 3 * chunk:
            n = W.replay_unit(chunk, skip - done, DEFAULT.cold_replay_rows)
            advanced = min(n, max(skip - done, 0))
            assert advanced in (0, n)                      # (advance or accumulate, not both)
            units.append((advanced, n - advanced))
            done += n
        assert max(a / 8 + b for a, b in units) <= chunk
        first = next(i for i, (a, b) in enumerate(units) if b)
        assert sum(a for a, _ in units[:first]) == skip     # (the skip ends at a unit's end)
        assert units[first][1] == DEFAULT.cold_replay_rows and all(b == chunk for _, b in units[first + 1:])
        assert done >= skip + 3 * chunk

@pytest.mark.parametrize("window_s, drift, skip", [(None, 0, 0), (1.0, 2, 100), (0.01, 2, 0)])
def test_blocked_replay_equals_one_rank_one_update_per_sample(window_s, drift, skip):
    """``replay`` (rows gathered in blocks, one matrix product each) = ``replay_direct`` (the live kernel's
    rank-one update per sample; S's upper triangle, where the statistics are held): with the drift columns, missing
    outputs (NaN, skipped), a skipped start,
    replays cut at arbitrary lengths, and a window short enough (10 ms at 1 kHz) that the weight passes
    1e100 and the statistics are rescaled inside a block."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 3000
    u = _staircase(n, 300, 5)
    y = simulate(model, np.arange(n) * h, u) + 1e-3 * np.random.default_rng(1).normal(size=n)
    y[[7, 8, 40, 41, 42, 1500]] = np.nan
    tr = _tracker(model, h, window_s=window_s, drift=drift)
    _feed(tr, u, y)
    st0, S0 = WS.fresh(tr, tr.a1l, tr.a2l)
    st0[tr.lay["m"]:tr.lay["sy"]] = tr.m          # the drift columns' coefficients of the estimate
    st0[tr.lay["md"]:] = tr.md
    start = tr._ring_position(0)
    blocked, direct = (st0.copy(), S0.copy()), (st0.copy(), S0.copy())
    scratch = W.replay_scratch(tr.p)
    done = 0
    for length in (1, 31, 33, 500, 1, 977, n):     # cut anywhere, as the jobs' units do
        length = min(length, n - done)
        if length <= 0:
            break
        pos = (start + done) % tr.ring.shape[1]
        W.replay(tr.ring, pos, length, max(skip - done, 0), *blocked, *scratch)
        W.replay_direct(tr.ring, pos, length, max(skip - done, 0), *direct)
        done += length
    (stb, Sb), (std, Sd) = blocked, direct
    assert stb[W.SC_N] == std[W.SC_N] == n
    for k in (W.SC_G, W.SC_NEFF, W.SC_SYY):
        assert stb[k] == pytest.approx(std[k], rel=1e-12)
    lay = tr.lay
    assert np.allclose(stb[lay["phi"]:lay["m"]], std[lay["phi"]:lay["m"]], rtol=0, atol=0)
    assert np.allclose(np.triu(Sb), np.triu(Sd), rtol=1e-11, atol=1e-13 * np.abs(Sd).max())
    assert np.allclose(stb[lay["sy"]:lay["co"]], std[lay["sy"]:lay["co"]], rtol=1e-11,
                       atol=1e-13 * np.abs(std[lay["sy"]:lay["co"]]).max())
    if window_s == 0.01:
        assert std[W.SC_G] < 1e100        # rescaled on the way (unrescaled: exp(0.1 n) ~ 1e130)

def _drift_window(seed: int, tref: float | None = None) -> tuple[WindowTracker, int, float]:
    """A 1 s window with both drift columns fed 3 s of a staircase (its drift origin at ``tref`` if given)."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 3000
    u = _staircase(n, 300, seed)
    y = simulate(model, np.arange(n) * h, u)
    tr = _tracker(model, h, window_s=1.0, drift=2)
    if tref is not None:
        tr.sc[W.SC_TREF] = tref
    _feed(tr, u, y)
    return tr, n, h


def test_rereference_equals_accumulating_with_the_new_time_origin():
    """Moving the drift columns' time origin in the statistics = accumulating with that origin (m fixed)."""
    moved, n, _ = _drift_window(4)
    W.rereference(moved.st, moved.S, float(n))
    direct, _, _ = _drift_window(4, tref=n)
    assert moved.sc[W.SC_TREF] == n
    assert np.allclose(moved.S, direct.S, rtol=1e-8, atol=1e-11 * np.abs(direct.S).max())
    assert np.allclose(moved.sy, direct.sy, rtol=1e-8, atol=1e-11 * np.abs(direct.sy).max())


def test_refit_statistics_equal_moving_the_origin_then_scaling():
    """The re-fit's statistics kernels (move_origin, scaled_statistics) = rereference, the running total of the
    moves, symmetrize and scale."""
    tr, n, h = _drift_window(6)
    st, S, shift = tr.st.copy(), tr.S.copy(), np.zeros((tr.q + W.ONE, 2))
    F, fy = np.empty((tr.p, tr.p)), np.empty(tr.p)
    W.move_origin(tr.st, tr.S, shift)
    fyy = W.scaled_statistics(tr.st, tr.S, F, fy)
    t = (n - st[W.SC_TREF]) * h
    W.rereference(st, S, float(n))
    g = st[W.SC_G]
    assert np.array_equal(F, (np.triu(S) + np.triu(S, 1).T) * (1.0 / g))
    assert np.array_equal(fy, st[tr.lay["sy"]:tr.lay["co"]] / g)
    assert fyy == st[W.SC_SYY] / g
    assert np.allclose(shift[:, 0], t * tr.m[:tr.q + W.ONE], rtol=1e-15, atol=0)
    assert np.allclose(shift[:, 1], t * tr.md, rtol=1e-15, atol=0)


def test_since_statistics_equal_the_snapshot_moved_to_the_live_origin():
    """The change test's statistics since a snapshot = live minus the snapshot re-referenced, in one move, to
    the live origin, although the live statistics moved twice since (the moves compose additively)."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 6000
    u = _staircase(n, 300, 7)
    y = simulate(model, np.arange(n) * h, u)
    tr = _tracker(model, h, window_s=1.0, drift=2)
    _feed(tr, u[:2000], y[:2000])
    W.move_origin(tr.st, tr.S, tr._shift)                     # a move before the snapshot
    snap = tr.st.copy(), tr.S.copy(), tr._shift.copy()
    _feed(tr, u[2000:4000], y[2000:4000])
    W.move_origin(tr.st, tr.S, tr._shift)                     # two moves after it
    _feed(tr, u[4000:], y[4000:])
    W.move_origin(tr.st, tr.S, tr._shift)
    st0, S0, shift0 = snap
    sy0, syy0 = st0[tr.lay["sy"]:tr.lay["co"]].copy(), float(st0[W.SC_SYY])
    R, ry = np.empty((tr.p, tr.p)), np.empty(tr.p)
    ryy = W.since_statistics(tr.st, tr.S, S0, sy0, syy0, tr._shift, shift0, R, ry)
    moved, S0m = st0.copy(), S0.copy()
    W.rereference(moved, S0m, float(tr.sc[W.SC_TREF]))      # the snapshot in one move (m unchanged since)
    g = tr.sc[W.SC_G]
    expect = (tr.S - S0m) / g
    scale = np.abs(tr.S).max() / g
    assert np.allclose(R, R.T, rtol=0, atol=0)
    assert np.allclose(R, expect, rtol=1e-9, atol=1e-11 * scale)
    assert np.allclose(ry, (tr.sy - moved[tr.lay["sy"]:tr.lay["co"]]) / g, rtol=1e-9,
                       atol=1e-11 * np.abs(tr.sy).max() / g)
    assert ryy == pytest.approx((tr.sc[W.SC_SYY] - syy0) / g, rel=1e-15)


def _fed_drifting_tracker(seed: int) -> WindowTracker:
    """A tracker with free responses and both drift columns, 4 s of a noisy staircase into a plant near its
    estimate (the re-fit machine's test bed)."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 4000
    u = _staircase(n, 300, seed)
    y = simulate(model, np.arange(n) * h, u) + np.random.default_rng(seed).normal(0, 1e-3, n)
    tr = _tracker(CreepModel.from_resonance(0.12, 33.0, 0.25, 0.9), h, free=True, drift=2)
    _feed(tr, u, y)
    return tr


@pytest.mark.parametrize("wide", [False, True])
def test_refit_machine_equals_its_kernels_in_sequence(wide):
    """refit.refit_unit, one stage or slice per call, = the statistics, REFIT_STEPS Levenberg-Marquardt steps
    and the covariance called in sequence, bit for bit (the slices sum in the same order); refit.accept swaps
    the result in with its coefficients. ``wide``: all eight free responses fitted, else the four of
    ``tracker.WINDOW_FREE_START`` (the others held)."""
    tr = _fed_drifting_tracker(9)
    tr._wk[RF.RF_WIDE] = 1.0 if wide else 0.0
    st, S, shift, start = tr.st.copy(), tr.S.copy(), tr._shift.copy(), tr.theta.copy()
    lam, dx = tr.basis.lam, tr.basis.dx
    F, fy = np.empty((tr.p, tr.p)), np.empty(tr.p)
    W.move_origin(st, S, shift)
    fyy = W.scaled_statistics(st, S, F, fy)
    theta, mu, out = start.copy(), 1e-3, np.empty(3)
    free = np.ones(theta.size)
    free[4:5 + tr.n_free] = W.LINEAR                 # the offset and free responses of a stream in operation
    if not wide:                                     # ... four of them until the wide test frees the others
        free[[5 + i for i, rate in enumerate(DEFAULT.window_free_rates) if rate not in DEFAULT.window_free_start]] = 0.0
    free[-2:] = 0.0                                  # rates off: MASK_CONSTANT
    H, g = np.empty((theta.size, theta.size)), np.empty(theta.size)
    for _ in range(DEFAULT.refit_steps):
        cost = W.lm_normal(theta, tr.a1l, tr.a2l, lam, dx, F, fy, fyy, H, g)
        mu = W.lm_trial(theta, free, mu, H, g, cost, tr.a1l, tr.a2l, lam, dx, F, fy, fyy, *tr.alpha_bounds, out)
    cov = np.empty_like(H)
    W.covariance(H, free, cov)
    RF.begin(tr.st, tr.S, tr._shift, tr._wk, 0, False, False, 1, True)      # (with the drift-origin move)
    units = 1
    while not RF.fit_unit(tr.st, tr.S, tr._shift, tr.theta, tr._wk, lam, dx):
        units += 1
    normal_slices = -(-tr.p // int(tr._wk[RF.RF_NORMAL_ROWS]))
    cost_slices = -(-tr.p // int(tr._wk[RF.RF_COST_ROWS]))
    inverse_slices = -(-theta.size // int(tr._wk[RF.RF_INVERSE_COLS]))
    warm_slices = -(-tr.p // int(tr._wk[RF.RF_WARM_ROWS]))
    assert normal_slices > 1 and inverse_slices > 1 and warm_slices > 1   # the slices are exercised
    # F warmed, the drift origin's move (1), scaling (1); per step the model coefficients (two halves), their
    # resonance derivatives, the Jacobian's, the rows, the step's factor and solve, the trial's coefficients, its
    # cost; the covariance's factor and its inverse's columns
    assert units == warm_slices + 2 + DEFAULT.refit_steps * (4 + normal_slices + 3 + cost_slices) + 1 + inverse_slices
    head, fitted, var = RF.result(tr._wk)
    assert np.array_equal(fitted, theta) and np.array_equal(var, np.diag(cov))
    assert head[RF.RF_AFTER] == out[1] and head[RF.RF_DRIFT] == 0.0
    r = RF.Accepted._make(RF.accept(tr.st, tr.theta, tr._wk, lam, dx))
    assert r.verdict == RF.ACCEPTED and np.array_equal(tr.theta, theta)
    m = np.empty(tr.p)
    W.full_coefficients(theta, tr.a1l, tr.a2l, lam, dx, m)
    assert np.array_equal(tr.m, m)


def test_the_refit_keeps_the_resonance_within_its_trust_region_and_the_change_test_does_not():
    """A re-fit's trial moves ln a1, ln a2 at most ``tracker.TRUST`` from the linearization point (beyond it the
    statistics' first-order expansion is not the model: close_modes 0 walked a1 to +1159 % on it); alpha, b and
    the rest are not touched. The change test's fit is not bounded: a plant change is a large move it must see."""
    tr = _fed_drifting_tracker(9)
    assert tr._wk[RF.RF_TRUST] == DEFAULT.trust > 0.0 and tr._test_wk[RF.RF_TRUST] == 0.0
    wk = tr._wk.copy()
    wk[RF.RF_A1L], wk[RF.RF_A2L] = 2e-4, 3e-7
    c1, c2 = math.log(2e-4), math.log(3e-7)
    for d1, d2 in ((1.0, -1.0), (-0.7, 0.9), (0.1, -0.2)):
        trial = np.array([0.3, c1 + d1, c2 + d2, 1.5, 0.01])
        RF._trust(trial, wk)
        assert trial[1] == pytest.approx(c1 + max(min(d1, DEFAULT.trust), -DEFAULT.trust), abs=1e-12)
        assert trial[2] == pytest.approx(c2 + max(min(d2, DEFAULT.trust), -DEFAULT.trust), abs=1e-12)
        assert trial[[0, 3, 4]].tolist() == [0.3, 1.5, 0.01]
    wk[RF.RF_TRUST] = 0.0                             # none: the trial as it was
    trial = np.array([0.3, c1 + 1.0, c2 - 1.0, 1.5, 0.01])
    RF._trust(trial, wk)
    assert trial.tolist() == [0.3, c1 + 1.0, c2 - 1.0, 1.5, 0.01]


@pytest.mark.parametrize("slices", [1, 3])
@pytest.mark.parametrize("outputs", ["missing", "measured"])
def test_the_per_sample_kernel_runs_the_refit_machine_to_the_same_result(slices, outputs):
    """refit.sample_work (a sample, then slices of the re-fit, with theta, shift, nodes and work arrays taken
    from the context array) = refit.run on the state at the re-fit's start, bit for bit, and reports the end
    with MACHINE_DONE after exactly the machine's number of slices. With outputs measured meanwhile the
    statistics move under the fit: it must read them at one instant (the scaling's slice, after the drift
    origin's move in the slice before). Scaled in two slices a sample apart, they gave a window cost that grew
    with the stream while theta stayed right (the demo ended "degraded" at 1.85x the noise floor, sample by
    sample only)."""
    tr = _fed_drifting_tracker(4)
    lam, dx = tr.basis.lam, tr.basis.dx
    rng = np.random.default_rng(1)
    ys = [math.nan if outputs == "missing" else 0.8 + 1e-3 * rng.standard_normal() for _ in range(2000)]
    RF.begin(tr.st, tr.S, tr._shift, tr._wk, 0, False, False, 1, True)
    # the reference: until the statistics are frozen (the warming slices, the drift origin's move, the scaling)
    # each call's sample (sample_work takes it before its slices), then its slices; then the machine in one go
    st, S, shift, theta, wk, ring = (a.copy() for a in (tr.st, tr.S, tr._shift, tr.theta, tr._wk, tr.ring))
    before = 0
    frozen = False
    while not frozen:
        W.sample(0.5, ys[before // slices], st, S, ring)
        for _ in range(slices):
            RF.fit_unit(st, S, shift, theta, wk, lam, dx)
            before += 1
            frozen = wk[RF.RF_STAGE] == RF.ST_JACOBIAN
            if frozen:
                break
    assert before > 2                                  # (the warming slices and the move came first)
    expected = before
    probe = wk.copy()
    while not RF.fit_unit(st.copy(), S.copy(), shift.copy(), theta.copy(), probe, lam, dx):
        expected += 1
    RF.run(st, S, shift, theta, wk, lam, dx)
    calls = 0
    while True:
        status = RF.sample_work(0.5, ys[calls], tr.st, tr.S, tr.ring, tr._ctx, T.MACHINE_REFIT, slices)
        calls += 1
        if status >= RF.MACHINE_DONE:
            break
    assert status - RF.MACHINE_DONE == (1 if outputs == "missing" else 0)   # the sample itself
    assert calls == -(-(expected + 1) // slices)          # the last call's slice reports the end
    if outputs == "measured":
        assert calls > 5 and tr.sc[W.SC_NEFF] != st[W.SC_NEFF]           # the statistics did move
    assert np.array_equal(tr._wk, wk) and np.array_equal(tr.theta, theta)


@pytest.mark.parametrize("free_rates", [False, True])
def test_the_change_test_fits_a_drift_the_window_does_not(free_rates):
    """Before the window fits drift (rates off), the change test fits the drift rates itself: a plant whose
    alpha and gain drift (+5 %/s, +2.5 %/s) is then a drift, at the noise floor, not a resonance and gain
    "change" (without them: a1 and b moves beyond CHANGE_MOVE, the seen false event of plant 1010)."""
    base = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n, noise = 1e-3, 3000, 1e-4
    t = np.arange(n) * h
    u = _staircase(n, 400, 5)
    y = simulate_varying(t, u, 0.1 * (1 + 0.05 * t), base.a1, base.a2, 1 + 0.025 * t)
    y += np.random.default_rng(1).normal(0, noise, n)
    tr = _tracker(base, h, drift=2)
    _feed(tr, u[:1000], y[:1000])
    S0, sy0, shift0, theta0 = np.empty_like(tr.S), np.empty(tr.p), np.empty_like(tr._shift), np.empty(tr.theta.size)
    syy0, _ = W.snapshot(tr.st, tr.S, tr._shift, tr.theta, S0, sy0, shift0, theta0)
    _feed(tr, u[1000:], y[1000:])
    RF.start_test(tr.st, tr.S, S0, sy0, syy0, tr._shift, shift0, tr.theta, tr._test_wk, free_rates)
    RF.run(tr.st, tr.S, tr._shift, tr.theta, tr._test_wk, tr.basis.lam, tr.basis.dx)
    r = RF.TestOutcome._make(RF.test_outcome(tr._test_wk, tr.theta))
    moves = {"a1": math.exp(r.ln_a1 - r.live_ln_a1) - 1, "a2": math.exp(r.ln_a2 - r.live_ln_a2) - 1,
             "b": r.b / r.live_b - 1}
    if free_rates:
        assert all(abs(v) < 0.005 for v in moves.values()), moves
        assert r.after < 1.5 * (n - 1000) * noise**2
    else:
        assert any(abs(moves[k]) > DEFAULT.change_rule.move[k] for k in moves), moves


def test_drift_columns_model_a_drifting_gain_and_alpha():
    """With the true rates the window cost of a drifting plant is far below the constant-parameter cost."""
    base = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 8000
    t = np.arange(n) * h
    u = _staircase(n, 400, 5)
    alpha_dot, beta = 0.1 * 0.003, 0.002          # alpha +0.3 %/s, b +0.2 %/s
    tau = t - t[-1]
    y = simulate_varying(t, u, 0.1 * (1 + 0.003 * tau), base.a1, base.a2, 1 + beta * tau)
    tr = _tracker(base, h, drift=2)
    _feed(tr, u, y)
    W.rereference(tr.st, tr.S, float(n - 1))
    F = np.empty((tr.p, tr.p))
    W.symmetrize(tr.S, F, 1.0 / tr.sc[W.SC_G])
    fy, fyy = tr.sy / tr.sc[W.SC_G], tr.sc[W.SC_SYY] / tr.sc[W.SC_G]
    theta = tr.theta.copy()
    constant = W.cost_of(theta, tr.a1l, tr.a2l, tr.basis.lam, tr.basis.dx, F, fy, fyy)
    theta[-2:] = beta, alpha_dot
    drifting = W.cost_of(theta, tr.a1l, tr.a2l, tr.basis.lam, tr.basis.dx, F, fy, fyy)
    assert drifting < 0.01 * constant, (drifting, constant)


@pytest.mark.parametrize("alpha, fn, zeta, b, fs, seconds", [(0.3, 25.0, 0.2, 1.2, 2000, 0.3),
                                                            (0.05, 300.0, 0.15, 1.0, 10000, 0.05),
                                                            (0.6, 5.0, 0.5, -30.0, 1000, 1.0),
                                                            (0.01, 1000.0, 0.02, 1e-3, 10000, 0.2)])
def test_search_finds_the_basin(alpha, fn, zeta, b, fs, seconds):
    h = 1 / fs
    t = np.arange(int(seconds * fs)) * h
    u = np.where(t >= 0.01, 1.0, 0.0)
    y = simulate(CreepModel.from_resonance(alpha, fn, zeta, b), t, u)
    y = y + np.random.default_rng(0).normal(0, 0.01 * np.sqrt(np.mean(y**2)), t.size)
    r = ResonanceSearch(SoeBasis.build(h, top=SOE_TOP), u, y).run()
    found = CreepModel(r.alpha, r.a1, r.a2, r.b)
    assert r.alpha == pytest.approx(alpha, rel=0.05)
    assert found.fn == pytest.approx(fn, rel=0.03)
    assert found.zeta == pytest.approx(zeta, rel=0.1)
    assert r.b == pytest.approx(b, rel=0.05)


def test_truncated_gl_ring_buffer_equals_direct_sum():
    from creep_online.kernels import zoh_integral_weights
    rng = np.random.default_rng(1)
    u = rng.normal(size=700)
    h, alpha, length = 1e-3, 0.3, 64
    c = zoh_integral_weights(alpha, h, math.gamma(1 + alpha), length + 1)
    out = np.empty(u.size)
    K.truncated_gl_block(u, np.zeros(length), np.zeros(1, dtype=np.int64), c, out)
    ref = fractional_integral(u, h, alpha, memory=length)
    assert np.max(np.abs(out - ref)) < 1e-12


def test_varying_plant_equals_simulate_when_constant():
    model = CreepModel.from_resonance(0.05, 20.0, 0.2, 1.3)
    h, n = 2e-3, 6000
    t = np.arange(n) * h
    u = np.where(((t // 1.5) % 2) == 0, 1.0, -0.5)
    ref = simulate(model, t, u)
    out = simulate_varying(t, u, model.alpha, model.a1, model.a2, model.b)
    assert np.max(np.abs(out - ref)) < 1e-5 * np.ptp(ref)


def test_the_free_responses_block_does_not_void_the_covariance_of_the_others():
    """A stream in operation fits eight free responses (0.01-30 /s) and an offset, nearly collinear over a window:
    their block alone puts the normal matrix's condition beyond the 1e13 the inverse is trusted at, and every
    variance read inf (quality "provisional" at the noise floor for seconds, issue 8). Flagged ``window.LINEAR``
    they are left out of that test, and the others' variances are the exact least squares' (QR of the regressor),
    not a prior's: steps' creep, its alpha-derivative and a ringing mode on 6 s and 12 s windows."""
    rng = np.random.default_rng(0)
    for span in (12.0, 6.0):
        t = np.linspace(0.0, span, 6001)
        steps = np.arange(0.3, span, 1.0)
        du = rng.uniform(-1.0, 1.0, steps.size)
        lag = [np.clip(t - s, 0.0, None) for s in steps]
        creep = sum(d * x ** 0.3 for d, x in zip(du, lag))
        dcreep = sum(d * x ** 0.3 * np.log(np.maximum(x, 1e-12)) for d, x in zip(du, lag))
        ring = sum(d * np.exp(-30.0 * x) * np.sin(150.0 * x) for d, x in zip(du, lag))
        J = np.column_stack([dcreep, creep, ring, np.ones_like(t)] + [np.exp(-m * t) for m in DEFAULT.window_free_rates])
        H = J.T @ J
        n = H.shape[0]
        exact = np.sum(np.linalg.solve(np.linalg.qr(J, mode="r"), np.eye(n)) ** 2, axis=1)[:3]
        cov = np.empty((n, n))
        free = np.ones(n)
        free[3:] = W.LINEAR
        W.covariance(H, free, cov)
        # 1 %: the normal equations cannot do better than ~cond(H) x eps. The 6 s window's H has a condition of
        # ~3.5e14: the exact inverse of H as rounded (math.fsum of its entries) differs from the QR's variances
        # by 4.5e-3, and the kernel's by 2.6e-3 with AVX-512's BLAS products (1e-4 had held with AVX2's)
        np.testing.assert_allclose(np.diag(cov)[:3], exact, rtol=1e-2)
    W.covariance(H, np.ones(n), cov)               # the same 6 s window, every parameter judged: refused
    assert np.all(np.isinf(cov))


def test_small_cholesky_covariance_equals_numpy_inverse_and_refuses_singular():
    """The hand-rolled Cholesky inverse (no LAPACK call per re-fit) against numpy, on random SPD matrices."""
    rng = np.random.default_rng(3)
    for n in (5, 9, 11):
        J = rng.normal(size=(40, n)) * np.geomspace(1e-4, 1e4, n)      # badly scaled columns
        H = J.T @ J
        free = np.ones(n)
        free[rng.integers(n)] = 0.0                 # a held parameter: its row and column drop out
        cov = np.empty((n, n))
        W.covariance(H, free, cov)
        keep = free == 1.0
        ref = np.linalg.inv(H[np.ix_(keep, keep)])
        np.testing.assert_allclose(cov[np.ix_(keep, keep)], ref, rtol=1e-8)
        x = rng.normal(size=n)
        L = np.empty((n, n))
        assert W._cholesky(H, L)
        out = np.empty(n)
        W._cholesky_solve(L, x, out)
        np.testing.assert_allclose(H @ out, x, rtol=1e-6, atol=1e-9 * np.abs(x).max())
    singular = np.ones((4, 4))                      # rank one
    cov = np.empty((4, 4))
    W.covariance(singular, np.ones(4), cov)
    assert np.all(np.isinf(cov))


@pytest.mark.parametrize("free, drift", [(False, 0), (True, 2)])
def test_a_tracker_built_ahead_and_started_equals_one_built_at_the_estimate(free, drift):
    """``OnlineEstimator`` builds its trackers before the stream at a placeholder resonance and calls
    ``WindowTracker.start(theta)`` when the start-up search ends: the state, statistics, context and
    schedule must be those of a tracker built at theta directly, and so must what it does with samples."""
    h = 1e-4
    basis = SoeBasis.build(h, top=SOE_TOP)
    theta = np.array([0.3, math.log(2.0e-4), math.log(4.0e-7), 1.7, 0.01])
    placeholder = np.array([0.45, math.log(h * 3.2), math.log((h * 3.2) ** 2), 1.0, 0.0])

    def build(th: np.ndarray) -> WindowTracker:
        return WindowTracker(basis, th, window_s=10.0, free=free, ring=np.zeros((2, 1 << 12)), gate=0.0, burst=3,
                             stuck=10**9, alpha_bounds=ONLINE_ALPHA_BOUNDS, refit_every=50, test_every=5000,
                             detect=True, drift=drift)

    direct, ahead = build(theta), build(placeholder)
    ahead.start(theta)
    np.testing.assert_array_equal(ahead.st, direct.st)
    np.testing.assert_array_equal(ahead.S, direct.S)
    np.testing.assert_array_equal(ahead._ctx, direct._ctx)
    rng = np.random.default_rng(4)
    u = np.repeat(rng.uniform(-1, 1, 20), 100)
    y = simulate(CreepModel(0.3, 2.0e-4, 4.0e-7, 1.7), np.arange(u.size) * h, u) + rng.normal(0, 1e-3, u.size)
    np.testing.assert_array_equal(_feed(ahead, u, y), _feed(direct, u, y))
    ahead.finish()
    direct.finish()
    np.testing.assert_array_equal(ahead.theta, direct.theta)


def test_grid_frequencies_equal_numpy_geomspace_bit_for_bit():
    """The search's grid frequencies (three numpy calls instead of np.geomspace's Python, inside update()) are
    np.geomspace's to the last bit, over the spans and rates the searches use."""
    from creep_online.online.search import GRID_FREQS, grid_frequencies
    for h in (1e-4, 2e-4, 5e-4, 1e-3, 1 / 3000, 1e-2):
        for rows in (2, 17, 500, 1499, 5001, 20000, 1 << 15):
            f_hi = 0.3 / h
            f_lo = min(max(1.0 / (rows * h), 1e-3), f_hi / 16)
            mine, ref = grid_frequencies(f_lo, f_hi), np.geomspace(f_lo, f_hi, GRID_FREQS)
            assert mine.dtype == ref.dtype and mine.tobytes() == ref.tobytes(), (h, rows)


def test_distinct_picks_equal_a_stable_sort_then_the_neighbour_rule():
    """The grid's ranking (one insertion per point) is a stable sort by cost, and its picks are those of the plain
    rule: points in that order (ties keep the grid's order, non-finite costs end the list), each kept unless its
    resonance neighbours a better pick's."""
    from creep_online.online.search import _GRID_ZETAS, GRID_FREQS, REFINE, _distinct_picks, _rank, _same_resonance, \
        grid_frequencies
    rng = np.random.default_rng(5)
    freqs = grid_frequencies(20.0, 3000.0)
    n = 6 * GRID_FREQS * _GRID_ZETAS.size
    for trial in range(200):
        costs = rng.choice([0.5, 1.0, 2.0, math.inf], n) if trial % 2 else rng.uniform(0, 1, n)
        costs[rng.integers(n, size=5)] = 0.0
        ranked = sorted(range(n), key=lambda i: costs[i])
        picks: list[int] = []
        for i in ranked:
            if len(picks) == REFINE or not math.isfinite(costs[i]):
                break
            point = (freqs[(i // _GRID_ZETAS.size) % GRID_FREQS], _GRID_ZETAS[i % _GRID_ZETAS.size])
            if not any(_same_resonance(*point, freqs[(j // _GRID_ZETAS.size) % GRID_FREQS],
                                       _GRID_ZETAS[j % _GRID_ZETAS.size]) for j in picks):
                picks.append(i)
        mine, ranked = np.empty(REFINE, dtype=np.int64), np.empty(n, dtype=np.int64)
        kept = costs.copy()
        for i in range(n):
            _rank(kept[i], i, costs, ranked)
        assert ranked.tolist() == sorted(range(n), key=lambda i: kept[i])
        assert mine[:_distinct_picks(costs, ranked, n, freqs, _GRID_ZETAS, mine)].tolist() == picks


def test_a_search_on_shared_scratch_equals_one_on_its_own():
    """Searches that reuse their owner's work arrays (``SearchScratch``, allocated ahead) give the results of
    searches that allocate their own, also after another search has used them."""
    from creep_online.online.search import SearchScratch
    h = 1e-3
    t = np.arange(400) * h
    u = np.where(t >= 0.01, 1.0, 0.0)
    y = simulate(CreepModel.from_resonance(0.3, 25.0, 0.2, 1.2), t, u)
    basis = SoeBasis.build(h, top=SOE_TOP)
    scratch = SearchScratch(basis.size)
    ResonanceSearch(basis, u, -y, scratch=scratch).run()
    zeta0 = np.linspace(0.0, 1.0, basis.size)
    for kwargs in ({}, {"zeta0": zeta0, "lead": 40, "fixed_alpha": 0.3}):
        own = ResonanceSearch(basis, u, y, **kwargs).run()
        shared = ResonanceSearch(basis, u, y, scratch=scratch, **kwargs).run()
        assert shared == own


def test_block_over_a_range_equals_block_over_slices():
    """The start-up replay feeds ranges of the buffer (no slices from Python): the same states, statistics,
    ring and statuses as the slices."""
    h = 1e-4
    model = CreepModel.from_resonance(0.2, 300.0, 0.1, 1.5)
    rng = np.random.default_rng(6)
    u = np.repeat(rng.uniform(-1, 1, 8), 50)
    y = simulate(model, np.arange(u.size) * h, u) + rng.normal(0, 1e-3, u.size)
    sliced, ranged = _tracker(model, h), _tracker(model, h)
    s1, s2 = np.zeros(u.size, dtype=np.int64), np.zeros(u.size, dtype=np.int64)
    for k in range(0, u.size, 37):
        used = sliced.feed_block(u[k:k + 37], y[k:k + 37], s1[k:])
        assert ranged.feed_block(u, y, s2[k:], k, min(k + 37, u.size)) == used
    np.testing.assert_array_equal(s1, s2)
    for a, b in ((sliced.st, ranged.st), (sliced.S, ranged.S), (sliced.ring, ranged.ring)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(6))
def test_the_hand_written_cholesky_gain_equals_a_dense_solve(seed):
    """window.gn_gain (the drift score test's g^T H^-1 g over the free parameters, a Cholesky in preallocated
    scratch instead of LAPACK) against numpy's solve, on random SPD matrices with ill-scaled rows; and 0 for a
    singular H (two equal free columns)."""
    rng = np.random.default_rng(seed)
    k = 7
    m = rng.standard_normal((k, 3 * k)) * np.logspace(-3, 3, k)[:, None]
    H, g = m @ m.T, rng.standard_normal(k) * np.logspace(-2, 2, k)
    mask = (rng.uniform(size=k) < 0.7).astype(float)
    mask[0] = 1.0
    free = np.flatnonzero(mask)
    scratch = (np.empty((k, k)), np.empty(k), np.empty(k))
    expected = g[free] @ np.linalg.solve(H[np.ix_(free, free)], g[free])
    assert W.gn_gain(H, g, mask, *scratch) == pytest.approx(expected, rel=1e-9)
    H2 = H.copy()
    H2[:, 1], H2[1, :] = H2[:, 0], H2[0, :]
    H2[1, 1] = H2[0, 0]
    mask[:2] = 1.0
    assert W.gn_gain(H2, g, mask, *scratch) == 0.0


@pytest.mark.parametrize("seed", range(6))
def test_the_step_factor_holds_the_directions_it_is_not_positive_definite_in(seed):
    """window.cholesky_holding (the damped step's factor): on a positive definite matrix the plain Cholesky factor,
    bit for bit, none held; on a unit-diagonal matrix with one parameter's diagonal negative (a Gauss-Newton
    matrix in rounding, as the window's ln a2 entry of a resonance at an SOE node) that parameter is held and the
    solve is numpy's on the others, its step 0."""
    rng = np.random.default_rng(seed)
    k = 7
    m = rng.standard_normal((k, 3 * k))
    H = m @ m.T
    d = np.sqrt(np.diag(H))
    A = H / np.outer(d, d)
    ref = np.tril(A.copy())
    assert W.cholesky_factor(ref, ref, k, 0.0)
    got, x = A.copy(), rng.standard_normal(k)
    assert W.cholesky_holding(got, k, x) == 0
    np.testing.assert_array_equal(np.tril(got), np.tril(ref))
    bad = int(rng.integers(1, k))
    A[bad, bad] = -1.0
    A[bad, :bad] *= 1e-3                             # (its other entries near zero: the column is rounding)
    A[:bad, bad] = A[bad, :bad]
    A[bad + 1:, bad] *= 1e-3
    A[bad, bad + 1:] = A[bad + 1:, bad]
    rhs = rng.standard_normal(k)
    factor, x = A.copy(), rhs.copy()
    assert W.cholesky_holding(factor, k, x) == 1 and x[bad] == 0.0
    W._cholesky_solve_in_place(factor, x, k)
    keep = np.arange(k) != bad
    np.testing.assert_allclose(x[keep], np.linalg.solve(A[np.ix_(keep, keep)], rhs[keep]), rtol=1e-9)
    assert x[bad] == 0.0


def test_a_free_column_that_died_out_is_held_not_divided_by():
    """A stream in operation fits free responses up to 30 /s: after a replay from ~40 s into the stream their
    columns are exp(-1200) = 0 over the whole window, their diagonal of J^T J exactly 0. The score test's gain
    divided by sqrt(0) + 1e-300 twice, whose product underflows to 0 (ZeroDivisionError inside update(), the
    latency stream cut from operation at 46.7 s), and the covariance read every variance inf. Such a parameter
    carries no information: the gain and the covariance are those of the others, its own variance inf."""
    rng = np.random.default_rng(4)
    k = 6
    m = rng.standard_normal((k, 4 * k))
    m[3] = 0.0                                       # the dead column
    H, g = m @ m.T, rng.standard_normal(k)
    g[3] = 0.0
    mask = np.ones(k)
    live = [0, 1, 2, 4, 5]
    scratch = (np.empty((k, k)), np.empty(k), np.empty(k))
    expected = g[live] @ np.linalg.solve(H[np.ix_(live, live)], g[live])
    assert W.gn_gain(H, g, mask, *scratch) == pytest.approx(expected, rel=1e-9)
    cov = np.empty((k, k))
    for free in (np.ones(k), np.where(np.arange(k) == 3, W.LINEAR, 1.0)):
        W.covariance(H, free, cov)
        np.testing.assert_allclose(cov[np.ix_(live, live)], np.linalg.inv(H[np.ix_(live, live)]), rtol=1e-8)
        assert cov[3, 3] == np.inf


def test_a_long_stream_taken_in_operation_runs_through_its_replays():
    """The latency stream of bench_online.py cut from operation 10.05 s in (payload at 40 s): a replay after the
    change leaves the fastest free responses' columns zero over the window; update() raised ZeroDivisionError
    at 46.7 s. It runs to the end, follows the change and ends within 1 % of the plant."""
    from creep_online.online.estimator import OnlineEstimator
    from bench import bench_online as bench
    s = bench.make_stream(100.0, in_operation_s=10.05)
    n = int(52.0 / bench.H)
    est = OnlineEstimator(bench.H)
    update = est.update
    for uk, yk in zip(s["u"][:n].tolist(), s["y"][:n].tolist()):
        update(uk, yk)
    e = est.estimate
    assert e.events and e.events[0]["moved"] == ["a2"]
    for name in ("alpha", "a1", "a2", "b"):
        assert getattr(e, name) == pytest.approx(s["truth"][name][n - 1], rel=0.01), name


@pytest.mark.parametrize("past", [0.0, 1.0])
def test_the_wide_test_is_the_gauss_newton_gain_of_the_extra_free_responses(past):
    """A stream in operation fits four of its eight free responses until the wide test frees the others: after a
    converged re-fit, (gain over the fit's parameters with the other four freed - gain without) / the noise
    variance, each gain g^T H^-1 g at the result with the free responses' relative prior on the scaled
    diagonal (``window.linear_gain``), against numpy's solve; the extra four stay at zero until then, and the
    switch is on above WIDE_ON. ``past``: the creep of a step of this size 20 ms before the record,
    b (t + 0.02)^alpha / Gamma(1 + alpha), on the output (a noise-level gain without it; the switch with it)."""
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 4000
    t = np.arange(n) * h
    u = _staircase(n, 300, 9)
    y = simulate(model, t, u) + np.random.default_rng(9).normal(0, 1e-3, n)
    y = y + past * model.b * (t + 0.02) ** model.alpha / math.gamma(1.0 + model.alpha)
    # (the drift's score test waits for a window of drift_min_s: longer than this record, so the wide test runs)
    tr = _tracker(CreepModel.from_resonance(0.12, 33.0, 0.25, 0.9), h, free=True, drift=2,
                  settings=replace(DEFAULT, drift_min_s=5.0))
    _feed(tr, u, y)
    assert not tr.free_wide
    extra = [5 + i for i, rate in enumerate(DEFAULT.window_free_rates) if rate not in DEFAULT.window_free_start]
    lam, dx = tr.basis.lam, tr.basis.dx
    RF.begin(tr.st, tr.S, tr._shift, tr._wk, 0, False, True, 0, True)      # converged, the test due
    RF.run(tr.st, tr.S, tr._shift, tr.theta, tr._wk, lam, dx)
    head, fitted, _ = RF.result(tr._wk)
    assert head[RF.RF_DRIFT] == 0.0 and head[RF.RF_WIDE_DUE] == 1.0     # (the window spans < drift_min_s)
    assert all(fitted[i] == 0.0 for i in extra)
    st, S, shift = tr.st.copy(), tr.S.copy(), tr._shift.copy()
    F, fy = np.empty((tr.p, tr.p)), np.empty(tr.p)
    W.move_origin(st, S, shift)
    fyy = W.scaled_statistics(st, S, F, fy)
    k = len(fitted)
    H, g = np.empty((k, k)), np.empty(k)
    W.lm_normal(np.array(fitted), head[RF.RF_A1L], head[RF.RF_A2L], lam, dx, F, fy, fyy, H, g)

    def gain(free_idx: list[int]) -> float:
        d = np.sqrt(np.abs(np.diag(H)))[free_idx]
        A = H[np.ix_(free_idx, free_idx)] / np.outer(d, d)
        A[np.diag_indices_from(A)] += [W.LINEAR_PRIOR if 4 <= i < 5 + tr.n_free else 0.0 for i in free_idx]
        r = g[free_idx] / d
        return float(r @ np.linalg.solve(A, r))

    narrow = [i for i in range(k - 2) if i not in extra]                # rates off (MASK_CONSTANT)
    sigma2 = head[RF.RF_AFTER] / (head[RF.RF_NEFF] - k)
    expected = (gain(narrow + extra) - gain(narrow)) / sigma2
    assert expected > 0.1                                              # (a gain to compare)
    assert head[RF.RF_WIDE_STAT] == pytest.approx(expected, rel=1e-6)
    assert tr.free_wide == (expected > DEFAULT.wide_on) == (past > 0.0)      # (0.6 and 1566 here)


def test_the_buffer_noise_median_is_numpys_median_bit_for_bit():
    """``window.noise_level`` selects the median in place (no copy, one selection); against ``np.median`` on 2000
    random buffers: odd and even counts, many ties, sorted and reversed input, a constant with a few outliers."""
    rng = np.random.default_rng(7)
    scale = 0.6745 * math.sqrt(6.0)
    for trial in range(2000):
        k = int(rng.integers(8, W.NOISE_SEED_ROWS + 1))
        x = np.abs(rng.standard_normal(k))
        kind = trial % 5
        if kind == 1:
            x = np.round(x * 3) / 3
        elif kind == 2:
            x = np.sort(x)
        elif kind == 3:
            x = np.sort(x)[::-1].copy()
        elif kind == 4:
            x = np.full(k, 0.25)
            x[rng.integers(0, k, 5)] = 1.0
        scratch = np.full(W.NOISE_SEED_ROWS, np.nan)
        scratch[:k] = x
        assert W.noise_level(scratch, k) == float(np.median(x)) / scale, (trial, k)
    assert W.noise_level(np.ones(W.NOISE_SEED_ROWS), 7) == 0.0
