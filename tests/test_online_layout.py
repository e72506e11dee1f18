"""The window state array's layout comes from one definition (``online._kernels.layout``)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.online._kernels import layout as L
from creep_online.online._kernels import recursive as RK
from creep_online.online._kernels import window as W


@pytest.mark.parametrize("q, m, r", [(q, m, r) for q in (1, 10, 42, 57) for m in (0, 4, 8) for r in (0, 1, 2)])
def test_the_kernels_offsets_are_the_definitions(q, m, r):
    """The inlined numba offsets, the Python offsets and the blocks laid end to end agree."""
    off = L.offsets(q, m, r)
    p = q + W.FREE + m + r
    ends = [L.SCALARS]
    for name, size in L.BLOCKS:
        assert off[name] == ends[-1], name
        ends.append(ends[-1] + size.of(q, m, r))
    assert off["size"] == ends[-1] and off["p"] == p and off["phi"] == W.SC_SIZE
    assert (L.co_at(q, m, r), L.ztail_at(q, m, r), L.md_at(q, m, r)) == (off["co"], off["ztail"], off["md"])
    assert L.co_size(q, m) == off["ztail"] - off["co"] == 2 * q + L.RESONANCE + m
    assert L.resonance_in_co(q) == 2 * q and L.free_decay_in_co(q) == 2 * q + L.RESONANCE
    assert W.layout(q, m, r) == off
    if r == 0:                     # the recursive tracker's blocks follow the window layout
        assert RK.layout(q, m)["r"] == off["size"]


def test_every_slot_of_a_state_is_named_once():
    basis_q, m, r = 12, 4, 2
    st = np.zeros(L.offsets(basis_q, m, r)["size"])
    W.start_state(st, np.full(basis_q, 0.5), np.full(basis_q, 0.1), np.full(m, 0.9), 0.999, 1e-3, 2e-3, 1e-6, r)
    rows = L.describe_state(st)
    assert [i for i, _, _ in rows] == list(range(st.size))
    names = [n for _, n, _ in rows]
    assert len(set(names)) == len(names)
    named = dict((n, v) for _, n, v in rows)
    assert named["SC_NQ"] == basis_q and named["SC_NM"] == m and named["SC_A1L"] == 2e-3 and named["SC_H"] == 1e-3
    assert named["co.decay[0]"] == 0.5 and named["co.gain[11]"] == 0.1 and named["co.free_decay[3]"] == 0.9
    assert not math.isnan(named["co.resonance[0]"])
    text = L.format_state(st, limit=3)
    assert text.splitlines()[0].split()[:2] == ["0", "SC_G"]
