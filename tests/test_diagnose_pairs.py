"""Two effects hidden at once: ``diagnose`` names both and fits them together to the noise floor.

Records from ``bench/bench_diagnose_pairs.py`` (seed 0 of two of its cells, where the
diagnosis is right today; docs/diagnostics.md, "Two effects at once", has the whole
table and where it fails). Outcomes only, never timings.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from creep_online.diagnostics import diagnose

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    saved = sys.path[:]                  # the bench puts bench/ on the path (it imports the bands bench's generator)
    try:
        spec = importlib.util.spec_from_file_location("bench_diagnose_pairs", ROOT / "bench" / "bench_diagnose_pairs.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    finally:
        sys.path[:] = saved
    return mod


@pytest.mark.parametrize("pair, band", [(("second_mode", "hysteresis"), "3-10x"), (("hysteresis", "drift"), "10-100x")])
def test_two_hidden_effects_are_both_named_and_their_combination_reaches_the_noise_floor(pair, band):
    bench = _bench()
    rec = bench.make_pair_record(pair, bench.BANDS[band], 0)
    d = diagnose((rec["t"], rec["u"], rec["y"]))
    assert {c.effect for c in d.candidates if c.significant}.issuperset(pair)
    assert set([c.effect for c in d.candidates if c.significant][:2]) == set(pair)
    assert d.verdict in pair
    assert d.combination is not None and set(d.combination.fit.effects) == set(pair)
    assert d.combination.significant                      # the second effect adds evidence over the first alone
    assert d.combination.fit.residual_rms <= bench.FLOOR * rec["noise"]
