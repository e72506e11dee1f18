"""bench_test_coverage's arithmetic: the lines a change to the suite lost, and the cheapest tests that run them
(no suite is run here: coverage's own data files are written by hand)."""
from __future__ import annotations

import pytest

from bench import bench_test_coverage as bench


def test_lost_lines_are_those_the_earlier_run_ran_and_this_one_does_not():
    before = {"a.py": {"statements": [1, 2, 3, 4], "run": [1, 2, 3]}, "b.py": {"statements": [1, 2], "run": [1, 2]}}
    after = {"a.py": {"statements": [1, 2, 3, 4], "run": [1, 4]}}
    assert bench.lost(before, after) == {"a.py": [2, 3], "b.py": [1, 2]}
    assert bench.lost(after, after) == {}
    assert bench.summary(before) == {"files": 2, "statements": 6, "covered": 5, "percent": pytest.approx(83.33)}


def test_the_cover_takes_the_most_lines_per_second_first_and_names_what_no_test_ran():
    lost = {"a.py": [1, 2, 3, 4, 5], "b.py": [7]}
    by_test = {"slow_all": {"a.py": {1, 2, 3, 4}},            # 4 lines in 40 s
               "quick_two": {"a.py": {1, 2}},                 # 2 lines in 1 s
               "quick_rest": {"a.py": {3, 4}, "c.py": {9}},   # 2 lines in 1 s (c.py was not lost)
               "other": {"b.py": {8}}}
    seconds = {"slow_all": 40.0, "quick_two": 1.0, "quick_rest": 1.0, "other": 0.5}
    chosen, unreached = bench.cheapest_cover(lost, by_test, seconds)
    assert [c["test"] for c in chosen] == ["quick_two", "quick_rest"]
    assert [c["lines"] for c in chosen] == [2, 2]
    assert unreached == 2                                     # a.py:5 and b.py:7: no test ran them


def test_each_tests_children_are_counted_for_that_test(tmp_path):
    """Coverage data as the suite leaves it: contexts in the run's file, one file per test's child."""
    from coverage import CoverageData

    root = str(bench.ROOT)
    main = CoverageData(str(tmp_path / ".coverage"))
    main.set_context("tests/test_x.py::test_one|run")
    main.add_lines({f"{root}/creep_online/model.py": [1, 2]})
    main.set_context("tests/test_x.py::test_two|setup")
    main.add_lines({f"{root}/creep_online/model.py": [3]})
    main.write()
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "tests.gw0.jsonl").write_text('{"id": "tests/test_x.py::test_two", "number": "gw0-1"}\n')
    child = CoverageData(str(tmp_path / "tests" / "child.gw0-1.host.42.xyz"))
    child.add_lines({f"{root}/creep_online/cli.py": [5]})
    child.write()
    out = bench.lines_by_test(tmp_path)
    assert out == {"tests/test_x.py::test_one": {"creep_online/model.py": {1, 2}},
                   "tests/test_x.py::test_two": {"creep_online/model.py": {3}, "creep_online/cli.py": {5}}}
    bench.join_children(tmp_path)
    whole = CoverageData(str(tmp_path / ".coverage"))
    whole.read()
    assert sorted(whole.lines(f"{root}/creep_online/cli.py")) == [5]
