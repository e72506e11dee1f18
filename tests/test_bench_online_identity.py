"""The online identity bench: how it compares two trajectories, and that both sides run alike (each in a worker
of its own, its tree first on the path, an empty numba cache of its own)."""
from __future__ import annotations

import math

from bench import bench_online_identity as bench
from bench.bench_online_scenarios import ROOT, baseline_tree

NAN = math.nan


def _run(alpha: list[float], quality: list[str] | None = None, error: str | None = None) -> dict:
    n = len(alpha)
    traj = {"samples": list(range(1, n + 1)), "quality": quality or ["good"] * n, "alpha": alpha,
            "a1": [1.0] * n, "a2": [2.0] * n, "b": [3.0] * n}
    return {"error": error, "traj": traj}


def test_equal_trajectories_are_identical_and_nan_equals_nan():
    cmp = bench.compare_runs(_run([NAN, 0.5, 0.5]), _run([NAN, 0.5, 0.5]), rtol=0.0)
    assert cmp == {"identical": True, "max_rel_diff": 0.0, "first_diff_chunk": None}


def test_the_first_differing_chunk_and_the_largest_difference_are_named():
    cmp = bench.compare_runs(_run([0.5, 0.5, 0.5 * (1 + 1e-7), 0.6]), _run([0.5, 0.5, 0.5, 0.5]), rtol=0.0)
    assert not cmp["identical"] and cmp["first_diff_chunk"] == 2
    assert math.isclose(cmp["max_rel_diff"], 0.2)
    within = bench.compare_runs(_run([0.5, 0.5 * (1 + 1e-9)]), _run([0.5, 0.5]), rtol=1e-8)
    assert within["identical"] and within["max_rel_diff"] > 0.0


def test_a_quality_a_nan_or_a_length_that_differs_is_a_difference():
    assert bench.compare_runs(_run([0.5], ["good"]), _run([0.5], ["degraded"]), 0.0)["first_diff_chunk"] == 0
    assert bench.compare_runs(_run([NAN, 0.5]), _run([0.5, 0.5]), 0.0)["max_rel_diff"] == math.inf
    shorter = bench.compare_runs(_run([0.5]), _run([0.5, 0.5]), 0.0)
    assert not shorter["identical"] and shorter["first_diff_chunk"] == 1
    assert bench.compare_runs(_run([0.5], error="E"), _run([0.5], error="E"), 0.0)["identical"]


def test_each_side_runs_its_own_tree_in_a_worker_with_an_empty_numba_cache_of_its_own(tmp_path):
    """No records: the workers only import the package and report which one (what ``main`` checks)."""
    base = baseline_tree("HEAD", tmp_path / "baseline_src")
    sides = {name: bench.start_side(tree, [], "block", {}, tmp_path / name)
             for name, tree in (("current", ROOT), ("baseline", base))}
    reports = {name: bench.finish_side(proc, out, name) for name, (proc, out) in sides.items()}
    assert reports["current"]["package"] == str(ROOT / "creep_online" / "__init__.py")
    assert reports["baseline"]["package"] == str(base / "creep_online" / "__init__.py")
    assert all(r["results"] == [] and not r["hil_sim_imported"] for r in reports.values())
    for name in sides:
        assert reports[name]["numba_cache_dir"] == str(tmp_path / name / "numba_cache")
