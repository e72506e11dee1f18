"""Block mode is per-sample feeding, bit for bit: the kernels, the deferred statistics, the input gate's runs.

``update_block`` runs the trackers' block kernels (``window.block``: the rank-one updates of S deferred and added
in one pass, ``window._flush``; ``recursive.block``) and takes the samples the input gate passes as runs
(``InputStage.passing_run``). Each is checked against the per-sample reference it replaces (``window.sample``,
``recursive.sample``, ``InputStage.classify``/``accept`` one by one): kernels on their own, with the block
stopping where a job reads S; then whole estimators on records with a change, gaps, missing outputs, input
glitches and the hysteresis effect, every estimate and the final statistics compared with ``==``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.effects.hysteresis import hysteresis_input, threshold_fractions
from creep_online.model import ONLINE_ALPHA_BOUNDS, CreepModel
from creep_online.online import OnlineEstimator
from creep_online.online import inputs as INP
from creep_online.online import search as S
from creep_online.online._kernels import recursive as R
from creep_online.online._kernels import window as W
from creep_online.online.soe import SOE_TOP, SoeBasis
from creep_online.online.trackers import recursive as TR
from creep_online.online.trackers.window import FREE_RATES, WindowTracker
from creep_online.simulate import simulate
from hil_sim import scenarios


# ---------------------------------------------------------------------- references (what block mode replaces)
def _per_sample(sample):
    """A block kernel made of per-sample calls (the reference ``window.block`` and ``recursive.block`` are)."""
    def block(u, y, st, S, ring, status, start=0, stop=-1):
        end = u.shape[0] if stop < 0 else stop
        for k in range(start, end):
            s = sample(u[k], y[k], st, S, ring)
            status[k - start] = s
            if s >= 8:
                return k - start + 1
        return end - start
    return block


def _gate_one_by_one(self, u, y):
    """``InputStage.block`` with every sample through ``classify`` and ``accept`` in turn."""
    est = self.est
    if not est._deferred and est._u_lo <= u.min() and u.max() <= est._u_hi:
        est._u_last = float(u[-1])
        return u - est._u_ref, y, True
    ready = list(est._backlog)
    est._backlog.clear()
    for k in range(u.size):
        ready.extend((self.accept(v), w) for v, w in self.classify(float(u[k]), float(y[k])))
    est._deferred = bool(est._held)
    out = np.array(ready, dtype=float).reshape(-1, 2)
    return np.ascontiguousarray(out[:, 0]), np.ascontiguousarray(out[:, 1]), False


def _reference(monkeypatch) -> None:
    monkeypatch.setattr(W, "block", _per_sample(W.sample))
    monkeypatch.setattr(TR, "block", _per_sample(R.sample))
    monkeypatch.setattr(INP.InputStage, "block", _gate_one_by_one)
    monkeypatch.setattr(INP.InputStage, "buffer_quiet", lambda self, u, y: 0)     # every sample through the start-up
    monkeypatch.setattr(S.ResonanceSearch, "eager", _NEVER_EAGER, raising=False)  # searches in units


#: ``ResonanceSearch.eager`` pinned to False: every search in units of ~UNIT_WORK, its grid one candidate at a time.
_NEVER_EAGER = property(lambda self: False, lambda self, value: None)


# ---------------------------------------------------------------------- kernels
@pytest.mark.parametrize("p, k", [(7, 0), (7, 1), (8, 7), (8, 8), (9, 17), (51, 64), (52, 63), (51, 3)])
def test_flush_adds_the_rows_as_the_rank_one_updates_do(p, k):
    """``_flush`` of k deferred rows = k calls of ``_accumulate`` (its multiply-adds in the same order), bit for bit
    on S's upper triangle (where the statistics are held), for odd and even P and any count of rows (eight-row
    passes and the rest)."""
    rng = np.random.default_rng(p * 100 + k)
    X = rng.standard_normal((W.DEFER_ROWS, p)) * np.exp(rng.uniform(-20, 20, p))
    gx = np.exp(rng.uniform(0, 200, W.DEFER_ROWS))
    S0 = rng.standard_normal((p, p))
    flushed = S0.copy()
    W._flush(flushed, X, gx, k)
    direct, sy, sc = S0.copy(), np.zeros(p), np.zeros(W.SC_SIZE)
    sc[W.SC_FORGET] = 1.0                     # (the weight stays what each row sets)
    for t in range(k):
        sc[W.SC_G] = gx[t]
        W._accumulate(0.0, X[t].copy(), direct, sy, sc)
    assert np.array_equal(np.triu(flushed), np.triu(direct))


def _window_tracker(window_s: float | None, drift: int, free: bool) -> tuple[WindowTracker, np.ndarray, np.ndarray]:
    model = CreepModel.from_resonance(0.1, 30.0, 0.3, 1.0)
    h, n = 1e-3, 3000
    basis = SoeBasis.build(h, top=SOE_TOP)
    theta = np.array([model.alpha, math.log(model.a1), math.log(model.a2), model.b, 0.0])
    tr = WindowTracker(basis, theta, window_s=window_s, free=free, ring=np.zeros((2, 1 << 11)), gate=4.0,
                       burst=3, stuck=10**9, alpha_bounds=ONLINE_ALPHA_BOUNDS, refit_every=10**9,
                       test_every=10**9, detect=False, drift=drift)
    rng = np.random.default_rng(drift + 3)
    u = np.repeat(rng.normal(size=n // 300 + 1), 300)[:n]
    y = simulate(model, np.arange(n) * h, u) + 1e-3 * rng.standard_normal(n)
    y[[7, 8, 40, 41, 42, 1500]] = np.nan
    y[[900, 2000]] += 5.0                      # (outliers: gated, not accumulated)
    tr.sc[W.SC_GATE] = 4.0
    return tr, u, y


@pytest.mark.parametrize("window_s, drift, free", [(None, 0, False), (1.0, 2, True), (0.01, 2, False)])
def test_window_block_is_sample_by_sample_wherever_it_stops(window_s, drift, free):
    """``window.block`` = ``window.sample`` per sample: state, statistics (S's upper triangle, where they are held),
    ring and statuses bit for bit, at each sample where the block stops for a job (which reads S: the deferred rows
    are in S by then), with missing outputs, outliers, the drift and free columns, and a window short enough (10 ms
    at 1 kHz) that the weight is renormalised inside a block."""
    tr, u, y = _window_tracker(window_s, drift, free)
    st, S, ring = tr.st.copy(), tr.S.copy(), tr.ring.copy()
    ref = (tr.st.copy(), tr.S.copy(), tr.ring.copy())
    status, expected = np.empty(u.size, dtype=np.int64), np.empty(u.size, dtype=np.int64)
    done = 0
    for due in (1, 2, 65, 66, 200, 777, 1500, 2999, 10**9):
        st[W.SC_DUE] = ref[0][W.SC_DUE] = due
        while done < u.size:
            used = W.block(u, y, st, S, ring, status[done:], done)
            for k in range(done, done + used):
                expected[k] = W.sample(u[k], y[k], *ref)
            done += used
            assert np.array_equal(np.triu(S), np.triu(ref[1])) and np.array_equal(st, ref[0], equal_nan=True)
            if status[done - 1] >= 8:
                break
    assert done == u.size
    assert np.array_equal(status, expected) and np.array_equal(ring, ref[2], equal_nan=True)
    if window_s == 0.01:
        assert st[W.SC_G] < 1e100            # (renormalised on the way: exp(0.1 n) ~ 1e130 unrenormalised)


# ---------------------------------------------------------------------- whole estimators
def _payload_record() -> tuple[float, np.ndarray, np.ndarray]:
    """A payload change 10 kHz record (to 2 s after the change), with missing outputs and input glitches."""
    scen = scenarios.make("payload", 1)
    end = min(scen.u.size, int((scen.change_time + 2.0) / scen.h))
    u, y = scen.u[:end].copy(), scen.y[:end].copy()
    rng = np.random.default_rng(5)
    y[rng.integers(1000, end, 40)] = np.nan
    for k in rng.integers(5000, end - 10, 6):      # single-sample spikes of the input: glitches
        u[k] += 3.0 * np.ptp(u)
    return scen.h, u, y


def _operation_record() -> tuple[float, np.ndarray, np.ndarray]:
    """A stream taken in operation (its input held at a level, then moving), 3 s at 10 kHz, with missing outputs."""
    scen = scenarios.make("mid_operation", 1)
    end = min(scen.u.size, int(3.0 / scen.h))
    u, y = scen.u[:end].copy(), scen.y[:end].copy()
    y[np.random.default_rng(6).integers(100, end, 30)] = np.nan
    return scen.h, u, y


def _hammerstein_record() -> tuple[float, np.ndarray, np.ndarray]:
    """A creep plant behind play operators (hysteresis), a 1 Hz triangle, 4 s at 2 kHz."""
    h = 5e-4
    t = np.arange(int(4.0 / h)) * h
    u = np.round(4.0 * (2 * np.abs(t % 1.0 - 0.5)) * 250) / 250
    r = threshold_fractions(8) * np.ptp(u)
    w = np.linspace(1.0, 0.2, 8)
    y = simulate(CreepModel.from_resonance(0.08, 120.0, 0.2, 1.3), t, hysteresis_input(u, r, w))
    return h, u, y + 1e-4 * np.ptp(y) * np.random.default_rng(2).standard_normal(t.size)


def _trajectory(make, u: np.ndarray, y: np.ndarray, pieces: np.ndarray, gaps: dict[int, int]) -> tuple[list, object]:
    """Every estimate after each piece fed by update_block (and a gap before the pieces named in ``gaps``)."""
    est = make()
    out = []
    for i, (a, b) in enumerate(zip(pieces[:-1], pieces[1:])):
        if i in gaps:
            est.gap(gaps[i])
        est.update_block(u[a:b], y[a:b])
        e = est.estimate
        out.append((e.quality, e.samples, e.alpha, e.a1, e.a2, e.b, e.residual_rms, e.noise_rms,
                    est.input_outliers, len(est.events)))
    return out, est


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(all(x == z or (x != x and z != z) for x, z in zip(ra, rb)) for ra, rb in zip(a, b))


_RECORDS = {"payload": _payload_record, "operation": _operation_record, "hammerstein": _hammerstein_record}


@pytest.mark.parametrize("record, kwargs", [("payload", {}), ("payload", {"refit": "recursive"}),
                                            ("operation", {}), ("operation", {"refit": "recursive"}),
                                            ("hammerstein", {"effects": ("hysteresis",)})])
def test_update_block_is_the_per_sample_kernels_and_gate(record, kwargs, monkeypatch):
    """Whole estimators, block mode against the same feeding through the per-sample kernels, the input gate and the
    start-up one sample at a time, and the searches in units: every estimate after every piece and the final
    statistics identical (``==``), on a change with missing outputs, gaps and input glitches, a stream taken in
    operation, both trackers, and with the hysteresis columns."""
    h, u, y = _RECORDS[record]()
    rng = np.random.default_rng(11)
    pieces = np.unique(np.concatenate(([0, u.size], rng.integers(0, u.size, 60),
                                       np.arange(0, u.size, int(0.1 / h)))))
    gaps = {5: 3, 30: 1, 45: 20}

    def make():
        return OnlineEstimator(h, **kwargs)

    fast, est_fast = _trajectory(make, u, y, pieces, gaps)
    with monkeypatch.context() as m:
        _reference(m)
        slow, est_slow = _trajectory(make, u, y, pieces, gaps)
    assert _same(fast, slow)
    assert fast[-1][0] != "none" and est_fast.samples == est_slow.samples
    assert est_fast.estimate.internal_faults == 0     # (a kernel that failed to compile is a fault, recovered from)
    assert np.array_equal(np.triu(est_fast._tracker.S), np.triu(est_slow._tracker.S))
    if record == "payload":
        assert est_fast.input_outliers > 0   # (the glitches went through the gate's one-by-one path)


@pytest.mark.parametrize("seed", range(6))
def test_input_gate_runs_are_the_rule_sample_by_sample(seed, monkeypatch):
    """``InputStage.block``'s runs against the rule one sample at a time, on random inputs that keep widening their
    range, with glitches (returning within the burst) and moves (staying), a gate narrower than one range too:
    the samples fed, the held ones and the range after every block the same."""
    rng = np.random.default_rng(seed)
    n = 6000
    u = np.cumsum(rng.standard_normal(n)) * 0.01 + np.repeat(rng.uniform(-1, 1, n // 500 + 1), 500)[:n]
    for k in rng.integers(100, n - 5, 12):
        u[k:k + rng.integers(1, 4)] += rng.choice([-1, 1]) * rng.uniform(2, 20)
    for k in rng.integers(100, n - 5, 3):
        u[k:] += rng.uniform(5, 10)                 # (moves: the input stays)
    y = 0.5 * u + 0.01 * rng.standard_normal(n)
    gate = float(rng.choice([0.4, 2.0]))

    def feed(stage_block):
        monkeypatch.setattr(INP.InputStage, "block", stage_block)
        est = OnlineEstimator(1e-3, input_gate=gate)
        fed, states = [], []
        pieces = np.unique(np.concatenate(([0, n], rng_pieces)))
        for a, b in zip(pieces[:-1], pieces[1:]):
            est.update_block(u[a:b], y[a:b])
            states.append((est.samples, est.input_outliers, est._u_lo, est._u_hi, est._u_last, len(est._held),
                           est._startup.first_change))
            if est._live is not None:
                fed.append(est._live.n)
        return states, fed, est

    rng_pieces = np.random.default_rng(seed + 100).integers(0, n, 40)
    fast = feed(INP.InputStage.__dict__["block"])
    slow = feed(_gate_one_by_one)
    assert fast[0] == slow[0] and fast[1] == slow[1]
    e_fast, e_slow = fast[2].estimate, slow[2].estimate
    assert _same([(e_fast.alpha, e_fast.b, e_fast.quality)], [(e_slow.alpha, e_slow.b, e_slow.quality)])


# ---------------------------------------------------------------------- searches
def _search_buffer(seed: int) -> tuple[SoeBasis, np.ndarray, np.ndarray, tuple | None, int]:
    """A random plant's response on a random stretch of a random staircase (from rest, or taken in operation: the
    input's past unknown), 300-6000 samples at 10 kHz, some outputs missing: (basis, u, y, free rates, lead)."""
    rng = np.random.default_rng(seed)
    h = 1e-4
    n = int(rng.integers(300, 6000))
    past = int(rng.integers(0, 2)) * int(rng.integers(500, 4000))
    levels = rng.uniform(-1.0, 1.0, (n + past) // 200 + 2)
    u = np.repeat(levels, 200)[:n + past]
    alpha = float(rng.uniform(0.02, 0.6))
    model = CreepModel.from_resonance(alpha, float(10 ** rng.uniform(1.5, 3.2)), float(10 ** rng.uniform(-2, 0)), 1.0)
    y = simulate(model, np.arange(n + past) * h, u)[past:]
    y = y + 1e-3 * np.ptp(y) * rng.standard_normal(n)
    y[rng.integers(0, n, n // 100)] = np.nan
    u = u[past:] - (u[past] if past else 0.0)
    free = FREE_RATES if past else None
    return SoeBasis.build(h), u, y, free, int(rng.integers(0, n // 8))


@pytest.mark.parametrize("seed", range(8))
def test_block_mode_search_is_the_search_in_units(seed):
    """``ResonanceSearch`` in block mode (``eager``: each candidate's rows in one kernel call, the grid's candidates
    side by side, ``_rows_batch``/``_rows_free_batch``) against the same search in units: every grid cost, the refined
    candidates and the result identical (``==``), from rest and in operation, on random plants and buffers."""
    basis, u, y, free, lead = _search_buffer(seed)
    out = []
    for eager in (False, True):
        search = S.ResonanceSearch(basis, u, y, lead=lead, free=free, alphas=(0.3,))
        search.eager = eager
        while not search.step():
            pass
        size = len(search.alphas) * S.GRID_FREQS * len(S.GRID_ZETA)
        out.append((search._scratch.costs[:size].copy(), search.candidates, search.result))
    (c_units, cand_units, r_units), (c_eager, cand_eager, r_eager) = out
    assert np.array_equal(c_units, c_eager, equal_nan=True) and np.isfinite(c_units).any()
    assert cand_units == cand_eager and r_units == r_eager


class _Forgetful(dict):
    """A cost memo that keeps nothing: every point is evaluated each time the walk reaches it."""

    def __setitem__(self, key, value) -> None:
        pass


def _evaluations(seed: int, monkeypatch) -> list[tuple]:
    """(result, candidates, evaluations) of the block-mode search of ``_search_buffer(seed)``, with its cost memo
    and with one that keeps nothing."""
    basis, u, y, free, lead = _search_buffer(seed)
    calls = [0]
    evaluate = S.ResonanceSearch._evaluate

    def counted(self, *args):
        calls[0] += 1
        return (yield from evaluate(self, *args))

    monkeypatch.setattr(S.ResonanceSearch, "_evaluate", counted)
    out = []
    for memo in (True, False):
        calls[0] = 0
        search = S.ResonanceSearch(basis, u, y, lead=lead, free=free, alphas=(0.3,))
        search.eager = True
        if not memo:
            search._costs = _Forgetful()
        out.append((search.run(), search.candidates, calls[0]))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_search_costs_each_point_once(seed, monkeypatch):
    """The refinements' pattern search comes back to points it has costed; the search keeps their costs
    (``ResonanceSearch._cost_at``): the refined candidates and the result identical (``==``) to a search that
    evaluates every point each time, from rest and in operation, with fewer evaluations (5-28 % fewer on these
    buffers)."""
    (result, candidates, kept), (result_every, candidates_every, every) = _evaluations(seed, monkeypatch)
    assert result == result_every and candidates == candidates_every
    assert 0 < kept < every


def _start_record(seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    """A random plant under a random start: at rest or at a held non-zero level for 0-1.5 s (the start-up's idle
    buffer and its reading of the start), then a random staircase with input glitches and missing outputs, 2.5 s at
    10 kHz."""
    rng = np.random.default_rng(seed)
    h, n = 1e-4, 25_000
    hold = int(rng.integers(0, 15_000))
    first = float(rng.choice([0.0, rng.uniform(-1.0, 1.0)]))
    steps = np.repeat(rng.uniform(-1.0, 1.0, n // 300 + 1), 300)[:n - hold]
    u = np.concatenate((np.full(hold, first), steps))
    model = CreepModel.from_resonance(float(rng.uniform(0.03, 0.5)), float(10 ** rng.uniform(1.7, 3.0)),
                                      float(10 ** rng.uniform(-1.7, -0.3)), 1.0)
    y = simulate(model, np.arange(n) * h, u)
    y = y + 1e-3 * np.ptp(y) * rng.standard_normal(n)
    y[rng.integers(0, n, 25)] = np.nan
    for k in rng.integers(hold + 100, n - 5, 3):
        u[k] += 4.0 * np.ptp(u)
    return h, u, y


@pytest.mark.parametrize("seed", range(6))
def test_block_mode_start_up_is_the_start_up_sample_by_sample(seed, monkeypatch):
    """The start-up in block mode (the samples between its steps buffered at once, ``InputStage.buffer_quiet``; the
    searches' candidates in one pass) against every sample through ``buffer_sample`` and ``advance`` and the searches
    in units, on random starts (at rest or held at a level for up to 1.5 s, then moving), random block lengths:
    every estimate after every block identical (``==``)."""
    h, u, y = _start_record(seed)
    rng = np.random.default_rng(seed + 50)
    pieces = np.unique(np.concatenate(([0, u.size], rng.integers(0, u.size, 30))))
    fast, est_fast = _trajectory(lambda: OnlineEstimator(h), u, y, pieces, {})
    with monkeypatch.context() as m:
        m.setattr(INP.InputStage, "buffer_quiet", lambda self, u, y: 0)
        m.setattr(S.ResonanceSearch, "eager", _NEVER_EAGER, raising=False)
        slow, est_slow = _trajectory(lambda: OnlineEstimator(h), u, y, pieces, {})
    assert _same(fast, slow) and est_fast.estimate.internal_faults == 0


def _feedings(feed: str, **kwargs) -> tuple:
    """``OnlineEstimator(h, **kwargs)`` on a hil_sim hysteresis record (a triangle, seed 1003, 12,000 samples at 10 kHz:
    a start-up, re-fits, replays at the new resonance; with the hysteresis columns every re-fit asks for one) fed
    sample by sample (``"sample"``), in random chunks (``"chunks"``) or in one block: the estimate, the hysteresis
    weights, the replays swapped in."""
    from hil_sim.hysteresis_plants import hysteresis_record
    rec = hysteresis_record("triangle", 1003, n=12_000)
    est = OnlineEstimator(float(rec.t[1] - rec.t[0]), **kwargs)
    if feed == "sample":
        for a, b in zip(rec.u.tolist(), rec.y.tolist()):
            est.update(a, b)
    else:
        cuts = np.random.default_rng(7).integers(0, rec.u.size, 40) if feed == "chunks" else np.zeros(0, int)
        pieces = np.unique(np.concatenate(([0, rec.u.size], cuts)))
        for a, b in zip(pieces[:-1], pieces[1:]):
            est.update_block(rec.u[a:b], rec.y[a:b])
    e = est.estimate
    return ((e.quality, e.samples, e.alpha, e.a1, e.a2, e.b, e.residual_rms, e.noise_rms, len(e.events),
             est._tracker.relinearizations), tuple(e.hysteresis["w"]) if e.hysteresis else None)


@pytest.mark.parametrize("refit", ["window", "recursive"])
def test_estimate_is_the_same_per_sample_in_chunks_and_in_one_block(refit):
    """The plain estimator (both trackers) fed sample by sample, in random chunks and in one block: the same estimate
    (``==``). The background work (the start-up search going live, each re-fit and replay swapped in) lands at the
    sample where update()'s work budget puts it, whatever the feeding: block mode feeds sample by sample while work
    is under way (``OnlineEstimator._feed_block``)."""
    runs = {feed: _feedings(feed, refit=refit) for feed in ("block", "chunks", "sample")}
    assert runs["block"][0][0] != "none"
    assert runs["chunks"] == runs["block"] and runs["sample"] == runs["block"]


def test_hysteresis_estimate_is_the_same_per_sample_in_chunks_and_in_one_block():
    """The estimator with hysteresis fed sample by sample, in random chunks and in one block: the same estimate and
    hysteresis weights (``==``)."""
    runs = {feed: _feedings(feed, effects=("hysteresis",)) for feed in ("block", "chunks", "sample")}
    assert runs["block"][1] is not None
    assert runs["chunks"] == runs["block"] and runs["sample"] == runs["block"]
