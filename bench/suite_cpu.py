"""A pytest plugin that writes each test's CPU time, for ``bench_test_suite --here``.

Loaded with ``-p bench.suite_cpu`` and ``SUITE_CPU_DIR`` set, every process running tests (each
pytest-xdist worker) appends one JSON line per test to ``SUITE_CPU_DIR/<worker>.jsonl``: the node id,
its wall time, the CPU time of the process (all its threads) and of the child processes it waited for
(setup + call + teardown). CPU time does not grow with the machine's load as wall time does, so on a
shared machine it is the figure to compare. No effect without ``SUITE_CPU_DIR``.
"""
from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

import pytest

DIR_ENV = "SUITE_CPU_DIR"


def _cpu(who: int) -> float:
    use = resource.getrusage(who)
    return use.ru_utime + use.ru_stime


def worker_id(item: pytest.Item) -> str:
    """The pytest-xdist worker running ``item`` ("main" without xdist), from xdist's own config: the
    environment's worker id is inherited by a pytest a test starts."""
    return getattr(item.config, "workerinput", {}).get("workerid", "main")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    folder = os.environ.get(DIR_ENV)
    if not folder:
        yield
        return
    own, children, wall = _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN), time.perf_counter()
    yield
    row = {"id": item.nodeid, "wall": time.perf_counter() - wall, "self": _cpu(resource.RUSAGE_SELF) - own,
           "children": _cpu(resource.RUSAGE_CHILDREN) - children}
    path = Path(folder) / f"{worker_id(item)}.jsonl"
    with path.open("a") as out:
        out.write(json.dumps(row) + "\n")
