"""When does the window tracker search its resonance again, and when does it take the result?

The window's local re-fits never leave a wrong resonance basin. A *misfit* (the window's rms error
above ``ratio`` x the noise floor, or a broken fit) that lasts ``after_s`` starts a search of the
resonance on the recent samples with the live estimate competing; its result replaces the estimate
only when clearly better (``verdict``). A misfit run ends only below ``clear_ratio`` (between the two
it goes on, so one re-fit dipping below ``ratio`` does not restart it).

A misfit is *sudden* when it reaches ``sudden_ratio`` within ``sudden_within_s`` of a determined window
at the floor: the plant changed where the change test could not see it, and the re-search takes only
the samples since, alpha held, and a switch is declared as a change.

Pure functions of floats, tested as functions; the tracker orchestrates them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping


def likelihood_ratio(rows: int, c_old: float, c_new: float) -> float:
    """rows x ln(c_old / c_new): how much better the new candidate fits (inf if the old one's cost is not
    finite, -inf if the new one's is not, 0 if either is zero)."""
    if not math.isfinite(c_new):
        return -math.inf
    if not math.isfinite(c_old):
        return math.inf
    return rows * math.log(c_old / c_new) if c_old > 0.0 and c_new > 0.0 else 0.0


def above(rms: float, floor: float, ratio: float) -> bool:
    """Is the window's rms error above ``ratio`` x the noise floor (a known, positive floor)?"""
    return floor > 0.0 and rms > ratio * floor


@dataclass(frozen=True)
class ResearchRule:
    """Thresholds of the re-search trigger and of its switch (see the module's docstring).

    lr: the result replaces the live estimate when its likelihood ratio on the segment exceeds this
        (chi-square with 3 degrees of freedom, p ~ 1e-6) and the resonance moves by more than the change
        rule's ``move`` (or alpha by more than ``alpha_move``): a smaller move the re-fits make anyway.
    gain_ratio: a result whose gain differs from the live one by more than this factor (or in sign) is
        refused: a segment without excitation lets the offset and free responses fit the output alone
        (b ~ 0, a degenerate model).
    gross_misfit: ... but the sign may flip when the live estimate misfits by more than this multiple of
        the floor: then it is no model of the plant, and its gain's sign no reference.
    drifting_alpha_move: with a drift's trends projected out, the segment hardly determines alpha: a result
        moving it by more than this (relative) is refused.
    max_wait_s: a re-search that changed nothing doubles the wait before the next one, up to this.
    """

    ratio: float = 1.5
    clear_ratio: float = 1.25
    after_s: float = 1.0
    sudden_ratio: float = 3.0
    sudden_within_s: float = 1.0
    lr: float = 30.0
    alpha_move: float = 0.02
    gain_ratio: float = 5.0
    gross_misfit: float = 10.0
    drifting_alpha_move: float = 0.05
    max_wait_s: float = 16.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (isinstance(value, (int, float)) and value > 0):     # (inf: never; ratio=inf turns the trigger off)
                raise ValueError(f"ResearchRule.{name} must be a positive number, got {value!r}")
        if not 1.0 <= self.clear_ratio <= self.ratio:
            raise ValueError("ResearchRule needs 1 <= clear_ratio <= ratio")
        if self.gain_ratio <= 1.0:
            raise ValueError("ResearchRule.gain_ratio must exceed 1")

    def misfits(self, rms: float, floor: float) -> bool:
        """A re-fit that starts (or continues) a misfit run."""
        return above(rms, floor, self.ratio)

    def clears(self, rms: float, floor: float) -> bool:
        """A re-fit that ends a misfit run (the window back at the floor)."""
        return not above(rms, floor, self.clear_ratio)

    def sudden(self, rms: float, floor: float, since_floor: int, within: int) -> bool:
        """Did the misfit come suddenly, ``since_floor`` samples after a window at the floor (at most ``within``)?
        (The caller also requires that window to have determined the resonance and alpha.)"""
        return rms >= self.sudden_ratio * floor and since_floor <= within

    def gross(self, rms: float, floor: float, broken: bool) -> bool:
        """Does the live estimate misfit so grossly that its gain's sign is no reference?"""
        return broken or rms > self.gross_misfit * floor

    def moved(self, change: Mapping[str, float], move: Mapping[str, float]) -> list[str]:
        """The parameters a result moves beyond what the re-fits would move anyway (alpha first)."""
        moved = sorted(k for k in ("a1", "a2") if abs(change[k]) > move[k])
        return ["alpha"] + moved if abs(change["alpha"]) > self.alpha_move else moved

    def plausible_gain(self, gain_ratio: float, gross: bool) -> bool:
        """Is the result's gain (``gain_ratio`` = new b / live b) one to take?"""
        return 1.0 / self.gain_ratio < abs(gain_ratio) < self.gain_ratio and (gain_ratio > 0 or gross)

    @staticmethod
    def agrees_with_change(gain_change: float, declared_gain_change: float, gain_move: float,
                           resonance_moved: bool = False) -> bool:
        """May a post-change search's result replace the estimate, as far as its gain goes? Its gain's move from
        the gain before the change (relative, ``gain_change``) must lie between no move and the move the change
        test estimated (``declared_gain_change``), widened on both sides by the change rule's smallest counted
        move (``gain_move``) or half the test's estimate. The search's segment starts after the detection, often
        just after an input step: with its start state unknown it sees the transients' shapes more than the
        levels, and a wrong gain with a wrong resonance can fit it at the floor while predicting the next second
        far off (close modes at 40 dB: the test b -3.5 %, the search b -18 %, a1 -21 %, a prediction 25x the
        output's spread until a longer pass corrected it). Either end may be the right one: a change the test
        declared on a misfit (close modes) is no change at all. A test that also moved the resonance by more than
        a counted move (``resonance_moved``) was linearized far from its solution: gain and resonance trade off in
        its short fit and the sign of its gain move is not to be trusted, only its size (a stiffness change, b
        +44 %: the test said b -26 % with a1 -24 %; a drifting plant's false change, a1 -57 %, a2 +79 %, b +0.2 %,
        whose search took b +30 %): then the gain may move either way by up to twice the test's move, widened by
        the smallest counted move."""
        if resonance_moved:
            return abs(gain_change) <= 2.0 * abs(declared_gain_change) + gain_move
        margin = max(gain_move, 0.5 * abs(declared_gain_change))
        return min(0.0, declared_gain_change) - margin <= gain_change <= max(0.0, declared_gain_change) + margin

    def switch(self, lr: float, moved: list[str], cost: float, gain_ratio: float, gross: bool,
               drifting: bool, alpha_change: float) -> bool:
        """Does the re-search's result replace the live estimate? Clearly better (``lr``), a real move, a finite
        cost, a plausible gain, and alpha not moved by a drift's trends (with them projected out the segment
        hardly determines alpha). (The caller also refuses a result on the search box's edge.)"""
        alpha_held = drifting and abs(alpha_change) > self.drifting_alpha_move
        return (lr > self.lr and bool(moved) and math.isfinite(cost) and self.plausible_gain(gain_ratio, gross)
                and not alpha_held)
