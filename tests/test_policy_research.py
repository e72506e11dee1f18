"""The re-search rules as functions (``online.policy.research``)."""
from __future__ import annotations

import pytest

from creep_online.online.policy.research import ResearchRule

MOVE = 0.03     # the change rule's smallest counted gain move (``LikelihoodRatioTest.move["b"]``)


@pytest.mark.parametrize("found, declared, takes", [
    (-0.185, -0.035, False),     # close modes: the test saw b -3.5 %, the short segment's search b -18 %
    (0.18, -0.012, False),       # a drifting record's false change: the search's gain the other way
    (0.001, -0.0745, True),      # a false change the test put at b -7.5 %: the search finds the gain unmoved
    (-0.07, -0.0745, True),      # ... or where the test put it
    (-0.02, 0.0, True),          # within the smallest counted move
    (-0.30, -0.25, True),        # a real gain change: the search refines the test's estimate
    (-0.40, -0.25, False),       # ... not beyond half of it
    (0.10, 0.20, True),
    (-0.15, 0.20, False),
])
def test_a_post_change_search_keeps_its_gain_between_before_and_the_test_s_estimate(found, declared, takes):
    assert ResearchRule.agrees_with_change(found, declared, MOVE) is takes


def test_a_declared_change_that_moved_the_resonance_holds_the_gain_in_size_only():
    """A change test that moved the resonance beyond a counted move was linearized far from its solution: its gain
    (a stiffness change of b +44 % read as b -26 % with a1 -24 %) bounds the search's only in size."""
    rule = ResearchRule()
    assert not rule.agrees_with_change(0.44, -0.26, 0.03)
    assert rule.agrees_with_change(0.44, -0.26, 0.03, resonance_moved=True)
    assert not rule.agrees_with_change(-0.18, -0.035, 0.03, resonance_moved=False)
    # only its size then: a false change that moved a1 -57 %, a2 +79 % and the gain +0.2 % holds the gain within
    # 3.4 % (a search's b +30 % had predicted 50x the output's spread)
    assert not rule.agrees_with_change(0.30, 0.002, 0.03, resonance_moved=True)
    assert rule.agrees_with_change(-0.03, 0.002, 0.03, resonance_moved=True)
