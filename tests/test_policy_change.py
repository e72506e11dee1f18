"""The change and re-search rules as functions (``online.policy``): tables of cases, then generated records.

The rules are pure: a statistic, the recent level and the moves in, a verdict out. The generated records
are block-wise least-squares tests of a three-parameter linear model whose parameters jump (or not) at a
known block: each detector, fed the statistics and moves the same way a tracker feeds it, must raise no
false alarm on records without a change and find each change within one block.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from creep_online.online.policy import change as C
from creep_online.online.policy.research import ResearchRule, above, likelihood_ratio
from creep_online.online.trackers.settings import DEFAULT, TrackerSettings

LRT = C.LikelihoodRatioTest()
GLR = C.GeneralizedLikelihoodRatio()


# ---------------------------------------------------------------------- tables
@pytest.mark.parametrize("move, size, limit, sigmas, sd, expected", [
    (0.10, 0.10, 0.08, 5.0, 0.01, True),        # large and determined
    (-0.10, 0.10, 0.08, 5.0, 0.01, True),       # either sign
    (0.07, 0.07, 0.08, 5.0, 0.001, False),      # below the physical limit
    (0.10, 0.10, 0.08, 5.0, 0.03, False),       # not determined (3.3 sigma)
    (0.08, 0.08, 0.08, 5.0, 0.0, False),        # at the limit: not beyond it
    (2.32, 1.20, 0.05, 5.0, 0.40, False),       # exp(d) - 1 large, d itself 3 sigma: the size decides
    (math.nan, 1.0, 0.05, 5.0, 0.01, False),    # no move
])
def test_a_move_counts_when_large_and_determined(move, size, limit, sigmas, sd, expected):
    assert C.significant(move, size, limit, sigmas, sd) is expected


@pytest.mark.parametrize("stat, level, threshold, jump, expected", [
    (60.0, 0.0, 50.0, 3.0, True),
    (50.0, 0.0, 50.0, 3.0, True),               # at the threshold
    (49.9, 0.0, 50.0, 3.0, False),
    (60.0, 25.0, 50.0, 3.0, False),             # a high recent level (a drifting plant) needs a jump to 75
    (80.0, 25.0, 50.0, 3.0, True),
    (math.nan, 0.0, 50.0, 3.0, True),           # a broken statistic is looked at
])
def test_a_statistic_exceeds_the_threshold_and_the_recent_level(stat, level, threshold, jump, expected):
    assert C.exceeds(stat, level, threshold, jump) is expected


@pytest.mark.parametrize("stat, level, quiet, moved, expected", [
    (150.0, 10.0, False, True, True),
    (150.0, 10.0, True, True, False),           # inside the quiet time after an alarm
    (150.0, 40.0, False, True, False),          # below 5x the level
    (150.0, math.inf, False, True, False),      # no level yet: no alarm
    (150.0, 10.0, False, False, False),         # nothing moved
    (90.0, 1.0, False, True, False),            # below the threshold
])
def test_the_glr_alarm(stat, level, quiet, moved, expected):
    assert C.glr_alarm(stat, level, quiet, GLR.threshold, GLR.jump, moved) is expected
    assert GLR.is_change(stat, level, {"a1": 0.2} if moved else {}, quiet=quiet) is expected


@pytest.mark.parametrize("recent, lrt, glr", [
    ([], 0.0, math.inf),
    ([1.0, 2.0, 3.0], 0.0, math.inf),
    ([4.0, 1.0, 3.0, 2.0], 2.5, 2.5),
    ([5.0, 1.0, 3.0, 2.0, 4.0], 3.0, 3.0),
])
def test_the_recent_level_is_the_median_once_half_the_history_is_there(recent, lrt, glr):
    assert LRT.level(recent) == lrt and GLR.level(recent) == glr


@pytest.mark.parametrize("stat, level, moved, quiet, disagrees, change", [
    (10.0, 0.0, {}, True, False, False),
    (25.0, 0.0, {}, False, False, False),                  # above "disagree", nothing moved
    (25.0, 0.0, {"a1": -0.3}, False, True, False),         # disagrees, below the threshold: "changing", no restart
    (60.0, 0.0, {"b": 0.1}, False, True, True),
    (60.0, 30.0, {"b": 0.1}, False, True, False),          # no jump against the level
    (60.0, 30.0, {}, False, False, False),
])
def test_the_window_test_verdicts(stat, level, moved, quiet, disagrees, change):
    assert LRT.quiet(stat, level) is quiet
    assert LRT.disagrees(stat, moved) is disagrees
    assert LRT.is_change(stat, level, moved) is change


def test_the_moves_that_count_are_named():
    moves = {"a1": 0.10, "a2": 0.04, "b": -0.05}
    sizes = {k: abs(v) for k, v in moves.items()}
    sds = {"a1": 0.001, "a2": 0.001, "b": 0.02}
    assert LRT.moved(moves, sizes, sds) == {"a1": 0.10}        # a2 below 5 %, b not determined


@pytest.mark.parametrize("kwargs", [{"threshold": 0.0}, {"threshold": math.nan}, {"jump": -1.0}, {"history": 1},
                                    {"move": {"a1": 0.1}}, {"move": {"a1": 0.1, "a2": 0.1, "b": 0.0}}])
def test_a_rule_refuses_bad_thresholds(kwargs):
    with pytest.raises(ValueError):
        C.LikelihoodRatioTest(**kwargs)
    with pytest.raises(ValueError):
        C.GeneralizedLikelihoodRatio(**kwargs)


def test_the_glr_history_is_the_kernels():
    with pytest.raises(ValueError, match="history"):
        C.GeneralizedLikelihoodRatio(history=10)


def test_the_kernel_compiles_the_same_rule():
    """The recursive tracker's kernel runs these functions compiled: same verdicts on the tables."""
    from creep_online.online._kernels import recursive as K
    rng = np.random.default_rng(3)
    for _ in range(500):
        move, size, sd = rng.normal(0, 0.2), abs(rng.normal(0, 0.2)), abs(rng.normal(0, 0.03))
        assert K._significant(move, size, 0.05, 5.0, sd) == C.significant(move, size, 0.05, 5.0, sd)
        stat, level = rng.exponential(80.0), rng.exponential(20.0)
        quiet, moved = bool(rng.integers(2)), bool(rng.integers(2))
        assert K._alarm(stat, level, quiet, 100.0, 5.0, moved) == C.glr_alarm(stat, level, quiet, 100.0, 5.0, moved)


