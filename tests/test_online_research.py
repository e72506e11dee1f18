"""The tracker's re-search trigger, its resonance bounds and the search's row sampling (issue 8).

The local re-fits never leave a wrong resonance basin; the re-search trigger
(``Researcher.watch``) searches the resonance again when the window's error
stays above the noise floor. The plants are built here, not taken from the
bench's seeds.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from creep_online.online import OnlineEstimator, OnlineSettings
from creep_online.online._kernels import fit_machine as RF
from creep_online.online.trackers import window as T
from creep_online.online.trackers.settings import DEFAULT
from creep_online.online.search import ResonanceSearch
from creep_online.online.soe import SoeBasis
from hil_sim.scenarios import simulate_tv

TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
H = 1e-4


def _resonance(fn: float, zeta: float) -> tuple[float, float]:
    wn = 2 * math.pi * fn
    return 2 * zeta / wn, 1 / wn**2


def _quiet_start_record(alpha: float, fn: float, zeta: float, b: float, seed: int, seconds: float = 8.0,
                        noise: float = 0.01):
    """Small steps (0-0.1) every 0.3 s from 0.1 s, then steps to +-1 every 0.5 s from 2.5 s; noise ``noise`` b.

    The start-up search sees the resonance only through the small steps, near the noise.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds / H)) * H
    small = rng.uniform(0.0, 0.1, 64)
    big = rng.uniform(-1.0, 1.0, 64)
    u = np.where(t >= 0.1, small[((t - 0.1) / 0.3).astype(int) % 64], 0.0)
    u = np.where(t >= 2.5, big[((t - 2.5) / 0.5).astype(int) % 64], u)
    a1, a2 = _resonance(fn, zeta)
    y = simulate_tv(H, u, alpha, a1, a2, b) + rng.normal(0.0, noise * abs(b), t.size)
    return u, y, {"alpha": alpha, "a1": a1, "a2": a2, "b": b}


def _run(u: np.ndarray, y: np.ndarray, single: bool = False, **kwargs) -> OnlineEstimator:
    est = OnlineEstimator(H, **kwargs)
    if single:
        for a, b in zip(u.tolist(), y.tolist()):
            est.update(a, b)
    else:
        for k in range(0, u.size, 1000):
            est.update_block(u[k:k + 1000], y[k:k + 1000])
    return est


def _errors(est: OnlineEstimator, truth: dict) -> dict:
    e = est.estimate
    return {k: abs(getattr(e, k) / truth[k] - 1) for k in TOL}


@pytest.fixture(scope="module")
def wrong_basin_record():
    # alpha 0.4, 10 Hz, zeta 0.05: from the small steps the start-up search lands in a wrong basin that the
    # re-fits alone do not leave. (alpha 0.3, 8 Hz, seed 1 was the record here until replays became twice as
    # fast: the re-fits, each replayed at its new point sooner, now walk out of that basin alone. Of 48
    # records scanned, plants alpha 0.2-0.5, 5-15 Hz, zeta 0.02-0.05, seeds 1-6, with the change test off,
    # 4 stay wrong without the re-search; this one is left by it in block mode and sample by sample.)
    return _quiet_start_record(0.4, 10.0, 0.05, 1.0, seed=3)


@pytest.mark.parametrize("single", [False, True], ids=["block", "single"])
def test_a_wrong_basin_start_is_left_by_the_research(wrong_basin_record, single):
    u, y, truth = wrong_basin_record
    # the change test off: a change declared on the walking start-up estimate also corrects it (sample by
    # sample it does here, at 2.0 s), and this is the re-search's test
    est = _run(u, y, single, detect_changes=False)
    err = _errors(est, truth)
    assert all(err[k] <= TOL[k] for k in TOL), err
    switched = [r for r in est.estimate.researches if r["switched"]]
    assert switched and set(switched[0]["moved"]) & {"a1", "a2"}
    assert switched[0]["lr"] > DEFAULT.research.lr and "noise floor" in switched[0]["reason"]
    assert est.estimate.quality == "good"


def test_without_the_research_the_wrong_basin_is_kept(wrong_basin_record, monkeypatch):
    """The same record with the trigger off: the re-fits stay in the wrong basin (what the trigger fixes)."""
    monkeypatch.setattr(T, "DEFAULT", replace(DEFAULT, research=replace(DEFAULT.research, ratio=math.inf)))
    u, y, truth = wrong_basin_record
    est = _run(u, y, detect_changes=False)
    err = _errors(est, truth)
    assert not all(err[k] <= TOL[k] for k in TOL), err
    assert est.estimate.researches == [] and est.estimate.quality != "good"


