"""A pytest plugin that gives each test's child processes a coverage data file of their own.

Loaded with ``-p bench.suite_coverage`` and ``SUITE_COVERAGE_DIR`` set (``bench_test_coverage --by-test``),
every test runs with ``COVERAGE_FILE`` pointing into that folder under a number of its own, and the
numbers go to ``SUITE_COVERAGE_DIR/tests.<worker>.jsonl`` with the node ids: the lines a test's CLI
children ran are then known per test (pytest-cov's ``--cov-context=test`` names the lines run in the
test's own process). A child started with an environment of its own keeps the suite's data file.
No effect without ``SUITE_COVERAGE_DIR``.
"""
from __future__ import annotations

import itertools
import json
import os
from pathlib import Path

import pytest

from bench.suite_cpu import worker_id

DIR_ENV = "SUITE_COVERAGE_DIR"
_numbers = itertools.count()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    folder = os.environ.get(DIR_ENV)
    if not folder:
        yield
        return
    worker = worker_id(item)
    number = f"{worker}-{next(_numbers)}"
    before = os.environ.get("COVERAGE_FILE")
    os.environ["COVERAGE_FILE"] = str(Path(folder) / f"child.{number}")
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("COVERAGE_FILE", None)
        else:
            os.environ["COVERAGE_FILE"] = before
    with (Path(folder) / f"tests.{worker}.jsonl").open("a") as out:
        out.write(json.dumps({"id": item.nodeid, "number": number}) + "\n")
