"""Run a diagnosis' independent candidate fits on the machine's cores, with the serial run's results.

``diagnose`` fits one extension of the base model per catalogue effect
(eight); the fits share nothing but the prepared record and its remembered
responses (exact reuse only, ``extended.Prepared``), so they can run at once
(and so can the short polishes of the combination fit, ``extended._short_polishes``).
About half of a fit's CPU time runs without the GIL (scipy's FFTs, BLAS,
numpy's loops, the numba kernels, compiled ``nogil``); the rest holds it
(Python, scipy's f2py LAPACK wrappers such as ``lstsq``, ``lfilter``), so two
threads overlap ~1.5x rather than 2x. Worker processes (fork) measured about
the same (1.87-1.94 s against 2.0-2.1 s on two 30,000-sample records) and were
not taken: they fork a process that has threads, start with cold caches and do
not exist on Windows.

Determinism: every fit is a pure function of the record, the base fit and the
effect; a remembered response is bit for bit what a recomputation gives, and
each fit owns its ``Design`` objects (their solution caches and evaluation
counters). Results are returned in the order of the inputs, so the parallel
run's candidates, evidence, verdict and ranking are those of the serial one
(``tests/test_diagnose_parallel.py``).

Memory: glibc gives each thread its own malloc arena and keeps what a fit
freed there for the next allocation of that thread, so with threads the
diagnosis' resident memory grew with every fit (the 150 V piezo record,
50,001 samples: 830-910 MB peak with two threads, 650 MB with one). Each
worker hands the free pages back (``malloc_trim``, where the C library has
it) after each item.

Workers: ``workers=None`` takes ``CREEP_ONLINE_DIAGNOSE_WORKERS`` if set, else
the cores this process may run on (``os.sched_getaffinity``), capped at
``MAX_WORKERS``; 1 (a one-core machine, or the batch runner that already runs
one process per core) runs everything in the calling thread as before.
"""
from __future__ import annotations

import ctypes
import os
from typing import Callable, Iterable, Iterator, TypeVar

from ..errors import CreepOnlineError

#: At most this many threads by default (the candidate fits: eight, unequal; more threads than cores only add switching).
MAX_WORKERS = 4
#: Environment variable overriding the default number of workers (1 = serial).
WORKERS_ENV = "CREEP_ONLINE_DIAGNOSE_WORKERS"

T = TypeVar("T")
R = TypeVar("R")


def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim`` (free pages of every arena back to the system), None where the C library lacks it."""
    try:
        return ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError, TypeError):
        return None


_TRIM = _malloc_trim()


def _trimmed(fn: Callable[[T], R]) -> Callable[[T], R]:
    """``fn`` followed by ``malloc_trim(0)`` in the same thread (see Memory above)."""
    if _TRIM is None:
        return fn

    def run(item: T) -> R:
        try:
            return fn(item)
        finally:
            _TRIM(0)
    return run


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the platform tells it, else os.cpu_count())."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def default_workers() -> int:
    """Workers for ``diagnose``: ``CREEP_ONLINE_DIAGNOSE_WORKERS`` if set, else the available cores (<= MAX_WORKERS)."""
    env = os.environ.get(WORKERS_ENV, "").strip()
    if env:
        return resolve_workers(_parse_env(env))
    return max(1, min(available_cores(), MAX_WORKERS))


def _parse_env(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise CreepOnlineError(f"{WORKERS_ENV} must be a whole number of workers, got {text!r}") from None


def resolve_workers(workers: int | None) -> int:
    """``workers`` checked (>= 1), or the default when None."""
    if workers is None:
        return default_workers()
    if int(workers) != workers or workers < 1:
        raise CreepOnlineError(f"workers must be a whole number >= 1 (got {workers!r})")
    return int(workers)


def ordered_map(fn: Callable[[T], R], items: Iterable[T], workers: int,
                before: Callable[[int, T], None] | None = None) -> Iterator[R]:
    """``fn(item)`` for each item, yielded in the items' order; on ``workers`` threads when > 1.

    ``before(i, item)`` is called in the calling thread just before item i's
    result is waited for (serial: before it is computed), e.g. to show progress.
    An exception of ``fn`` is raised when its item's turn comes, as in the
    serial loop; the items not yet started are then cancelled.
    """
    items = list(items)
    if workers <= 1 or len(items) <= 1:
        for i, item in enumerate(items):
            if before is not None:
                before(i, item)
            yield fn(item)
        return
    from concurrent.futures import ThreadPoolExecutor   # ~9 ms to import: only when threads are used
    with ThreadPoolExecutor(max_workers=min(workers, len(items)), thread_name_prefix="creep-diagnose") as pool:
        futures = [pool.submit(_trimmed(fn), item) for item in items]
        try:
            for i, (item, future) in enumerate(zip(items, futures)):
                if before is not None:
                    before(i, item)
                yield future.result()
        finally:
            for future in futures:
                future.cancel()