def test_resonance_bounds_keep_the_fit_representable():
    """A fit that collapses a2 (fn far beyond Nyquist) or drives zeta out of 0.003-3 is projected back."""
    est = _run(*_quiet_start_record(0.1, 50.0, 0.2, 1.0, seed=3, seconds=3.0)[:2])
    tr = est._tracker
    theta = tr.theta.copy()
    theta[1], theta[2] = math.log(2.2e-4), math.log(3.8e-11)      # seen on a drifting plant: a NaN window
    assert RF.bound_resonance(theta, tr._wk)
    fn = 1 / (2 * math.pi * math.exp(0.5 * theta[2]))
    zeta = math.exp(theta[1]) / (2 * math.exp(0.5 * theta[2]))
    assert fn == pytest.approx(DEFAULT.fn_max_fs / H) and T.ZETA_BOUNDS[0] <= zeta <= T.ZETA_BOUNDS[1] * (1 + 1e-12)
    inside = tr.theta.copy()
    assert not RF.bound_resonance(inside, tr._wk) and np.array_equal(inside, tr.theta)


def test_search_rows_do_not_alias_the_resonance():
    """Every 5th row of a 10 kHz record (2 kHz) cannot tell 1168 Hz ringing from 835 Hz (1168 aliases to
    832 Hz): with fixed-stride rows the strided cost of the wrong resonance was 1.2x the right one's (the
    post-change search picked it), with rows at hashed offsets it is as far above as on every row."""
    rng = np.random.default_rng(0)
    t = np.arange(10585) * H                          # 1 s after a change, one step in it
    u = np.where(t < 0.4, 0.3, -0.5)
    a1, a2 = _resonance(835.0, 0.0232)
    y = simulate_tv(H, u, 0.0238, a1, a2, -0.188) + rng.normal(0.0, 1.07e-3, t.size)
    search = ResonanceSearch(SoeBasis.build(H), u, y)
    for _ in search._history():
        pass

    def cost(fn: float, zeta: float, stride: int) -> float:
        gen = search._evaluate(0.0238, *_resonance(fn, zeta), stride)
        while True:
            try:
                next(gen)
            except StopIteration as done:
                return done.value[0]

    every_row = cost(1168.0, 0.017, 1) / cost(835.0, 0.0232, 1)
    strided = cost(1168.0, 0.017, 5) / cost(835.0, 0.0232, 5)
    assert every_row > 30
    assert strided > 0.5 * every_row