def test_the_recursive_tracker_takes_its_rule_from_the_settings():
    from creep_online.online._kernels import recursive as K
    from creep_online.online.soe import SoeBasis
    from creep_online.online.trackers.recursive import RecursiveTracker
    rule = C.GeneralizedLikelihoodRatio(threshold=200.0, jump=4.0, sigmas=6.0, move={"a1": 0.1, "a2": 0.2, "b": 0.3})
    basis = SoeBasis.build(1e-3, horizon_s=10.0)
    tr = RecursiveTracker(basis, np.array([0.1, math.log(2e-3), math.log(1e-6), 1.0, 0.0]), window_s=1.0, free=False,
                          gate=0.0, burst=2, stuck=10, alpha_bounds=(0.005, 0.9), refit_every=50, detect=True,
                          scale=1.0, settings=replace(DEFAULT, recursive_change=rule))
    assert [tr.r[i] for i in (K.R_LIMIT, K.R_JUMPK, K.R_MOVE_A1, K.R_MOVE_A2, K.R_MOVE_B, K.R_SIGMAS)] == \
        [200.0, 4.0, 0.1, 0.2, 0.3, 6.0]


# ---------------------------------------------------------------------- research rule
@pytest.mark.parametrize("rows, c_old, c_new, expected", [
    (100, 2.0, 1.0, 100 * math.log(2.0)), (100, math.inf, 1.0, math.inf), (100, 1.0, math.nan, -math.inf),
    (100, 0.0, 1.0, 0.0), (100, 1.0, 1.0, 0.0)])
