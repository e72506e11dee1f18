"""The candidate fits of ``diagnose`` on several threads give the serial run's diagnosis, bit for bit.

``diagnostics/pool.py`` runs the independent candidate fits at once; the
remembered responses of the record are shared (exact reuse only) and every
fit owns its designs, so nothing may differ: verdict, ranking, evidence, the
fitted parameters, residual sums, evaluation counts and the combination. The
records: a hidden hysteresis (its fit explores on a window of the record and a
combination is fitted) and a clean one. No timing is asserted.

The fits run with BLAS on one thread whatever the caller's process set (a
program that imported numpy first gets OpenBLAS' threads, which only add
synchronisation on these small matrices).
"""
from __future__ import annotations

import os

import pytest

from creep_online.diagnostics import diagnose
from creep_online.diagnostics.pool import (MAX_WORKERS, WORKERS_ENV, available_cores, default_workers, ordered_map,
                                          resolve_workers)
from creep_online.errors import CreepOnlineError
from hil_sim.hidden_effects import hidden_dataset


def _outcome(d) -> list:
    """Everything a diagnosis decides, exactly (floats compared bit for bit)."""
    out = [d.verdict, d.noise_rms, sorted(d.skipped.items()), d.base.rss, d.base.theta.tobytes()]
    for c in d.candidates:
        out.append((c.effect, c.evidence, c.significant, c.fit.rss, c.fit.theta.tobytes(), c.fit.coef.tobytes(),
                    c.fit.nfev, c.signature))
    if d.combination is not None:
        c = d.combination
        out.append((c.effect, c.evidence, c.significant, c.fit.rss, c.fit.theta.tobytes(), c.fit.nfev))
    return out


@pytest.mark.parametrize("effect,seed,n", [("hysteresis", 1, 12_000), (None, 3, 4000)])
def test_parallel_diagnosis_equals_serial(effect, seed, n):
    ds = hidden_dataset(effect, seed, n=n)
    serial = diagnose((ds.t, ds.u, ds.y), workers=1)
    parallel = diagnose((ds.t, ds.u, ds.y), workers=3)
    assert _outcome(parallel) == _outcome(serial)
    assert serial.verdict == (effect or "none")


def test_the_fits_run_with_one_blas_thread_whatever_the_caller_set(monkeypatch):
    """diagnose, fit_base, fit_extended and compare, called with BLAS allowed two threads, solve on one."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from creep_online.diagnostics import compare, extended, fit_base, fit_extended, prepare

    seen = []
    solve = extended._solve

    def spying(*args):
        seen.append(max(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"))
        return solve(*args)

    monkeypatch.setattr(extended, "_solve", spying)
    ds = hidden_dataset("drift", 3, n=2000)
    with threadpool_limits(limits=2, user_api="blas"):
        assert max(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas") == 2
        diagnose((ds.t, ds.u, ds.y), candidates=("drift",), combine=False, workers=2)
        data = prepare(ds.t, ds.u, ds.y)
        fit = fit_extended(data, ("drift",), fit_base(data))
        compare(fit, (ds.t, ds.u, ds.y))
    assert seen and set(seen) == {1}, sorted(set(seen))


def test_ordered_map_keeps_order_and_raises_in_turn():
    seen = []
    out = list(ordered_map(lambda x: x * x, range(7), 3, before=lambda i, x: seen.append((i, x))))
    assert out == [x * x for x in range(7)]
    assert seen == [(i, i) for i in range(7)]

    def fail_on_three(x):
        if x == 3:
            raise ValueError("three")
        return x

    got = []
    with pytest.raises(ValueError, match="three"):
        for value in ordered_map(fail_on_three, range(6), 2):
            got.append(value)
    assert got == [0, 1, 2]          # the results before the failing item, as the serial loop gives them


def test_workers_resolution(monkeypatch):
    assert resolve_workers(1) == 1 and resolve_workers(2) == 2
    for bad in (0, -1, 1.5):
        with pytest.raises(CreepOnlineError):
            resolve_workers(bad)
    monkeypatch.setenv(WORKERS_ENV, "1")
    assert default_workers() == 1 and resolve_workers(None) == 1
    monkeypatch.setenv(WORKERS_ENV, "two")
    with pytest.raises(CreepOnlineError, match=WORKERS_ENV):
        default_workers()
    monkeypatch.delenv(WORKERS_ENV)
    # the cores this process may use (one core: serial, no threads), at most MAX_WORKERS
    assert default_workers() == min(available_cores(), MAX_WORKERS)
    assert 1 <= available_cores() <= max(1, os.cpu_count() or 1)