def test_a_research_reaches_the_stream_json_text_and_trace(tmp_path, capsys):
    """Issue 8: a re-search that replaced the resonance is reported where changes are (JSON, text, trace)."""
    import csv
    import json

    from creep_online.cli import main
    from creep_online.io.csvfile import save_csv

    # a wrong start-up basin that the stream's re-search leaves at 1.3 s (with the change test on, as in
    # the command); the start-up search window held at 0.05 s (--t-c): left to grow, the search gets this
    # plant's basin at the start and there is nothing to re-search
    u, y, _ = _quiet_start_record(0.3, 8.0, 0.05, 1.0, seed=1)
    path = tmp_path / "quiet.csv"
    save_csv(path, np.arange(u.size) * H, u, y)
    trace = tmp_path / "trace.csv"
    assert main(["stream", "--source", f"csv:{path}", "--block", "--json", "--t-c", "0.05",
                 "--trace", str(trace)]) == 0
    out = json.loads(capsys.readouterr().out)
    switched = [r for r in out["researches"] if r["switched"]]
    assert switched and set(switched[0]["moved"]) & {"a1", "a2"}
    with open(trace, newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows[0]["researches"] == "" and rows[-1]["researches"].startswith(f"{switched[0]['t']:.4g}:")
    # the same feed (block mode in the trace's 10 ms chunks: where a waiting job resumes depends on them)
    assert main(["stream", "--source", f"csv:{path}", "--block", "--t-c", "0.05",
                 "--trace", str(tmp_path / "again.csv")]) == 0
    text = capsys.readouterr().out
    assert f"resonance re-searched at t = {switched[0]['t']:.4g} s" in text and "likelihood ratio" in text


def _search_record(seconds: float, seed: int = 3):
    """A slow, moderately damped plant (2.7 Hz, zeta 0.2, alpha 0.28) after one input step, plus noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds / H)) * H
    u = np.where(t >= 0.05, 1.0, 0.0)
    a1, a2 = _resonance(2.7, 0.2)
    return u, simulate_tv(H, u, 0.28, a1, a2, 1.07) + rng.normal(0.0, 0.005, t.size)


def _searched(u: np.ndarray, y: np.ndarray, starts: list) -> ResonanceSearch:
    search = ResonanceSearch(SoeBasis.build(H), u, y, starts=starts)
    search.run()
    return search


def test_repeated_search_starts_are_refined_once():
    """After a first search its candidates often coincide: each basin is refined once (measured: three
    identical starts, each refined for 78000 units on a 2 s buffer, 23 s of stream sample by sample)."""
    u, y = _search_record(0.6)
    start = (0.2, 3.5, 0.3)
    once, thrice = _searched(u, y, [start]), _searched(u, y, [start] * 3)
    assert len(thrice.candidates) == 1 and thrice.result == once.result
    assert thrice.units == once.units


def test_a_refinement_stops_in_a_basin_already_found():
    """A start far from the plant (160 Hz) walks down into the basin a better start already refined: the
    walk stops there instead of converging a second time, and the pattern moves keep the walk short (without
    them it crawled down the (fn, zeta) valley for 74000 units, 7 s of stream at 10 kHz)."""
    u, y = _search_record(1.2)
    good, far = (0.28, 2.7, 0.2), (0.5, 160.0, 0.011)
    both = _searched(u, y, [good, far])
    alone = _searched(u, y, [good])
    far_alone = _searched(u, y, [far])
    assert both.result == alone.result
    assert abs(math.log(far_alone.result.a2 / alone.result.a2)) < 0.1    # the far start ends in the same basin
    walked = both.candidates[1]
    assert walked[0] > both.candidates[0][0]                              # stopped before converging ...
    assert both.units - alone.units < far_alone.units < 40000             # ... and sooner than alone


def test_a_slow_mode_quiet_start_converges_sample_by_sample():
    """Issue 8 item 2 (start from nothing): a 5.5 Hz mode with zeta 0.025 needs a 2 s start-up buffer; at
    one search step per sample its search outlasted a 10 s stream at 10 kHz (quality 'none' to the end).
    A unit is now three steps, as in the tracker's own searches, and repeats are refined once."""
    u, y, truth = _quiet_start_record(0.04, 5.5, 0.025, -6.5, seed=4, seconds=10.0)
    est = _run(u, y, single=True)
    err = _errors(est, truth)
    assert all(err[k] <= TOL[k] for k in TOL), (err, est.estimate.quality, est.estimate.reason)



def _drain(gen):
    """Run a unit generator to its return value."""
    try:
        while True:
            next(gen)
    except StopIteration as stop:
        return stop.value


def _ringing_segment(seed: int = 0, noise: float = 1e-3):
    """A unit-gain model from rest under steps, plus a free ringing of its own resonance (an unknown state at
    the segment's start), an offset and white noise; returns the model, t, u, y, the free response's rate and
    frequency, and the noise."""
    from creep_online.model import CreepModel
    from creep_online.simulate import simulate
    rng = np.random.default_rng(seed)
    a1, a2 = _resonance(6.0, 0.03)
    model = CreepModel(0.05, a1, a2, 1.0)
    t = np.arange(12000) * H
    u = np.where(t >= 0.05, 1.0, 0.0) + np.where(t >= 0.6, -0.7, 0.0)
    s = simulate(model, t, u)
    sigma, omega = -a1 / (2 * a2), math.sqrt(1 / a2 - (a1 / (2 * a2)) ** 2)
    free = np.exp(sigma * t) * (0.8 * np.cos(omega * t) - 0.5 * np.sin(omega * t))
    y = 1.7 * s + 0.3 + free + rng.normal(0.0, noise, t.size)
    return model, t, u, y, s, sigma, omega


def test_judged_cost_is_least_squares_with_the_free_responses():
    """search.judged_cost = min over gain, offset, the resonance's two free responses and the given decays of
    the mean squared error, against numpy's least squares on the exact simulator's output, the closed-form
    homogeneous solutions exp(sigma t) cos(omega t), exp(sigma t) sin(omega t) (the same span as the sampled
    ones) and exp(-mu t)."""
    model, t, u, y, s, sigma, omega = _ringing_segment()
    y = y + 0.4 * np.exp(-5.0 * t)                  # an earlier input's fading memory (a stream in operation)
    basis = SoeBasis.build(H, horizon_s=3600.0)
    for decays in ((), (1.0, 5.0)):
        for lead in (0, 3000):
            search = ResonanceSearch(basis, u, y, lead=lead)
            _drain(search._history())
            judged = _drain(search.judged_cost(model.alpha, model.a1, model.a2, decays))
            X = np.column_stack([s, np.ones_like(t), np.exp(sigma * t) * np.cos(omega * t),
                                 np.exp(sigma * t) * np.sin(omega * t)] + [np.exp(-mu * t) for mu in decays])[lead:]
            coef, *_ = np.linalg.lstsq(X, y[lead:], rcond=None)
            reference = np.mean((y[lead:] - X @ coef) ** 2)
            assert judged == pytest.approx(reference, rel=1e-3)
            if decays:
                assert judged == pytest.approx(1e-6, rel=0.05)     # the noise: nothing left unexplained


def test_judged_rows_count_the_rows_after_the_lead_with_an_output():
    """search.judged_rows: the rows the judged cost summed over (after the lead, the output not NaN), read off
    its Gram matrix once a judged cost ran, counted over the segment before; the same number both ways."""
    model, t, u, y, s, sigma, omega = _ringing_segment()
    y = y.copy()
    y[[10, 2999, 3000, 5000, 5001, 11999]] = np.nan
    expected = int(np.count_nonzero(~np.isnan(y[3000:])))
    search = ResonanceSearch(SoeBasis.build(H, horizon_s=3600.0), u, y, lead=3000)
    _drain(search._history())
    assert search.judged_rows() == expected          # (counted)
    judged = _drain(search.judged_cost(model.alpha, model.a1, model.a2, (1.0,)))
    assert math.isfinite(judged)
    assert search._judged_rows == expected           # (the Gram matrix's)
    assert search.judged_rows() == expected


def test_judged_cost_reaches_the_noise_floor_where_the_rest_start_cannot():
    """With a ringing resonance state at the segment's start the search's own cost (state at rest, 0.3 s
    lead against a 0.9 s decay) misses the true model by orders of magnitude; the judged cost finds the
    noise (a re-search once switched from a right estimate to alpha -95 % on such a comparison)."""
    model, t, u, y, s, sigma, omega = _ringing_segment(noise=1e-3)
    search = ResonanceSearch(SoeBasis.build(H, horizon_s=3600.0), u, y, lead=3000)
    _drain(search._history())
    rest, _, _ = _drain(search.exact_cost(model.alpha, model.a1, model.a2))
    judged = _drain(search.judged_cost(model.alpha, model.a1, model.a2))
    assert judged == pytest.approx(1e-6, rel=0.05)
    assert rest > 100 * judged


def test_free_fit_is_least_squares_with_the_unknown_start():
    """search._free_fit (what a search of a stream in operation ranks by, ``ResonanceSearch(free=...)``): the
    cost of ``_free_cost`` and the gain of numpy's least squares on [s, 1, free responses, decays]; the offset
    is the mean of y - b s (the decays and the constant are nearly collinear)."""
    from creep_online.online.search import _free_cost, _free_fit
    model, t, u, y, s, sigma, omega = _ringing_segment()
    y = y + 0.4 * np.exp(-5.0 * t)
    basis = SoeBasis.build(H, horizon_s=3600.0)
    decays = (1.0, 5.0)
    search = ResonanceSearch(basis, u, y, free=decays)
    _drain(search._history())
    G = _drain(search._free_gram(model.alpha, model.a1, model.a2, decays, 1))
    cost, b, c = _free_fit(G)
    X = np.column_stack([s, np.ones_like(t), np.exp(sigma * t) * np.cos(omega * t),
                         np.exp(sigma * t) * np.sin(omega * t)] + [np.exp(-mu * t) for mu in decays])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    assert cost == pytest.approx(_free_cost(G), rel=1e-6)      # (the ranking's elimination is scaled)
    assert cost == pytest.approx(np.mean((y - X @ coef) ** 2), rel=1e-3)
    assert b == pytest.approx(coef[0], rel=1e-4) and b == pytest.approx(1.7, rel=1e-3)
    assert c == pytest.approx(np.mean(y - b * s), rel=1e-5)      # (s: the exact simulator, not the SOE)
    # the search's own cost is that fit, on every row at stride 1 and on one row per block at a stride
    assert _drain(search.exact_cost(model.alpha, model.a1, model.a2))[0] == pytest.approx(cost, rel=1e-12)
    strided, b10, _ = _drain(search._evaluate(model.alpha, model.a1, model.a2, 10))
    assert strided == pytest.approx(1e-6, rel=0.3) and b10 == pytest.approx(1.7, rel=1e-2)
    # the strided rows evaluate the free responses in closed form (``_free_modes``): on every row, the same fit
    # as the recursion's, for an underdamped, an overdamped and a critically damped resonance
    from creep_online.online.search import _rows_free_sparse
    for a1, a2 in ((model.a1, model.a2), (2.5 * math.sqrt(model.a2), model.a2), (2 * math.sqrt(model.a2), model.a2)):
        G = _drain(search._free_gram(model.alpha, a1, a2, decays, 1)).copy()
        G2 = np.zeros_like(G)
        _drain(search._free_gram(model.alpha, a1, a2, decays, 1))       # (the candidate's coefficients)
        search._x[:] = 0.0
        _rows_free_sparse(search._hist, search.u, search.y, search._vz, search._v[-2], search._v[-1], search._rc,
                          search._x, np.array([1.0, 0.0]), (a1, a2), H, np.array(decays), 0, t.size, 1, 0, G2,
                          np.zeros((1, 1)), 0)
        assert _free_fit(G2)[0] == pytest.approx(_free_cost(G), rel=1e-6), (a1, a2)


def test_a_search_in_operation_shares_its_candidates_rows_bit_for_bit(monkeypatch):
    """A search of a stream taken in operation keeps the decays and the constant's, decays' and output's Gram
    entries of its first candidate at a stride (``FreeRowCache``) and gives every later candidate only its own
    entries: each candidate's Gram matrix, and the whole search's result, are those computed without it, bit for
    bit (a NaN row, a lead and a stride included)."""
    from creep_online.online import search as S
    model, t, u, y, s, sigma, omega = _ringing_segment()
    y = y[:3000] + 0.4 * np.exp(-5.0 * t[:3000])
    y[1234] = np.nan
    u = u[:3000]
    basis = SoeBasis.build(H, horizon_s=3600.0)
    decays = (0.03, 0.2, 1.0, 5.0)
    candidates = [(model.alpha, model.a1, model.a2), (0.2, 3 * model.a1, 0.5 * model.a2), (0.01, 1e-3, 1e-7)]

    def grams(cached: bool) -> list:
        search = ResonanceSearch(basis, u, y, free=decays, lead=37)
        search._bind()                             # (its scratch, bound on first use: patched below)
        if not cached:
            monkeypatch.setattr(search._rows_cache, "claim", lambda *a: (-1, 0))
        _drain(search._history())
        out = [_drain(search._free_gram(*c, decays, stride, closed=True)).copy()
               for stride in (3, 1) for c in candidates]
        monkeypatch.undo()
        return out

    for a, b in zip(grams(True), grams(False)):
        assert np.isfinite(a).all()        # (the overdamped candidate's free responses too: ``_free_modes``)
        assert np.array_equal(a, b)
    with_cache = ResonanceSearch(basis, u, y, free=decays).run()
    monkeypatch.setattr(S, "CACHE_ROWS", 0)
    without = ResonanceSearch(basis, u, y, free=decays).run()
    assert with_cache == without


@pytest.mark.parametrize("fn", [1.0, 30.0, 300.0, 2500.0])
def test_the_free_responses_shift_is_their_closed_form(fn):
    """The strided search rows advance the two free responses by their exact one-step shift (``_free_shift``):
    over 4000 rows each stays within 1e-11 of the closed form (``_free_modes``) relative to the largest value it
    has had (rounding: ~4000 steps of a few ulps; measured 2e-13), for damping from 0.003 to 3 and roots that
    merge (zeta 1 - 1e-6, 1, 1 + 1e-6); from t = 0.6 s too, where the overdamped closed form's 2qt > 709 (it
    once read 0 * inf there). Over a search's longest buffer (2^15 rows) from row 0, within 1e-10."""
    from creep_online.online.search import _free_modes, _free_shift
    h = 1e-4
    wn = 2 * math.pi * fn
    for z in (0.003, 0.05, 0.7, 1 - 1e-6, 1.0, 1 + 1e-6, 1.5, 3.0):
        a1, a2 = 2 * z / wn, 1 / wn ** 2
        m11, m12, m21, m22 = _free_shift(a1, a2, h)
        for r0 in (137, 6000):
            g = np.array(_free_modes(a1, a2, r0 * h))
            largest = np.abs(g)
            for k in range(r0, r0 + 4000):
                closed = np.array(_free_modes(a1, a2, k * h))
                largest = np.maximum(largest, np.abs(closed))
                assert np.isfinite(g).all()
                seen = largest > 1e-250          # (not where both have decayed into the subnormal range)
                assert (np.abs(g - closed)[seen] <= 1e-11 * largest[seen]).all(), (fn, z, r0, k, g, closed)
                g = np.array([m11 * g[0] + m12 * g[1], m21 * g[0] + m22 * g[1]])
    for z in (0.003, 1.5):                        # the longest buffer, lightly damped and overdamped
        a1, a2 = 2 * z / wn, 1 / wn ** 2
        m11, m12, m21, m22 = _free_shift(a1, a2, h)
        g1, g2, big1, big2, worst = 1.0, 0.0, 0.0, 0.0, 0.0
        for k in range(1 << 15):
            c1, c2 = _free_modes(a1, a2, k * h)
            big1, big2 = max(big1, abs(c1)), max(big2, abs(c2))
            worst = max(worst, abs(g1 - c1) / big1, abs(g2 - c2) / big2 if big2 > 0.0 else 0.0)
            g1, g2 = m11 * g1 + m12 * g2, m21 * g1 + m22 * g2
        assert worst <= 1e-10, (fn, z, worst)


def test_free_fit_reads_an_exact_fit_as_rounding():
    """A noisy output is never fitted exactly: a cost of 0 from ``_free_fit`` is rounding in nearly collinear
    regressors (a slow overdamped candidate won the start-up search of mid_operation seed 2 at 80 dB with
    it) and reads inf; the judge's ``_free_cost`` reports the 0."""
    from creep_online.online.search import _free_cost, _free_fit
    rng = np.random.default_rng(0)
    s = rng.normal(size=500)
    rows = np.column_stack([s, np.ones(500), np.zeros(500), np.zeros(500), s])    # y = s, free responses absent
    G = np.triu(rows.T @ rows)
    assert _free_cost(G) == 0.0
    assert _free_fit(G)[0] == math.inf


def test_a_search_in_operation_finds_the_plant_under_a_fading_memory():
    """A record cut from operation: 3 s of steps before it, then steps; the fading memory of those steps runs
    through the whole 0.4 s buffer. Ranked by a cost that starts at rest the search misses the resonance (it
    fits the memory instead); with the unknown start projected out (``free``: the tracker's decay rates) it
    finds the plant."""
    rng = np.random.default_rng(3)
    a1, a2 = _resonance(160.0, 0.3)
    alpha, b = 0.4, -6.0
    t = np.arange(int(3.4 / H)) * H
    levels = rng.uniform(-1.0, 1.0, 40)
    u = levels[(t / 0.15).astype(int)]
    y = simulate_tv(H, u, alpha, a1, a2, b)
    y = y + rng.normal(0.0, 1e-4 * np.sqrt(np.mean(y ** 2)), t.size)     # 80 dB
    cut = int(3.0 / H)
    u, y = u[cut:] - u[cut], y[cut:]
    basis = SoeBasis.build(H)
    found = {}
    for free in (None, T.FREE_RATES):
        r = ResonanceSearch(basis, u, y, free=free).run()
        fn, zeta = 1 / (2 * math.pi * math.sqrt(r.a2)), r.a1 / (2 * math.sqrt(r.a2))
        found[free] = {"alpha": r.alpha / alpha - 1, "fn": fn / 160.0 - 1, "zeta": zeta / 0.3 - 1, "b": r.b / b - 1}
    # the search's basin (the window re-fits polish it): fn within 2 %, zeta and alpha within 50 % and 10 %, b 10 %
    # (the buffer also holds the fast memory of the last steps before it, which the decays only approximate)
    limits = {"alpha": 0.1, "fn": 0.02, "zeta": 0.5, "b": 0.1}
    assert not all(abs(v) < limits[k] for k, v in found[None].items()), found[None]
    assert all(abs(v) < limits[k] for k, v in found[T.FREE_RATES].items()), found


def test_a_high_snr_slow_mode_stays_at_the_noise_floor_sample_by_sample():
    """A 5.5 Hz mode with zeta 0.025 at a noise of 1e-4 of the gain (80 dB), sample by sample: the estimate
    ends within the tolerances at the noise floor and reads "good". Two things broke it: the re-search
    judged candidates with the resonance at rest at its segment's start (the ringing dominated every cost;
    it switched from a right estimate to alpha -95 %), and the window sat at 2-3x the floor because the
    first-order expansion 0.3 % from the linearization point is itself a misfit at this SNR
    (``tracker.RELINEARIZE_FINE``; this record: "degraded" at 2.45x the floor, alpha 0.28 % off, before it;
    seeds 0-11 of this plant: 1.0-1.22x after, three of them 1.7-2.45x before)."""
    u, y, truth = _quiet_start_record(0.04, 5.5, 0.025, -6.5, seed=5, seconds=8.0, noise=1e-4)
    est = _run(u, y, single=True)
    e = est.estimate
    err = _errors(est, truth)
    assert all(err[k] <= TOL[k] for k in TOL), (err, e.quality, e.reason)
    assert e.quality == "good", e.reason
    assert e.residual_rms < 1.25 * e.noise_rms


@pytest.mark.parametrize("single", [False, True], ids=["block", "single"])
def test_a_corrected_start_frees_alpha_at_once(single):
    """alpha 0.35, 7 Hz, zeta 0.02, seed 6: the start-up estimate is wrong and still moving when the change test
    corrects it (1.5 s; ``estimate_settled`` False sample by sample). The restart does not hold alpha after
    the post-change search: held, as after a plant change, it ended -5.5 % off sample by sample."""
    u, y, truth = _quiet_start_record(0.35, 7.0, 0.02, 1.0, seed=6)
    est = _run(u, y, single)
    err = _errors(est, truth)
    assert all(err[k] <= TOL[k] for k in TOL), err
    assert all(ev["estimate_settled"] is False for ev in est.estimate.events), est.estimate.events
    assert est.estimate.quality == "good"


def _run_to_end(job) -> np.ndarray:
    """Run a generator job (``Replayer.nodes_at``) to its return value."""
    try:
        while True:
            next(job)
    except StopIteration as stop:
        return stop.value


@pytest.mark.parametrize("history", [40_000, 1 << 19], ids=["history-wrapped", "history-whole"])
def test_a_node_mark_fast_forwards_to_the_same_state_as_the_history_tail(history):
    """A search's start state from the newest node mark is the one fast-forwarded from the history's oldest
    sample (the same recursion on the same inputs: equal to rounding), with the history wrapped or not."""
    u, y, _ = _quiet_start_record(0.3, 40.0, 0.05, 1.0, seed=2, seconds=12.0)
    est = OnlineEstimator(H, settings=OnlineSettings().replace(memory={"max_history": history}))
    for k in range(0, u.size, 1000):
        est.update_block(u[k:k + 1000], y[k:k + 1000])
    tr = est._tracker
    marks = tr._node_mark_at[tr._node_mark_at >= 0]
    assert marks.size >= 3 and marks.max() >= tr.n - 2 * tr._node_mark_every
    oldest = int(tr.sc[T.W.SC_RSTART])
    for n0 in (tr.n - 1, tr.n - 7000, oldest + (tr.n - oldest) // 2):
        from_mark = _run_to_end(tr.replayer.nodes_at(tr, n0))
        saved = tr._node_mark_at.copy()
        tr._node_mark_at.fill(-1)
        from_tail = _run_to_end(tr.replayer.nodes_at(tr, n0))
        tr._node_mark_at[:] = saved
        assert tr.replayer.nearest_mark(tr, n0, oldest) >= 0
        np.testing.assert_allclose(from_mark, from_tail, rtol=1e-12, atol=1e-14 * np.abs(from_tail).max())