def test_the_likelihood_ratio_of_two_costs(rows, c_old, c_new, expected):
    assert likelihood_ratio(rows, c_old, c_new) == pytest.approx(expected)


@pytest.mark.parametrize("lr, moved, cost, ratio, gross, drifting, dalpha, expected", [
    (40.0, ["a1"], 1.0, 1.1, False, False, 0.0, True),
    (20.0, ["a1"], 1.0, 1.1, False, False, 0.0, False),        # not clearly better
    (40.0, [], 1.0, 1.1, False, False, 0.0, False),            # a move the re-fits make anyway
    (40.0, ["a1"], math.inf, 1.1, False, False, 0.0, False),
    (40.0, ["a1"], 1.0, 0.01, False, False, 0.0, False),       # b ~ 0: a degenerate model
    (40.0, ["a1"], 1.0, -0.8, False, False, 0.0, False),       # the sign flipped ...
    (40.0, ["a1"], 1.0, -0.8, True, False, 0.0, True),         # ... allowed when the live estimate misfits grossly
    (40.0, ["alpha"], 1.0, 1.0, False, True, 0.08, False),     # alpha moved by a drift's trends
    (40.0, ["alpha"], 1.0, 1.0, False, False, 0.08, True),
])
def test_a_research_result_is_taken_only_when_clearly_better_and_plausible(lr, moved, cost, ratio, gross, drifting,
                                                                          dalpha, expected):
    assert ResearchRule().switch(lr, moved, cost, ratio, gross, drifting, dalpha) is expected


def test_the_misfit_run_has_hysteresis():
    rule = ResearchRule()
    assert rule.misfits(1.6, 1.0) and not rule.misfits(1.4, 1.0) and not rule.clears(1.4, 1.0)
    assert rule.clears(1.2, 1.0) and not rule.misfits(5.0, 0.0) and not above(5.0, 0.0, 1.5)
    assert rule.sudden(3.0, 1.0, 100, 1000) and not rule.sudden(2.9, 1.0, 100, 1000)
    assert not rule.sudden(3.0, 1.0, 1001, 1000)
    assert rule.moved({"alpha": 0.03, "a1": 0.1, "a2": 0.01, "b": 0.0}, LRT.move) == ["alpha", "a1"]


def test_settings_validate_and_keep_their_defaults():
    s = TrackerSettings()
    assert s.change_rule.threshold == 50.0 and s.recursive_change.threshold == 100.0 and s.trust == 0.3
    for bad in ({"trust": 0.0}, {"refit_steps": 2.5}, {"drift_off": 30.0}, {"window_free_start": (0.5,)},
                {"fn_max_fs": 0.6}, {"determined": {"alpha": 0.01}}, {"free_rates": ()}):
        with pytest.raises(ValueError):
            TrackerSettings(**bad)
    with pytest.raises(ValueError):
        ResearchRule(clear_ratio=2.0)
    assert ResearchRule(ratio=math.inf).misfits(1e9, 1.0) is False      # the trigger turned off


# ---------------------------------------------------------------------- generated records
BLOCKS, ROWS, NOISE, CHANGE_AT = 24, 200, 0.05, 14


