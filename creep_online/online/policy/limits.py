"""What "determined" means: the relative 1-sigma below which the data determine a parameter.

One definition for the quality rule (``policy.quality``: ``provisional`` until every parameter is determined) and the
window tracker (``trackers.research``: a determined resonance that misfits is searched again). Half the accuracy
goals (alpha 2 %, b 3 %, a1 and a2 5 %): an estimate within them at 1 sigma lands within the goals ~95 % of the time.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ...errors import DataError


@dataclass(frozen=True)
class DeterminedLimits:
    """Relative 1-sigma below which the data determine a parameter (in this order the quality names the first
    one that is not)."""

    alpha: float = 0.01
    b: float = 0.015
    a1: float = 0.025
    a2: float = 0.025

    def __post_init__(self) -> None:
        for name, value in self.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise DataError(f"DeterminedLimits.{name} must be a positive finite number, got {value!r}")

    def items(self) -> list[tuple[str, float]]:
        """(name, limit) in order."""
        return [(f.name, getattr(self, f.name)) for f in dataclasses.fields(self)]
