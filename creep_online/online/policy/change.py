"""When is a test statistic a change of the plant? One interface, two detectors.

A tracker tests its recent samples against its estimate and gets a statistic (a likelihood ratio,
chi-square under "no change") and, per parameter, a move with its 1-sigma. A rule turns that into a
verdict. Three conditions make a change, in every detector:

* the statistic is significant (``threshold``);
* it jumps against the tracker's own recent level (``jump`` times the median of the last
  ``history`` statistics): a drifting plant or a slightly wrong model raises the statistic slowly
  and evenly, a change makes it jump;
* a parameter moved by a physically large amount (``move``, relative) that the test determines
  (``sigmas`` of its own 1-sigma): an undetermined parameter never "moves".

The detectors are swappable (``change_rule=`` of the trackers' settings, as river's
``drift_detector=``): ``LikelihoodRatioTest`` is the window tracker's (a fit of the last second
against the window's estimate); ``GeneralizedLikelihoodRatio`` is the recursive tracker's
(Willsky-Jones GLR of a parameter jump on the normalised innovations, decided inside its numba
kernel with the same functions).

The functions at module level are pure and written in the subset numba compiles (floats and bools):
the recursive tracker's kernel compiles them as they are.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Protocol, Sequence

#: The parameters whose moves count as a change (alpha does not jump with a payload or a stiffness).
MOVING = ("a1", "a2", "b")


def significant(move: float, size: float, limit: float, sigmas: float, sd: float) -> bool:
    """A move that counts: larger than ``limit`` (relative) and its ``size`` (on the scale its 1-sigma
    ``sd`` is on) beyond ``sigmas`` of it."""
    return abs(move) > limit and size > sigmas * sd


def exceeds(stat: float, level: float, threshold: float, jump: float) -> bool:
    """Is the statistic beyond the threshold and ``jump`` times the recent level?"""
    return not stat < max(threshold, jump * level)


def glr_alarm(stat: float, level: float, quiet: bool, threshold: float, jump: float, moved: bool) -> bool:
    """The recursive tracker's alarm: outside the quiet time after the last one, a significant statistic
    that jumps against the recent level, with a parameter that moved (``significant``)."""
    return not quiet and stat > threshold and stat > jump * level and moved


def median(values: Sequence[float]) -> float:
    """Median of a short list of floats (numpy's median costs ~50 us from cold Python)."""
    s = sorted(values)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


class ChangeRule(Protocol):
    """What a change detector declares (the trackers call these; ``moved`` names the parameters)."""

    threshold: float
    jump: float
    history: int
    sigmas: float
    move: Mapping[str, float]

    def level(self, recent: Sequence[float]) -> float:
        """The reference level of the recent statistics (no reference yet: see each detector)."""

    def moved(self, moves: Mapping[str, float], sizes: Mapping[str, float],
              sds: Mapping[str, float]) -> dict[str, float]:
        """The moves that count (``significant``), by parameter."""

    def is_change(self, stat: float, level: float, moved: Mapping[str, float]) -> bool:
        """Is this test a change of the plant?"""


@dataclass(frozen=True)
class _Rule:
    threshold: float
    jump: float
    history: int
    sigmas: float
    move: Mapping[str, float]

    def __post_init__(self) -> None:
        for name in ("threshold", "jump", "sigmas"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and not math.isnan(value)):
                raise ValueError(f"{type(self).__name__}.{name} must be a positive number, got {value!r}")
        if not (isinstance(self.history, int) and self.history >= 2):
            raise ValueError(f"{type(self).__name__}.history must be an integer >= 2, got {self.history!r}")
        if set(self.move) != set(MOVING) or not all(v > 0 for v in self.move.values()):
            raise ValueError(f"{type(self).__name__}.move must give a positive relative move for each of {MOVING}")

    def moved(self, moves: Mapping[str, float], sizes: Mapping[str, float],
              sds: Mapping[str, float]) -> dict[str, float]:
        return {k: v for k, v in moves.items() if significant(v, sizes[k], self.move[k], self.sigmas, sds[k])}

    def is_change(self, stat: float, level: float, moved: Mapping[str, float]) -> bool:
        return bool(moved) and exceeds(stat, level, self.threshold, self.jump)


def _window_moves() -> dict[str, float]:
    return {"a1": 0.08, "a2": 0.05, "b": 0.03}


@dataclass(frozen=True)
class LikelihoodRatioTest(_Rule):
    """The window tracker's test: a fit of the last second's statistics (the difference of two snapshots)
    against the window's estimate; ``stat`` = (cost before - cost after) / the noise variance.

    threshold: chi-square with 4 degrees of freedom, p ~ 1e-9 (higher thresholds left damping changes of
        -30 % on a lightly damped mode undeclared while the window followed them slowly by forgetting).
    disagree: a statistic beyond it (p ~ 5e-4) with a move that counts says the last second disagrees
        with the window's estimate, even below ``threshold``: the quality is then not "good".
    move: the smallest relative moves (a1, a2, b) that count as a change; below them the window follows.
    misfit_floor: a window whose mean square error exceeds this ratio squared times the noise's misses the data
        (the quality's ``floor_ratio``); there the statistic is no chi-square (``misfit_explains``).
    Without ``history // 2`` recent statistics the level is 0 (the threshold alone decides).
    """

    threshold: float = 50.0
    jump: float = 3.0
    history: int = 8
    sigmas: float = 5.0
    move: Mapping[str, float] = field(default_factory=_window_moves)
    disagree: float = 20.0
    misfit_floor: float = 2.0

    def level(self, recent: Sequence[float]) -> float:
        return median(recent) if len(recent) >= self.history // 2 else 0.0

    def misfit_explains(self, second_ms: float, window_ms: float, noise_var: float) -> bool:
        """Does the window's own misfit explain the tested second? Where the model class misses the data (close
        unmodelled modes: a window error a hundred times the noise floor), the residuals are the missing dynamics,
        which a short second's fit absorbs partly by moving the gain or the resonance (b -8 % against a 127x window,
        at a likelihood ratio of 700 on no change). The second is a change only if the window's estimate misses it
        by more than it misses the window itself (mean square errors ``second_ms``, ``window_ms``); a change
        smaller than the misfit cannot be told from the misfit's own variation with the input."""
        return window_ms > self.misfit_floor ** 2 * noise_var and second_ms <= window_ms

    def quiet(self, stat: float, level: float) -> bool:
        """Nothing to look at (the common case: no dictionaries of moves are built)."""
        return stat <= self.disagree and not exceeds(stat, level, self.threshold, self.jump)

    def disagrees(self, stat: float, moved: Mapping[str, float]) -> bool:
        """Does the tested second disagree with the estimate (not "good"), change or not?"""
        return stat > self.disagree and bool(moved)


@dataclass(frozen=True)
class GeneralizedLikelihoodRatio(_Rule):
    """The recursive tracker's test: over blocks of ``block_s`` the score z = sum psi e / s^2 and the
    information I = sum psi psi' / s^2; every ``check_s`` the statistic z' I^-1 z (chi-square with
    n <= 9 degrees of freedom; threshold: p < 1e-15) and the jump I^-1 z, whose entries are the moves.
    After an alarm none for ``quiet_s`` and the history restarts (the re-convergence is itself a burst
    of innovations). Without ``history // 2`` statistics the level is infinite: no alarm yet.

    Decided inside the numba kernel (``glr_alarm``, ``significant``) from ``kernel_parameters``.
    ``history`` is compiled into the kernel's state layout: only its default is accepted.
    """

    threshold: float = 100.0
    jump: float = 5.0
    history: int = 8
    sigmas: float = 5.0
    move: Mapping[str, float] = field(default_factory=_window_moves)
    block_s: float = 0.5
    check_s: float = 0.05
    quiet_s: float = 1.5

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.history != 8:
            raise ValueError("GeneralizedLikelihoodRatio.history is fixed at 8 (the kernel's state holds 8)")
        for name in ("block_s", "check_s", "quiet_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"GeneralizedLikelihoodRatio.{name} must be positive")

    def level(self, recent: Sequence[float]) -> float:
        return median(recent) if len(recent) >= self.history // 2 else math.inf

    def is_change(self, stat: float, level: float, moved: Mapping[str, float], quiet: bool = False) -> bool:
        return glr_alarm(stat, level, quiet, self.threshold, self.jump, bool(moved))

    def kernel_parameters(self) -> tuple[float, float, float, float]:
        """The kernel's copy of the move rule: relative moves of a1, a2, b and the sigmas."""
        return float(self.move["a1"]), float(self.move["a2"]), float(self.move["b"]), float(self.sigmas)
