"""The input gate: which input samples are glitches, held back and replaced, and which are moves.

An input further than ``input_gate`` input ranges (the range seen so far; none before the input has moved) from
the last accepted one is a glitch candidate and is kept back with its output. If the input returns before more
than ``burst`` samples were kept, they were a glitch: fed with the last accepted input (counted in
``input_outliers``). If the input stays, it was a move: they are fed as they came, so the model never sees a real
step late (held and fed at once, a real step early in a stream reached the model late by the hold and the window
then misfitted for seconds). ``input_gate=0`` disables the gate (inputs the caller computed itself, e.g. a
compensator's commands, legitimately jump far beyond what came before).

``verdict`` is the rule; ``online/inputs.py`` holds the samples and acts on it.
"""
from __future__ import annotations

from typing import NamedTuple

#: The sample is taken as it came (nothing held).
PASS = "pass"
#: The sample is a glitch candidate: kept back with its output.
HOLD = "hold"
#: The held samples were a glitch (the input returned): fed with the last accepted input, then this sample.
GLITCH = "glitch"
#: The held samples, this one the last, were a move (the input stayed): fed as they came.
MOVE = "move"


class InputRange(NamedTuple):
    """The inputs accepted so far: their range and the last one."""

    lo: float
    hi: float
    last: float


def glitch_candidate(u: float, seen: InputRange, gate: float) -> bool:
    """Is u further than ``gate`` input ranges (seen so far; none before the input has moved) from the last
    accepted input?"""
    rng = seen.hi - seen.lo
    return rng > 0 and gate > 0 and abs(u - seen.last) > gate * rng


def verdict(candidate: bool, held: int, burst: int) -> str:
    """What becomes of a sample (``candidate``: a glitch candidate) with ``held`` samples already kept back, at most
    ``burst`` kept before a run of candidates counts as a move."""
    if candidate:
        return HOLD if held + 1 <= burst else MOVE
    return GLITCH if held else PASS
