"""The bench harness: one distribution summary, the results naming rule, the stamped JSON report."""
from __future__ import annotations

import json

import numpy as np
import pytest

from bench import harness


def test_dist_matches_the_direct_percentiles_and_scales_by_per():
    x = np.random.default_rng(3).exponential(2.0, 1001)
    d = harness.dist(x)
    assert d == {"p50": float(np.percentile(x, 50)), "p99": float(np.percentile(x, 99)), "max": float(x.max()),
                 "mean": float(x.mean()), "n": 1001}
    scaled = harness.dist(list(x), per=4.0)
    assert scaled["n"] == 1001
    for key in ("p50", "p99", "max", "mean"):
        assert scaled[key] == pytest.approx(d[key] / 4.0, rel=1e-12)


def test_dist_of_no_values_says_none_rather_than_raising():
    assert harness.dist([]) == {"p50": None, "p99": None, "max": None, "mean": None, "n": 0}


@pytest.mark.parametrize("name", ["online_latency_63e0dda", "online_scenarios_single_40db_08e202d_run2",
                                  "diagnose_pairs_0-7_d6cc48d", "x_4549161", "sub/name"])
def test_results_names_refuse_commit_ids_and_folders(name):
    with pytest.raises(ValueError, match="commit ids"):
        harness.results_path(name)


@pytest.mark.parametrize("name", ["online_latency", "online_scenarios_single_40db", "diagnose_bands_0-99",
                                  "online_oracle_fits_80db_fresh3000", "close_modes_80db"])
def test_results_names_by_what_is_measured_go_to_bench_results(name):
    assert harness.results_path(name) == harness.RESULTS / f"{name}.json"


def test_every_kept_result_is_named_without_a_commit_id():
    names = [p.stem for p in harness.RESULTS.glob("*.json")]
    assert names
    for name in names:
        harness.results_path(name)


def test_the_report_is_stamped_printed_and_written(tmp_path, capsys):
    out = tmp_path / "sub" / "r.json"
    harness.write_report({"value": np.float64(1.5)}, out, argv=["--quick"])
    doc = json.loads(out.read_text())
    assert doc["value"] == 1.5
    run = doc["run"]
    assert run["command"].endswith("--quick") and run["version"]
    assert len(run["load_average"]) == 3 and run["utc"].endswith("Z")
    assert json.loads(capsys.readouterr().out) == doc
