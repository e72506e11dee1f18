"""The quality rule (``online/policy/quality.py``) as a function: one view in, one verdict out, case by case."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from creep_online.online.estimator import QUALITIES
from creep_online.online.policy import quality as Q
from creep_online.online.settings import DeterminedLimits, QualitySettings

DT = 1e-3
NOISE = 0.01


def _tracker(ratio: float = 1.0, **changes) -> Q.TrackerView:
    """A live tracker at ``ratio`` x the noise floor, every parameter determined (0.1 % 1-sigma)."""
    values = dict(alpha=0.2, a1=1e-3, a2=1e-6, b=1.5)
    base = Q.TrackerView(
        replaying=False, **values, std={k: 1e-3 * abs(v) for k, v in values.items()}, fit_sample=5000,
        fit_cost=100 * (ratio * NOISE) ** 2, fit_neff=100.0, noise=NOISE, live_error_power=NOISE ** 2,
        output_stuck=False, input_held_samples=10.0, last_event=None, disagreement=None, last_research=None)
    return dataclasses.replace(base, **changes)


_LIVE = object()


def _view(tracker=_LIVE, **changes) -> Q.QualityView:
    base = Q.QualityView(
        settings=QualitySettings(), dt=DT, samples=20000, n_shift=0, window_s=10.0, alpha_bounds=(0.005, 0.95),
        u_span=1.0, frozen=False, frozen_t=0.0, start=Q.StartView(competing=False, start="rest", u_first=0.0,
                                                                  moved=True),
        tracker=_tracker() if tracker is _LIVE else tracker, fault=None)
    return dataclasses.replace(base, **changes)


NOW = 20000 * DT                        # the views' stream time (s)
FAULT = Q.FaultView(t=NOW - 1.0, error="ZeroDivisionError", where="update", message="boom",
                    recovery="tracker restarted", fit_after=4000)

CASES = [
    # (name, view, quality, reason starts with / contains, determined)
    ("at the floor, all determined", _view(), "good", "", ["alpha", "b", "a1", "a2"]),
    ("replaying", _view(_tracker(replaying=True)), "provisional", "replaying the start-up buffer", []),
    ("output stuck", _view(_tracker(output_stuck=True)), "degraded", "output frozen or clipped", []),
    ("a change just found", _view(_tracker(last_event={"t": NOW - 1.0, "detected_t": NOW - 0.5, "moved": ["b"],
                                                       "settled": True})),
     "changing", "change detected at t=19 s (b moved)", []),
    ("a change of the estimate", _view(_tracker(last_event={"t": NOW - 1.0, "detected_t": NOW - 0.5, "moved": ["a1"],
                                                            "settled": True, "estimate_settled": False})),
     "provisional", "estimate corrected", []),
    ("an old unsettled change, window at the floor", _view(_tracker(last_event={
        "t": NOW - 9.0, "detected_t": NOW - 8.0, "moved": ["b"], "settled": False})),
     "changing", "change detected", []),
    ("... of the resonance alone (never pinned by a scan)", _view(_tracker(last_event={
        "t": NOW - 9.0, "detected_t": NOW - 8.0, "moved": ["a1"], "settled": False})),
     "changing", "change detected", ["alpha", "b"]),
    ("... an estimate's correction", _view(_tracker(last_event={
        "t": NOW - 9.0, "detected_t": NOW - 8.0, "moved": ["a1", "a2"], "settled": False, "estimate_settled": False})),
     "provisional", "estimate corrected", ["alpha", "b"]),
    ("... just found", _view(_tracker(last_event={
        "t": NOW - 1.0, "detected_t": NOW - 0.5, "moved": ["a1"], "settled": False})),
     "changing", "change detected", []),
    ("... the last second disagreeing on b", _view(_tracker(
        last_event={"t": NOW - 9.0, "detected_t": NOW - 8.0, "moved": ["a1"], "settled": False},
        disagreement={"t": NOW - 1.0, "moves": {"b": 0.1}, "lr": 30.0})),
     "changing", "change detected", []),
    ("an old unsettled change, window missing the data", _view(_tracker(ratio=50.0, last_event={
        "t": NOW - 9.0, "detected_t": NOW - 8.0, "moved": ["a1"], "settled": False})),
     "degraded", "window error 50.0x", []),
    ("an old settled change", _view(_tracker(last_event={"t": NOW - 9.0, "detected_t": NOW - 8.0, "moved": ["a1"],
                                                         "settled": True})),
     "good", "", ["alpha", "b", "a1", "a2"]),
    ("the change test disagrees", _view(_tracker(disagreement={"t": NOW - 1.0, "moves": {"b": 0.1}, "lr": 30.0})),
     "changing", "the last second disagrees", []),
    ("the change test disagrees on the resonance alone", _view(_tracker(disagreement={
        "t": NOW - 1.0, "moves": {"a1": 0.5, "a2": 0.3}, "lr": 30.0})), "changing", "the last second disagrees",
     ["alpha", "b"]),
    ("... the creep part not determined", _view(_tracker(disagreement={"t": NOW - 1.0, "moves": {"a1": 0.5}, "lr": 30.0},
                                                         std={"alpha": 2e-4, "b": 0.5, "a1": 1e-4, "a2": 1e-9})),
     "changing", "the last second disagrees", ["alpha"]),
    ("... the window missing the data", _view(_tracker(ratio=2.5, disagreement={
        "t": NOW - 1.0, "moves": {"a1": 0.5}, "lr": 30.0})), "changing", "the last second disagrees", []),
    ("... a change just found", _view(_tracker(disagreement={"t": NOW - 1.0, "moves": {"a1": 0.5}, "lr": 30.0},
                                               last_event={"t": NOW - 1.0, "detected_t": NOW - 0.5, "moved": ["b"],
                                                           "settled": True})),
     "changing", "change detected", []),
    ("no window fit yet", _view(_tracker(fit_sample=0)), "provisional", "first window fit pending", []),
    ("a re-search switched", _view(_tracker(fit_sample=0, last_research={"t": 3.0, "switched": True,
                                                                         "moved": ["a1", "a2"]})),
     "provisional", "resonance re-searched at t=3 s (a1, a2 moved)", []),
    ("input held for 3 windows", _view(_tracker(input_held_samples=31.0 / DT)), "provisional", "input constant", []),
    ("window misses the data", _view(_tracker(ratio=2.5)), "degraded", "window error 2.5x", []),
    ("... naming the window a drifting plant needs", _view(_tracker(ratio=2.5)), "degraded",
     "a shorter window_s follows faster", []),
    ("window misses a little", _view(_tracker(ratio=1.5)), "provisional", "window error 1.50x",
     ["alpha", "b", "a1", "a2"]),
    ("... naming the window a drifting plant needs", _view(_tracker(ratio=1.5)), "provisional",
     "parameters moving within the window: a shorter window_s follows faster", ["alpha", "b", "a1", "a2"]),
    ("alpha at its bound", _view(_tracker(alpha=0.95)), "provisional", "alpha at its bound", ["b", "a1", "a2"]),
    ("a1 undetermined", _view(_tracker(std={"alpha": 2e-4, "b": 1e-3, "a1": 1e-4, "a2": 1e-9})),
     "provisional", "a1 not yet determined by the data (10 % 1-sigma)", ["alpha", "b", "a2"]),
    ("b undetermined first", _view(_tracker(std={"alpha": 2e-4, "b": 0.5, "a1": 1e-4, "a2": 1e-9})),
     "provisional", "b not yet determined", ["alpha", "a2"]),
    ("frozen, still predicting", _view(frozen=True, frozen_t=12.0), "provisional", "frozen since t=12 s", []),
    ("frozen, missing the data", _view(_tracker(live_error_power=(3 * NOISE) ** 2), frozen=True),
     "degraded", "frozen since", []),
    ("a fault, no fit since", _view(_tracker(fit_sample=4000), fault=FAULT), "degraded",
     "internal fault at t=19 s (ZeroDivisionError in update: boom); tracker restarted; re-converging", []),
    ("a fault, re-converged", _view(fault=FAULT), "good", "", ["alpha", "b", "a1", "a2"]),
    ("a fault, a fit since but a check fails", _view(_tracker(ratio=2.5), fault=FAULT), "degraded",
     "internal fault", []),
    ("a fault a window ago, a check fails", _view(_tracker(ratio=2.5), fault=dataclasses.replace(FAULT, t=NOW - 11.0)),
     "degraded", "window error 2.5x", []),
]


@pytest.mark.parametrize("name, view, quality, reason, determined", CASES, ids=[c[0] for c in CASES])
def test_the_rule_case_by_case(name, view, quality, reason, determined):
    v = Q.assess(view)
    assert v.quality == quality, v
    assert (v.reason == "" if reason == "" else reason in v.reason), v.reason
    assert v.determined == determined
    assert v.fault_cleared == (view.fault is not None and not v.reason.startswith("internal fault"))


@pytest.mark.parametrize("start, reason", [
    (Q.StartView(False, "rest", 0.0, False), "waiting for the input to move"),
    (Q.StartView(False, "operation", 0.3, False), "waiting for the input to move (the stream is in operation"),
    (Q.StartView(False, None, 0.3, False), "reading the start: the input is at 0.3 from the first sample"),
    (Q.StartView(True, None, 0.3, True), "searching the resonance and creep: the input's first level as a step"),
    (Q.StartView(False, "rest", 0.0, True), "searching the resonance and creep"),
])
def test_before_a_tracker_the_reason_says_what_the_start_up_waits_for(start, reason):
    v = Q.assess(_view(tracker=None, start=start))
    assert v == ("none", v.reason, [], False) and v.reason.startswith(reason), v.reason


def test_the_thresholds_are_the_settings():
    """The same view under other settings: the rule reads its thresholds from ``QualitySettings`` only."""
    view = _view(_tracker(ratio=1.5))
    assert Q.assess(view).quality == "provisional"
    assert Q.assess(dataclasses.replace(view, settings=QualitySettings(good_ratio=1.6))).quality == "good"
    assert Q.assess(dataclasses.replace(view, settings=QualitySettings(floor_ratio=1.4, good_ratio=1.2))).quality \
        == "degraded"
    loose = QualitySettings(determined=DeterminedLimits(a1=0.2))
    a1_rough = _view(_tracker(std={"alpha": 2e-4, "b": 1e-3, "a1": 1e-4, "a2": 1e-9}))
    assert Q.assess(dataclasses.replace(a1_rough, settings=loose)).quality == "good"
    assert Q.DETERMINED == dict(QualitySettings().determined.items())


def test_random_views_keep_the_rule_s_promises():
    """On 2000 random views: a known quality; "good" only with all four determined and the window within the good
    ratio; anything determined only when good or provisional; a verdict never depends on a second call."""
    rng = np.random.default_rng(45)
    kept = 0
    for _ in range(2000):
        tv = _tracker(ratio=float(rng.uniform(0.5, 3.0)), alpha=float(rng.uniform(0.004, 0.96)),
                      std={k: float(10 ** rng.uniform(-6, -1)) for k in ("alpha", "b", "a1", "a2")},
                      fit_sample=int(rng.integers(0, 2)) * 5000, output_stuck=bool(rng.random() < 0.1),
                      input_held_samples=float(rng.uniform(0, 40) / DT), replaying=bool(rng.random() < 0.1))
        view = _view(tv, frozen=bool(rng.random() < 0.1))
        v = Q.assess(view)
        assert v.quality in QUALITIES and v == Q.assess(view)
        if v.quality == "good":
            assert v.determined == ["alpha", "b", "a1", "a2"] and Q.floor_ratio(view) <= 1.2
        if v.determined:
            assert v.quality in ("good", "provisional")
        kept += 1
    assert kept == 2000


def test_residual_and_floor():
    tv = _tracker(ratio=2.0)
    assert Q.residual(tv) == pytest.approx(2 * NOISE)
    assert Q.residual(_tracker(fit_cost=math.inf)) is None and Q.residual(_tracker(fit_neff=0.0)) is None
    assert Q.noise_floor(_tracker(noise=0.0), 2.0) == pytest.approx(1e-9 * 1.5 * 2.0)


@pytest.mark.parametrize("determined, rel, remembered, source", [
    ({"alpha", "b", "a1", "a2"}, {}, False, "determined"),
    ({"alpha", "b", "a1", "a2"}, {}, True, "determined"),     # a determined resonance replaces the one held
    ({"alpha", "b", "a1"}, {"a1": 0.1, "a2": 0.9}, True, "held"),
    ({"alpha", "b"}, {"a1": 0.4, "a2": 0.3}, False, "rough"),
    ({"alpha", "b"}, {"a1": 0.6, "a2": 0.1}, False, ""),      # a1 not even rough
    ({"alpha", "b"}, {"a1": 0.5, "a2": 0.1}, False, ""),      # at the limit: not below it
])
def test_where_a_compensator_s_resonance_comes_from(determined, rel, remembered, source):
    assert Q.model_source(determined, rel, remembered) == source


def test_the_tracker_s_determined_limits_are_the_quality_rule_s():
    """The window tracker judges a determined resonance with the same limits (its re-search trigger)."""
    from creep_online.online.trackers.settings import TrackerSettings
    assert dict(TrackerSettings().determined) == Q.DETERMINED
