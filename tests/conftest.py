"""Shared fixtures and session set-up.

* The reference data the tests need lives in tests/data (each folder with its source and licence).
* Run in parallel (``pytest -n auto``, pytest-xdist), the numba kernels are compiled once, before
  the workers start, so that two workers never compile the same kernel at once (on a fresh clone
  that is about a minute of CPU each); the workers then load them from numba's cache.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"

#: Compiles (or loads from numba's cache) every kernel family; the two halves take about as long.
WARM_KERNELS = (
    "from creep_online.online.estimator import warm_kernels; warm_kernels()",
    "import numpy as np, creep_online as c\n"
    "from creep_online.online import compensator, recursive\n"
    "from creep_online.diagnostics import diagnose\n"
    "compensator.warm_kernels(); recursive.warm()\n"
    "t = np.arange(2000) * 1e-3; u = (t > 0.1) * 1.0\n"
    "y = c.simulate(c.CreepModel(0.3, 0.01, 1e-4), t, u) + 1e-3 * np.random.default_rng(0).standard_normal(t.size)\n"
    "c.identify(t, u, y); diagnose((t, u, y), candidates=('drift', 'delay'), workers=1)\n",
)


def _runs_workers(config: pytest.Config) -> bool:
    """True in the pytest-xdist controller of a parallel run (not in a worker, not in a serial run)."""
    return bool(getattr(config.option, "numprocesses", None)) and not hasattr(config, "workerinput")


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    if not _runs_workers(session.config):
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line("loading the numba kernels for the workers (compiling them takes about a minute "
                            "of CPU on a fresh clone)")
    procs = [subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True) for code in WARM_KERNELS]
    for proc in procs:
        _, err = proc.communicate(timeout=900)
        if proc.returncode != 0:      # the tests that use the kernel will say what is wrong
            sys.stderr.write(f"conftest: warming the numba kernels failed:\n{err[-2000:]}\n")


@pytest.fixture(scope="session")
def reference_data() -> Path:
    """Path of tests/data: FOMCON outputs, exact references and real measurements."""
    return DATA
