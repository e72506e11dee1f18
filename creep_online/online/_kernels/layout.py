"""The layout of the window tracker's flat state array, from one definition.

The per-sample kernel takes one float array ``st`` (fewer arguments per numba call): a header of scalars
(``window.SC_*``), then blocks whose sizes depend on the node count Q, the free responses M and the drift
columns R. ``BLOCKS`` names each block and gives its size as coefficients of (1, Q, M, R); everything else
is generated from it:

* ``offsets(q, m, r)``: the offsets Python uses (``window.layout``);
* ``co_at``, ``ztail_at``, ``md_at``, ``co_size``, ``resonance_in_co``, ``free_decay_in_co``: numba functions
  the kernels inline, whose coefficients are module globals computed from ``BLOCKS`` (numba compiles them
  in as constants: the compiled code is what a hand-written offset gives);
* ``describe_state(st)``: every slot of a state array by name, for debugging.

Inside the ``co`` block (the coefficients) ``CO_PARTS`` gives the sub-blocks the same way.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

#: The regressor after the Q SOE nodes: the resonance states x0, x1 (X0), their a1 sensitivities (S1) and a2
#: sensitivities (S2), the offset (ONE: the alpha-derivative md spans the nodes and these), then the free
#: responses (from FREE) and the drift columns.
X0, S1, S2, ONE, FREE = 0, 2, 4, 6, 7
#: Resonance coefficients: Phi, Gamma at (a1, a2) and their a1- and a2-derivatives (``window.resonance_coefficients``).
RESONANCE = 18
#: Scalars in the header (``window.SC_*``).
SCALARS = 45


class Size(NamedTuple):
    """A block's length as const + q Q + m M + r R."""

    const: int = 0
    q: int = 0
    m: int = 0
    r: int = 0

    def of(self, q: int, m: int, r: int) -> int:
        return self.const + self.q * q + self.m * m + self.r * r


#: The regressor's length P: the nodes and the constant term, the resonance states and the offset, the
#: free responses, the drift columns.
P = Size(FREE, 1, 1, 1)
#: The state array after the header, in order.
BLOCKS = (
    ("phi", P),                     # the regressor
    ("m", P),                       # the model coefficients (prediction = phi . m)
    ("sy", P),                      # the statistics' sum g phi y
    ("co", Size(RESONANCE, 2, 1)),  # the coefficients of the state step (``CO_PARTS``)
    ("ztail", Size(0, 1)),          # the node states before the oldest remembered sample
    ("md", Size(ONE, 1)),           # the alpha-derivative of the model coefficients (b dk/dalpha)
)
#: Inside ``co``: the nodes' per-sample decays and input gains, the resonance coefficients, the free
#: responses' decays.
CO_PARTS = (("decay", Size(0, 1)), ("gain", Size(0, 1)), ("resonance", Size(RESONANCE)), ("free_decay", Size(0, 0, 1)))


def _start(blocks: tuple, name: str, base: int) -> Size:
    """The offset of a block as a Size (the sum of the blocks before it, from ``base``)."""
    total = Size(base)
    for block, size in blocks:
        if block == name:
            return total
        total = Size(*(a + b for a, b in zip(total, size)))
    raise KeyError(name)


def offsets(q: int, m: int, r: int = 0, h: int = 0) -> dict[str, int]:
    """The offsets of the blocks of a state array (``{"sc": 0, "phi": ..., "size": ..., "p": P}``).

    ``h`` hysteresis columns (``hysteresis.py``) count as trailing columns beside the R drift columns, and their
    block (``"hyst"``) follows ``md``."""
    from .hysteresis import size as hyst_size
    out = {"sc": 0}
    for name, _ in BLOCKS:
        out[name] = _start(BLOCKS, name, SCALARS).of(q, m, r + h)
    last, size = BLOCKS[-1]
    out["hyst"] = out[last] + size.of(q, m, r + h)
    out["size"] = out["hyst"] + hyst_size(q, h)
    out["p"] = P.of(q, m, r + h)
    return out


#: The offsets the kernels use, as integer coefficients of (1, Q, M, R): module globals, which numba compiles in
#: as constants.
CO_C, CO_Q, CO_M, CO_R = _start(BLOCKS, "co", SCALARS)
ZTAIL_C, ZTAIL_Q, ZTAIL_M, ZTAIL_R = _start(BLOCKS, "ztail", SCALARS)
MD_C, MD_Q, MD_M, MD_R = _start(BLOCKS, "md", SCALARS)
CO_SIZE_C, CO_SIZE_Q, CO_SIZE_M, _ = dict(BLOCKS)["co"]
RES_C, RES_Q, _, _ = _start(CO_PARTS, "resonance", 0)
FREE_DECAY_C, FREE_DECAY_Q, _, _ = _start(CO_PARTS, "free_decay", 0)


@njit(cache=True, inline="always")
def co_at(q: int, m: int, r: int) -> int:
    """Offset of the coefficients ``co`` in the state array."""
    return CO_C + CO_Q * q + CO_M * m + CO_R * r


@njit(cache=True, inline="always")
def co_size(q: int, m: int) -> int:
    """Length of ``co``."""
    return CO_SIZE_C + CO_SIZE_Q * q + CO_SIZE_M * m


@njit(cache=True, inline="always")
def ztail_at(q: int, m: int, r: int) -> int:
    """Offset of ``ztail`` in the state array."""
    return ZTAIL_C + ZTAIL_Q * q + ZTAIL_M * m + ZTAIL_R * r


@njit(cache=True, inline="always")
def md_at(q: int, m: int, r: int) -> int:
    """Offset of ``md`` in the state array."""
    return MD_C + MD_Q * q + MD_M * m + MD_R * r


@njit(cache=True, inline="always")
def resonance_in_co(q: int) -> int:
    """Offset of the resonance coefficients inside ``co``."""
    return RES_C + RES_Q * q


@njit(cache=True, inline="always")
def free_decay_in_co(q: int) -> int:
    """Offset of the free responses' decays inside ``co``."""
    return FREE_DECAY_C + FREE_DECAY_Q * q


def describe_state(st: np.ndarray, names: dict[int, str] | None = None) -> list[tuple[int, str, float]]:
    """Every slot of a window state array as (index, name, value): the header scalars by their names
    (``names``: index -> name; default the ``window.SC_*`` constants), the blocks as ``phi[3]``, ``co.gain[0]``..."""
    from . import window as W
    if names is None:
        names = {v: k for k, v in vars(W).items() if k.startswith("SC_") and k != "SC_SIZE" and isinstance(v, int)}
    q, m, r = int(st[W.SC_NQ]), int(st[W.SC_NM]), int(st[W.SC_NR]) + int(st[W.SC_NH])
    out = [(i, names.get(i, f"sc[{i}]"), float(st[i])) for i in range(SCALARS)]
    off = offsets(q, m, r)
    for name, size in BLOCKS:
        start, n = off[name], size.of(q, m, r)
        if name == "co":
            for part, psize in CO_PARTS:
                p0 = start + _start(CO_PARTS, part, 0).of(q, m, r)
                out += [(p0 + i, f"co.{part}[{i}]", float(st[p0 + i])) for i in range(psize.of(q, m, r))]
        else:
            out += [(start + i, f"{name}[{i}]", float(st[start + i])) for i in range(n)]
    return out


def format_state(st: np.ndarray, limit: int | None = None) -> str:
    """``describe_state`` as text, one slot per line (the first ``limit`` slots)."""
    rows = describe_state(st)[:limit]
    return "\n".join(f"{i:6d}  {name:<22s} {value: .9g}" for i, name, value in rows)
