"""The live prediction never diverges: per 1 s window its rms error stays below the output's own spread there.

A prediction worse than the window's mean is a divergence. The real records (tests/data/real, their SISO
``t,u,y`` columns) and the estimator's own rule for a search result far from its linearization point.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import DATA
from creep_online.online import OnlineEstimator
from creep_online.online.trackers.settings import DEFAULT

TRUST = DEFAULT.trust

REAL = DATA / "real"


def _window_ratios(path, **kwargs) -> list[float]:
    """Per full 1 s window where the estimator tracks: rms(y - last_prediction) / std(y)."""
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    t, u, y = data[:, 0], data[:, 1], data[:, 2]
    h = float(t[1] - t[0])
    est = OnlineEstimator(h, **kwargs)
    err = np.full(t.size, np.nan)
    for i, (a, b) in enumerate(zip(u.tolist(), y.tolist())):
        est.update(a, b)
        p = est.last_prediction
        if p is not None and est.phase == "tracking":
            err[i] = b - p
    w = int(round(1.0 / h))
    ratios = []
    for a in range(0, t.size - w + 1, w):
        e, ok = err[a:a + w], np.isfinite(err[a:a + w])
        if np.count_nonzero(ok) >= w // 2:
            ratios.append(float(np.sqrt(np.mean(e[ok] ** 2)) / np.std(y[a:a + w][ok])))
    return ratios


@pytest.mark.parametrize("alpha0", [None, 0.0686])
def test_the_150_volt_record_does_not_diverge(alpha0):
    """The real 150 V piezo record (hysteresis-dominated), the plain estimator with and without the batch fit's alpha
    as a hint (``creep-online fit --effects hysteresis --online`` gives it that hint): a re-search's resonance 900x
    from the live linearization point was predicted with at once, the states holding the old one to first order
    only, and one window's error reached 2.3e5 times the noise floor (~1000x the output's spread)."""
    ratios = _window_ratios(REAL / "piezo-hyst-150V-1Hz" / "piezo_150V_1Hz.csv", alpha0=alpha0)
    assert ratios and max(ratios) < 1.0, ratios


def test_the_micromanipulator_record_does_not_diverge():
    """A re-search on the real micromanipulator record took a resonance on its box's edge (zeta 0.003 at 2.6 Hz
    under the 1 Hz sine); its window re-fits ran off, and one window missed by 1.16x the output's spread."""
    ratios = _window_ratios(REAL / "piezo-micromanipulator-1Hz" / "micromanipulator_1Hz.csv")
    assert ratios and max(ratios) < 0.5, ratios


def _scenario_ratios(family: str, seed: int, snr_db: float, rest_samples: int | None, monkeypatch) -> list[tuple]:
    """(window start s, ratio, samples) per 1 s window of a scenario record fed sample by sample."""
    from hil_sim import scenarios
    monkeypatch.setattr(scenarios, "SNR_DB", snr_db)
    scen = scenarios.make(family, seed, rest_samples)
    est = OnlineEstimator(scen.h)
    err = np.full(scen.u.size, np.nan)
    for i, (a, b) in enumerate(zip(scen.u.tolist(), scen.y.tolist())):
        est.update(a, b)
        p = est.last_prediction
        if p is not None and est.phase == "tracking":
            err[i] = b - p
    w = int(round(1.0 / scen.h))
    out = []
    for a in range(0, scen.u.size - w + 1, w):
        e, ok = err[a:a + w], np.isfinite(err[a:a + w])
        if np.count_nonzero(ok) >= w // 2:
            out.append((a * scen.h, float(np.sqrt(np.mean(e[ok] ** 2)) / np.std(scen.y[a:a + w][ok])),
                        int(np.count_nonzero(ok))))
    return out


@pytest.mark.long
def test_a_false_change_on_close_modes_does_not_take_a_wrong_gain(monkeypatch):
    """Close unmodelled modes from the step at the first sample, 40 dB (seed 4): the change test declared a change
    on the modes' misfit (b -3.5 %), and the first pass of the search after it took b -18 %, a1 -21 %, which fit
    its 1.2 s segment (it starts just after an input step: transients' shapes, not levels); the prediction then
    missed by 25x the output's spread for a second. A search's gain must agree with the test's."""
    windows = _scenario_ratios("close_modes", 4, 40.0, 0, monkeypatch)
    assert windows and not _divergent(windows), windows


def test_a_false_change_that_moved_the_resonance_does_not_take_a_far_gain(monkeypatch):
    """A drifting plant from the step at the first sample, 80 dB (seed 1): late in the record the change test read
    the drift as a change of the resonance (a1 -57 %, a2 +79 %, b +0.2 %), and the search after it took b +30 %,
    which fit its short segment with its start unknown; the prediction missed by 8.6x the output's spread. A
    test that moved the resonance bounds the search's gain move in size."""
    windows = _scenario_ratios("drift", 1, 80.0, 0, monkeypatch)
    assert windows and not _divergent(windows), windows


def _divergent(windows: list[tuple]) -> list[tuple]:
    """The windows whose ratio exceeds 1 beyond three standard deviations of an rms over their samples."""
    return [(t, r) for t, r, n in windows if r > 1.0 + 3.0 / math.sqrt(n)]


