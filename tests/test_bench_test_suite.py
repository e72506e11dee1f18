"""bench_test_suite reads what ``.ci/run`` prints and pytest's junit XML (no suite is run here)."""
from __future__ import annotations

import json

from bench import bench_test_suite as bench
from bench import suite_cpu

LOG = """== quick start 1: install and run the demo
demo output
== quick start 1: install and run the demo: 113 s wall (load average 1.04 1.80 2.69)
== quick start 2: the test suite
........
1519 passed, 6 deselected in 281.40s (0:04:41)
== quick start 2: the test suite: 283 s wall (load average 1.95 2.10 2.40)
== the slow tests
........
140 passed, 1738 deselected in 401.20s (0:06:41)
== the slow tests: 403 s wall (load average 2.05 2.20 2.30)
"""

XML = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest">
<testcase classname="tests.test_a" name="test_one" time="12.5"/>
<testcase classname="tests.test_a" name="test_two[x]" time="0.5"><failure message="boom"/></testcase>
<testcase classname="tests.test_b" name="test_three" time="3.0"><skipped message="no"/></testcase>
</testsuite></testsuites>"""


def test_the_steps_wall_times_and_loads_come_from_the_ci_log():
    out = bench.parse_log(LOG)
    assert out["steps"]["install_and_demo"] == {"wall_s": 113, "load_average_after": [1.04, 1.80, 2.69]}
    assert out["steps"]["suite"] == {"wall_s": 283, "load_average_after": [1.95, 2.10, 2.40]}
    assert out["steps"]["slow"] == {"wall_s": 403, "load_average_after": [2.05, 2.20, 2.30]}
    assert out["pytest_summary"] == "1519 passed, 6 deselected"
    assert out["pytest_summary_slow"] == "140 passed, 1738 deselected"


def test_counts_and_the_slowest_tests_come_from_the_junit_xml(tmp_path):
    path = tmp_path / "junit.xml"
    path.write_text(XML)
    out = bench.parse_junit(str(path), top=2)
    assert out["counts"] == {"passed": 1, "failed": 1, "error": 0, "skipped": 1} and out["tests"] == 3
    assert out["slowest"] == [{"test": "tests/test_a.py::test_one", "s": 12.5},
                              {"test": "tests/test_b.py::test_three", "s": 3.0}]
    assert out["sum_of_test_times_s"] == 16.0 and out["test_time_s"]["max"] == 12.5
    assert bench.summary([{"steps": bench.parse_log(LOG)["steps"]}])["within_target"] is True


def test_the_cpu_profile_sums_each_tests_cpu_per_file_and_ranks_the_costliest(tmp_path):
    rows = [{"id": "tests/test_a.py::test_one", "wall": 9.0, "self": 2.0, "children": 0.5},
            {"id": "tests/test_a.py::test_two", "wall": 1.0, "self": 0.2, "children": -0.0},
            {"id": "tests/test_b.py::test_three", "wall": 4.0, "self": 0.0, "children": 3.0}]
    for worker, part in (("gw0", rows[:2]), ("gw1", rows[2:])):
        (tmp_path / f"{worker}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in part))
    out = bench.cpu_profile(sorted(str(p) for p in tmp_path.glob("*.jsonl")), top=2)
    assert out["tests"] == 3 and out["sum_own_cpu_s"] == 2.2 and out["sum_children_cpu_s"] == 3.5
    assert out["sum_wall_s"] == 14.0
    assert out["files"] == {"tests/test_b.py": {"tests": 1, "cpu_s": 3.0, "wall_s": 4.0},
                            "tests/test_a.py": {"tests": 2, "cpu_s": 2.7, "wall_s": 10.0}}
    assert [c["test"] for c in out["costliest"]] == ["tests/test_b.py::test_three", "tests/test_a.py::test_one"]


def test_the_plugin_writes_one_row_per_test_with_its_cpu(tmp_path):
    """``-p bench.suite_cpu`` in a real pytest run: a test that spins ~0.2 s of CPU and one that runs a child."""
    import os
    import subprocess
    import sys

    (tmp_path / "test_spin.py").write_text(
        "import subprocess, sys, time\n"
        "def test_spin():\n    end = time.process_time() + 0.2\n    while time.process_time() < end: pass\n"
        "def test_child():\n    subprocess.run([sys.executable, '-c', 'pass'], check=True)\n")
    out = tmp_path / "cpu"
    out.mkdir()
    env = {**os.environ, suite_cpu.DIR_ENV: str(out), "PYTHONPATH": str(bench.ROOT)}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "bench.suite_cpu", "-p", "no:cacheprovider",
                           "-o", "addopts=", str(tmp_path / "test_spin.py")], cwd=tmp_path, env=env,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-2000:]
    rows = {r["id"].split("::")[1]: r for r in map(json.loads, (out / "main.jsonl").read_text().splitlines())}
    assert set(rows) == {"test_spin", "test_child"}
    assert rows["test_spin"]["self"] >= 0.19 and rows["test_child"]["children"] > 0.0


def test_the_durations_file_keeps_each_tests_least_time_and_splits_the_suite_at_its_threshold(tmp_path):
    """``--durations``: a test's least time over the runs given (a fresh clone's first tests also compile
    kernels); conftest marks ``long`` the tests over the threshold, the ones kept in the default suite excepted."""
    from conftest import ALWAYS_DEFAULT, measured_long

    first, second = tmp_path / "suite.xml", tmp_path / "long.xml"
    first.write_text(XML)
    second.write_text(XML.replace('time="12.5"', 'time="1.5"').replace(
        'classname="tests.test_b"', 'classname="tests.test_bench_test_suite.TestLike"'))
    out = tmp_path / "durations.json"
    bench.write_durations([str(first), str(second)], str(out))
    seconds = json.loads(out.read_text())["seconds"]
    assert seconds == {"tests/test_a.py::test_one": 1.5, "tests/test_a.py::test_two[x]": 0.5,
                       "tests/test_b.py::test_three": 3.0,
                       "tests/test_bench_test_suite.py::TestLike::test_three": 3.0}
    assert measured_long(out, 2.0) == {"tests/test_b.py::test_three",
                                       "tests/test_bench_test_suite.py::TestLike::test_three"}
    assert measured_long(out, 1.0) == set(seconds) - {"tests/test_a.py::test_two[x]"}
    seconds[next(iter(ALWAYS_DEFAULT))] = 99.0
    out.write_text(json.dumps({"seconds": seconds}))
    assert not measured_long(out, 2.0) & ALWAYS_DEFAULT
