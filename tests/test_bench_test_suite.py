"""bench_test_suite reads what ``.ci/run`` prints and pytest's junit XML (no suite is run here)."""
from __future__ import annotations

from bench import bench_test_suite as bench

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