def _record(rng: np.random.Generator, jump: dict | None):
    """Per block: the least-squares test of the block against the estimate before (the live one), as a
    tracker makes it: statistic, relative moves, their sizes and 1-sigma."""
    names = ("a1", "a2", "b")
    theta0 = rng.uniform(0.5, 2.0, 3) * rng.choice([-1.0, 1.0], 3)
    theta1 = theta0.copy()
    if jump:
        for k, v in jump.items():
            theta1[names.index(k)] *= 1.0 + v
    out = []
    for blk in range(BLOCKS):
        theta = theta1 if jump and blk >= CHANGE_AT else theta0
        X = rng.standard_normal((ROWS, 3))
        y = X @ theta + NOISE * rng.standard_normal(ROWS)
        fit, *_ = np.linalg.lstsq(X, y, rcond=None)
        r1 = y - X @ fit
        r0 = y - X @ theta0
        sigma2 = r1 @ r1 / (ROWS - 3)
        stat = (r0 @ r0 - r1 @ r1) / sigma2
        sd = np.sqrt(np.diag(np.linalg.inv(X.T @ X)) * sigma2) / np.abs(theta0)
        rel = (fit - theta0) / theta0
        out.append((stat, dict(zip(names, rel)), dict(zip(names, np.abs(rel))), dict(zip(names, sd))))
    return out


def _detections(rule, record) -> list[int]:
    """Blocks at which the rule declares a change (the history of quiet statistics as the trackers keep it)."""
    recent: list[float] = []
    found = []
    for blk, (stat, moves, sizes, sds) in enumerate(record):
        level = rule.level(recent)
        moved = rule.moved(moves, sizes, sds)
        if rule.is_change(stat, level, moved):
            found.append(blk)
            recent = []
        else:
            recent = (recent + [float(stat)])[-rule.history:]
    return found


@pytest.mark.parametrize("rule", [LRT, GLR], ids=["likelihood-ratio", "glr"])
def test_generated_records_no_false_alarm_and_a_change_found_within_a_block(rule):
    """200 records without a change and 200 with a jump of 12-40 % in a1, a2 or b (seeds 0-399)."""
    false_alarms, found, delays = 0, 0, []
    for seed in range(200):
        false_alarms += bool(_detections(rule, _record(np.random.default_rng(seed), None)))
    for seed in range(200, 400):
        rng = np.random.default_rng(seed)
        name = ("a1", "a2", "b")[seed % 3]
        hits = _detections(rule, _record(rng, {name: rng.uniform(0.12, 0.4) * rng.choice([-1.0, 1.0])}))
        after = [b for b in hits if b >= CHANGE_AT]
        if after and after[0] - CHANGE_AT <= 1 and not [b for b in hits if b < CHANGE_AT]:
            found += 1
            delays.append(after[0] - CHANGE_AT)
    print(f"{type(rule).__name__}: false alarms {false_alarms}/200, found within a block {found}/200, "
          f"delay {np.mean(delays):.2f} blocks")
    assert false_alarms == 0
    assert found == 200


def test_generated_records_below_the_physical_move_are_followed_not_declared():
    """A 2 % jump of b (below its 3 % move) is significant but not a change: 100 records, none declared."""
    declared = sum(bool(_detections(LRT, _record(np.random.default_rng(1000 + s), {"b": 0.02}))) for s in range(100))
    assert declared == 0


@pytest.mark.parametrize("second_ms, window_ms, noise_var, explains", [
    (1.88e-4, 2.29e-4, 1.5e-8, True),     # close modes: the second fits better than the window (127x the floor)
    (1.5e-3, 7.0e-4, 1.5e-8, False),      # the window's estimate misses the second twice as much: it may be a change
    (1.2e-8, 1.0e-8, 1.0e-8, False),      # a window at the floor: the chi-square statistic decides
    (3.0e-8, 3.9e-8, 1.0e-8, False),      # within floor_ratio 2 of the floor (mean square 3.9x): not a misfit
    (3.0e-8, 4.1e-8, 1.0e-8, True),
])
def test_a_window_that_misses_the_data_explains_a_second_it_misses_less(second_ms, window_ms, noise_var, explains):
    assert C.LikelihoodRatioTest().misfit_explains(second_ms, window_ms, noise_var) is explains