@pytest.mark.long
@pytest.mark.parametrize("seed, snr_db", [(4, 80.0), (9, 80.0), (9, 40.0)])
def test_the_first_live_predictions_come_from_the_windows_own_fit(seed, snr_db, monkeypatch):
    """Close unmodelled modes from the step at the first sample: the start-up search's estimate (a grid refined
    on the search window) was b -24 %, a1 -27 % off on seed 4 at 80 dB, and it predicted the first 50 live samples,
    until the first window fit: the first second of tracking missed by 4x the output's spread (seed 9: 2.2x; at
    40 dB 1.16x). The tracker now goes live once its first fit of the replayed window has finished."""
    windows = _scenario_ratios("close_modes", seed, snr_db, 0, monkeypatch)
    assert windows and not _divergent(windows), windows


@pytest.mark.parametrize("family, seed, snr_db, rest", [pytest.param("close_modes", 6, 80.0, 0, marks=pytest.mark.long),
                                                        ("drift", 15, 80.0, None)])
def test_a_window_that_misses_the_data_declares_no_change_on_its_own_misfit(family, seed, snr_db, rest,
                                                                            monkeypatch):
    """Close modes at 80 dB (seed 6, window error ~127x the floor): the change test declared b -8 % at 7 s on no
    change (likelihood ratio 710, though the tested second fit the window's estimate better than the window
    did); the restart took the test's gain and the 9 s window missed by 1.7x its spread. A misfitting window's
    second is a change only if the estimate misses it by more than it misses the window. Drift seed 15 (80 dB):
    the drift's gain trend read as alpha until the drift rates may enter (the 3 s hold missed by 1.13x); they
    may enter after 2.5 s of window now, which the misfit rule keeps from a late false change."""
    windows = _scenario_ratios(family, seed, snr_db, rest, monkeypatch)
    assert windows and not _divergent(windows), windows


def test_a_post_change_search_predicts_with_its_resonance_before_its_last_pass(monkeypatch):
    """A payload added in a hold (seed 6 from the step at the first sample, 80 dB; a2 +35 % at 6.4 s, seen at the
    next step, 7 s): the search's first pass took the new resonance at 7.6 s, but the prediction kept the old one
    (outside the live states' trust region) until the last pass's replay at 9.3 s; the old ringing, out of phase,
    missed the 9 s step by 1.04x the window's spread. A pass the prediction cannot represent is replayed at once."""
    windows = _scenario_ratios("payload", 6, 80.0, 0, monkeypatch)
    # (the 7-8 s window holds the first step after the change, which the old model cannot predict: it is the
    # change's, as in the bench's allowance)
    assert windows and not _divergent([w for w in windows if not 7.0 <= w[0] < 8.0]), windows
    assert max(r for t, r, n in windows if t >= 8.0) < 0.5, windows


def test_a_resonance_far_from_the_linearization_point_waits_for_its_replay():
    """The rule itself: a search's resonance further than TRUST (in ln) from the live states' point leaves the
    prediction's coefficients alone; within it they are the new estimate's."""
    from creep_online.model import CreepModel
    from creep_online.simulate import simulate
    h = 1e-4
    model = CreepModel.from_resonance(0.1, 300.0, 0.1, 1.0)
    t = np.arange(20000) * h
    u = np.where(t < 0.05, 0.0, 1.0)
    y = simulate(model, t, u) + np.random.default_rng(0).normal(0, 1e-4, t.size)
    est = OnlineEstimator(h)
    est.update_block(u, y)
    tr = est._tracker
    m = tr.m.copy()
    tr.theta[1] = math.log(tr.a1l) + 2 * TRUST
    tr._take_resonance()
    assert np.array_equal(tr.m, m)
    tr.theta[1] = math.log(tr.a1l) + 0.5 * TRUST
    tr._take_resonance()
    assert not np.array_equal(tr.m, m)


def _uniform_real_records() -> list:
    """Every record in tests/data/real sampled at a uniform step (the polymer-melt records' log-spaced time is not)."""
    paths = []
    for path in sorted(REAL.glob("*/*.csv*")):
        t = np.loadtxt(path, delimiter=",", skiprows=1, usecols=0)
        dt = np.diff(t)
        if dt.size and np.all(dt > 0) and np.ptp(dt) <= 1e-3 * np.mean(dt):
            paths.append(path)
    return paths


def test_the_real_records_are_sampled_as_expected():
    """The records the next test feeds: the six CubeSpec multisines (2.56 s each), the 150 V and micromanipulator
    piezo records (a lost record would silently shrink it)."""
    names = {p.name for p in _uniform_real_records()}
    assert len(names) == 8 and {"piezo_150V_1Hz.csv", "micromanipulator_1Hz.csv"} <= names, names


@pytest.mark.parametrize("path", _uniform_real_records(), ids=lambda p: p.name.split(".")[0])
def test_every_real_record_gets_an_estimate_before_its_end(path):
    """Fed sample by sample, every real record reaches tracking with parameters before its last sample. The
    CubeSpec multisine at 100 mV, realisation 1 (in operation, its output near zero at the first sample: both
    readings of the start compete) ended its 2.56 s still searching: the step's search had grown its window to
    1.37 s, and the in-operation search that it competes with ran its own grid (7400 units, one per sample)."""
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=(0, 1, 2))
    t, u, y = data[:, 0], data[:, 1], data[:, 2]
    est = OnlineEstimator(float(np.mean(np.diff(t))))
    first = None
    for i, (a, b) in enumerate(zip(u.tolist(), y.tolist())):
        est.update(a, b)
        if first is None and est.phase == "tracking":
            first = i
    e = est.estimate
    assert first is not None and first < t.size - 1, (e.phase, e.reason)
    assert e.phase == "tracking" and None not in (e.alpha, e.a1, e.a2, e.b), e.to_dict()
