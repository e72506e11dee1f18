"""Shared fixtures and session set-up.

* The reference data the tests need lives in tests/data (each folder with its source and licence).
* Run in parallel (``pytest -n auto``, pytest-xdist), the numba kernels are compiled once, in the
  controller, so that two workers never compile the same kernel at once (on a fresh clone that is
  about a minute of CPU); the workers load them from numba's cache.
* The suite's split: a test measured over ``LONG_S`` (tests/durations.json) is marked ``long``, which
  the README's test command leaves to CI (``.ci/run`` runs the long tests after the suite).
* Units of work (``FileOrTestScheduling``): a test file goes to one worker whole, so that its
  module fixtures are computed once; in the files of long tests (``SPLIT``) each test (or
  test class: tests that read one fixture are a class) is a unit of its own, so both workers
  share them. The longest units go out first (``RUN_FIRST``): they need only the batch kernels
  (compiled before the workers start), so the online kernels compile beside them, and the short
  files at the end let the workers finish together.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"

#: The batch kernels (simulation, identification, diagnosis): compiled before the workers start.
BATCH_KERNELS = (
    "import numpy as np, creep_online as c\n"
    "from creep_online.diagnostics import diagnose\n"
    "t = np.arange(2000) * 1e-3; u = (t > 0.1) * 1.0\n"
    "y = c.simulate(c.CreepModel(0.3, 0.01, 1e-4), t, u) + 1e-3 * np.random.default_rng(0).standard_normal(t.size)\n"
    "c.identify(t, u, y); diagnose((t, u, y), candidates=('drift', 'delay'), workers=1)\n"
)
#: The online kernels (estimator, recursive tracker, compensator): compiled while the first tests run.
ONLINE_KERNELS = (
    "from creep_online.online import compensator, estimator, recursive\n"
    "estimator.warm_kernels(); recursive.warm(); compensator.warm_kernels()\n"
)
#: Files whose tests are each long (a diagnosis, a documentation page's examples, a replay of a record): under -n
#: every test (or test class) is a unit of work, so that both workers share the file.
SPLIT = ("test_real_data.py", "test_diagnose_pairs.py", "test_diagnostics.py", "test_docs.py",
         "test_online_divergence.py", "test_hysteresis_fit.py")
#: Under -n these files go out first, in this order (the longest first; the rest follow in collection order).
RUN_FIRST = (*SPLIT, "test_online.py", "test_hil_faults.py", "test_bench_scenarios.py", "test_hold_physics.py",
             "test_scenarios.py", "test_diagnose_parallel.py", "test_readonly_install.py", "test_transport_pi.py",
             "test_identify_convergence.py", "test_online_kernels.py", "test_transport_can.py", "test_capancdt.py")

#: Each test's measured time (tests/durations.json: the least over CI runs on 2 cores, both busy; written by
#: ``python -m bench.bench_test_suite --durations`` from ``.ci/run``'s junit XML). A test over ``LONG_S`` is
#: marked ``long``: the rest, the README's test command, take about 5 minutes of a 2-core machine
#: (bench/bench_test_coverage.py says which lines of the package only the long tests run). A test not in the
#: file (a new one) runs in the default suite until the file is written again.
DURATIONS = Path(__file__).resolve().parent / "durations.json"
LONG_S = 2.0
#: Kept in the default suite whatever they take: the README's own examples (a newcomer's first page), the demo
#: and its compensation run (the first command's), and the tests that alone run the most lines of the package
#: per second among those over ``LONG_S`` (``bench_test_coverage --by-test --cover``: at least 3 lines a second),
#: one diagnosis that runs the pair search's rounds (otherwise only the long real-record tests reach them), and
#: the capaNCDT emulator's every fault at once (its fault paths: the other fault tests are long).
ALWAYS_DEFAULT = frozenset({
    "tests/test_docs.py::test_examples_run[README.md]",
    "tests/test_demo.py::test_demo_runs_without_a_tty_and_writes_a_report",
    "tests/test_compensator_loop.py::test_demo_compensate_writes_the_compensation_report",
    "tests/test_adversarial.py::test_compare_report_keeps_the_users_folders",
    "tests/test_transport_pi.py::test_a_tcp_controller_that_comes_back_is_reconnected",
    "tests/test_adversarial.py::test_every_source_option_refuses_hostile_values_in_one_line[csv-realtime]",
    "tests/test_identify_convergence.py::test_asynchronous_input_changes_are_warned_and_synchronous_ones_not",
    "tests/test_batch.py::test_an_earlier_table_is_not_a_record_and_no_record_is_overwritten",
    "tests/test_fuzz_frames.py::test_fuzz_binary_fast",
    "tests/test_online.py::test_a_start_up_correction_is_reported_as_such",
    "tests/test_hold_physics.py::test_the_holds_name_the_hidden_effect_at_every_strength[30.0-drift]",
    "tests/test_diagnostics.py::test_the_pair_search_names_two_hidden_effects",
    "tests/test_capancdt.py::test_faults_are_counted_exactly_and_every_sample_is_the_plants",
})

_warming: list[subprocess.Popen] = []


def _runs_workers(config: pytest.Config) -> bool:
    """True in the pytest-xdist controller of a parallel run (not in a worker, not in a serial run)."""
    return bool(getattr(config.option, "numprocesses", None)) and not hasattr(config, "workerinput")


def _warm(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def _reap(proc: subprocess.Popen) -> None:
    _, err = proc.communicate(timeout=900)
    if proc.returncode != 0:      # the tests that use the kernels say what is wrong; this says why they compiled
        sys.stderr.write(f"conftest: compiling the numba kernels failed:\n{err[-2000:]}\n")


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    if not _runs_workers(session.config):
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line("loading the numba kernels for the workers (compiling them takes about a minute "
                            "of CPU on a fresh clone)")
    _warming.append(_warm(ONLINE_KERNELS))
    _reap(_warm(BATCH_KERNELS))


def pytest_sessionfinish(session: pytest.Session) -> None:
    while _warming:
        _reap(_warming.pop())


def measured_long(path: Path = DURATIONS, threshold: float = LONG_S) -> frozenset[str]:
    """The node ids of the tests measured over ``threshold`` seconds (``ALWAYS_DEFAULT`` excepted)."""
    seconds = json.loads(path.read_text())["seconds"] if path.exists() else {}
    return frozenset(k for k, s in seconds.items() if s > threshold and k not in ALWAYS_DEFAULT)


@pytest.hookimpl(tryfirst=True)      # before pytest's -m selection
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    long_ids = measured_long()
    for item in items:
        if item.nodeid in long_ids:
            item.add_marker(pytest.mark.long)
    if hasattr(config, "workerinput"):      # an xdist worker: every worker sorts alike
        items.sort(key=lambda item: RUN_FIRST.index(item.path.name) if item.path.name in RUN_FIRST
                   else len(RUN_FIRST))


def _unit_of_work(nodeid: str) -> str:
    """A test file, or in a ``SPLIT`` file one test or test class ("file::Class"), goes to one worker whole."""
    path, _, rest = nodeid.partition("::")
    if Path(path).name not in SPLIT:
        return path
    first = rest.split("::")[0]
    return f"{path}::{first}" if "::" in rest else nodeid


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """pytest-xdist's file-at-a-time scheduling with the long tests' files taken test by test."""
    if config.getvalue("dist") != "loadscope":      # another --dist asked for on the command line: xdist's own
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileOrTestScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _unit_of_work(nodeid)

    return FileOrTestScheduling(config, log)


@pytest.fixture(scope="session")
def reference_data() -> Path:
    """Path of tests/data: FOMCON outputs, exact references and real measurements."""
    return DATA
