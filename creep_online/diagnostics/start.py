"""How a record starts: the one rule ``identify``, ``fit``, ``diagnose`` and ``compare`` share.

A first input u[0] != 0 reads two ways: the plant at rest at input 0 until the
first sample, where the input jumps to u[0] (a step test logged from its first
sample), or the plant in equilibrium at u[0] (a record cut out of operation:
the model sees u - u[0]). An input at 0 on the first sample reads the same both
ways.

The rule is ``identify``'s: from rest when the input is piecewise constant
(``identification.input_schedule``: a step experiment), in equilibrium at u[0]
otherwise. The other reading replaces it only when its fit leaves clearly less
residual (sum of squares below ``CLEARLY_BETTER`` times the first's). A reading
given explicitly (``u_pre``/``t_pre``: a caller's, or the loader's reading of a
creep-test log) is kept. ``identify`` goes one step further on a record whose
plant moves at its first sample: the free response of an unknown initial state
(``creep_online.initial_state``), kept when BIC prefers it.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import CreepOnlineError
from . import extended as ext

#: The second reading replaces the first only when its residual sum of squares is below this fraction
#: of the first's: a clear difference, not noise between two nearly equal fits.
CLEARLY_BETTER = 0.9

Reading = tuple[float | None, float | None]   # (u_pre, t_pre) as ``extended.prepare`` takes them


def readings(u: np.ndarray, u_pre: float | None = None, t_pre: float | None = None) -> list[Reading]:
    """The readings to try, the rule's first: [(u_pre, t_pre), ...].

    One when the caller gave a reading, when u[0] is 0 (both readings agree) or when the input is
    constant (a constant non-zero input can only be a step at the first sample); else the default
    (from rest for a piecewise-constant input, equilibrium otherwise) and the other.
    """
    u = np.asarray(u, dtype=float)
    if u_pre is not None or t_pre is not None:
        return [(u_pre, t_pre)]
    if u.size == 0 or u[0] == 0.0:
        return [(None, None)]
    if np.ptp(u) == 0.0:
        return [(0.0, None)]
    rest, equilibrium = (0.0, None), (None, None)
    return [rest, equilibrium] if piecewise_constant(u) else [equilibrium, rest]


def piecewise_constant(u: np.ndarray) -> bool:
    """identify's test for a step experiment: few input changes (``identification.input_schedule``)."""
    from ..identification import input_schedule
    return bool(input_schedule(np.arange(np.size(u), dtype=float), np.asarray(u, dtype=float)).piecewise)


def clearly_better(rss_other: float, rss_first: float) -> bool:
    """Whether the other reading's residual sum of squares beats the first's clearly (``CLEARLY_BETTER``)."""
    return rss_other < CLEARLY_BETTER * rss_first


def describe(reading: Reading, u0: float, t0: float) -> str:
    """The reading in words, for a note."""
    u_pre, t_pre = reading
    if u_pre is None:
        return f"the record starts in equilibrium at its first input {u0:g} (the model sees u - u[0])"
    at = t0 if t_pre is None else t_pre
    return f"the record starts from rest: input read as a jump {u_pre:g} -> {u0:g} at t = {at:g} s"


def identify_start(data: ext.Prepared, warnings: list[str]):
    """identify()'s model as one start of the base fit (uniform records); None if it cannot run.

    identify runs on the record's exploration window (``Prepared.explore_data``: the record itself unless it is
    long), where the base fit ranks its starts too: the model is only a start, polished on the whole record
    afterwards, and identify on a long record taken in operation runs its global multi-start fit on every
    sample (14 s of a 50,001-sample record against 0.4 s on its 10,387-sample window, the same base fit).
    """
    if not data.uniform:
        return None
    try:
        from ..identification import identify
        small = data.explore_data()
        return identify(small.t, small.u, small.y, polish=False).model
    except CreepOnlineError as exc:
        warnings.append(f"identify() gave no start ({exc}); grid start used")
    except Exception as exc:  # noqa: BLE001 - identify is a starting point only; its failure must not stop the fit
        warnings.append(f"identify() failed ({type(exc).__name__}: {exc}); grid start used")
    return None


def fit_base_by_rule(t: np.ndarray, u: np.ndarray, y: np.ndarray, *, source: str = "<array>",
                     u_pre: float | None = None, t_pre: float | None = None, use_identify: bool = True,
                     max_nfev: int = ext.MAX_NFEV, warnings: list[str] | None = None,
                     report: Callable[[str], None] | None = None) -> tuple[ext.Prepared, ext.ExtendedFit]:
    """The base model fitted under the reading the rule picks: (prepared record, base fit).

    The first reading's fit starts from identify's model (``use_identify``) and a grid; the other
    reading's from that fit's model, and, once it has won, from a grid too. ``warnings`` gets the prepared record's notes and, when the
    input starts away from 0, the reading used; ``report`` the stages as they start.
    """
    warnings = [] if warnings is None else warnings
    report = report or (lambda _stage: None)
    tried = readings(u, u_pre, t_pre)
    data = ext.prepare(t, u, y, source=source, u_pre=tried[0][0], t_pre=tried[0][1])
    warnings.extend(data.notes)
    report("base model: two-layer identification" if use_identify else "base model")
    start = identify_start(data, warnings) if use_identify else None
    report("base model: joint fit")
    base = ext.fit_base(data, start=start, max_nfev=max_nfev)
    chosen = tried[0]
    for other in tried[1:]:
        alt = ext.prepare(t, u, y, source=source, u_pre=other[0], t_pre=other[1])
        alt_base = ext.fit_base(alt, start=base.model, max_nfev=max_nfev, grid=False)
        if clearly_better(alt_base.rss, base.rss):
            # the reading is chosen: its fit gets the grid the first reading's had (a start from the other
            # reading's model can stay in that reading's basin)
            searched = ext.fit_base(alt, start=alt_base.model, max_nfev=max_nfev)
            data, base, chosen = alt, min(alt_base, searched, key=lambda f: f.rss), other
    if len(tried) > 1:
        why = " (fits clearly better than the other reading)" if chosen != tried[0] else ""
        warnings.append(describe(chosen, float(u[0]), float(t[0])) + why)
    return data, base
