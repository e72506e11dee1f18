"""The records of a fleet on ``dask.distributed``: a local cluster by default, or an existing scheduler.

Local clusters run one single-threaded worker *process* per core, for two
reasons. The identification is numba kernels (compiled without ``nogil``)
driven by Python (scipy's trust-region loop, the layers, the noise tests), so
threads of one interpreter serialise on the GIL wherever a record is in a
kernel or in Python (only numpy's array loops release it; how much that leaves
to a second thread could not be measured on the loaded 2-core machine). And
the warning capture that fills each row's ``warnings`` is process-wide
(``warnings.catch_warnings`` is not thread-safe): two records on two threads
could swap or lose their warnings. BLAS is held to one thread inside each fit
(``creep_online._threads``), so one process per core does not oversubscribe
the machine. The price is the start-up (each process imports numpy, scipy,
numba and dask): ``bench/results/batch.json``.

Records are submitted in a bounded window (``WINDOW_PER_THREAD`` per worker
thread), so a fleet of 10,000 long-format records never sits in the
scheduler's memory at once and Ctrl-C has little to cancel. Dask is imported
here, when a batch runs: it is the ``fleet`` extra.
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time
from itertools import islice
from typing import Any, Callable, Iterable, Iterator

from ..errors import CreepOnlineError, one_line
from ..io.fleet_records import RecordJob
from .row import empty_row

#: Seconds to wait for an existing scheduler before giving up with a one-line error.
CONNECT_TIMEOUT_S = 10.0
#: Worker deaths a task may see before Dask fails it (KilledWorker) on the local cluster (Dask's default: 3, each
#: death of a record too large for memory costing a worker's restart).
ALLOWED_FAILURES = 1
#: Records in flight per worker thread.
WINDOW_PER_THREAD = 4
#: Seconds between two looks at ``run_on_dask``'s ``stop`` while no record has finished.
STOP_POLL_S = 0.05
INSTALL_HINT = "pip install 'creep_online[fleet]'"


def distributed():
    """The ``dask.distributed`` module, or a one-line CreepOnlineError naming the extra to install."""
    try:
        import dask.distributed
    except ImportError:
        raise CreepOnlineError(f"batch identification needs Dask ({INSTALL_HINT})") from None
    return dask.distributed


def default_workers() -> int:
    """One worker process per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


#: The local cluster's own log level. What a record's run raises comes back as its row; below CRITICAL the
#: cluster's processes print Dask's internal races on the user's terminal, e.g. a worker whose heartbeat was in
#: flight while Ctrl-C shut the scheduler down logs "Failed to communicate with scheduler" with a traceback.
WORKER_LOG_LEVEL = logging.CRITICAL


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Any]:
    """A ``Client`` of the scheduler at ``scheduler``, or of a new local cluster of ``workers`` processes.

    The local cluster (and only it) is shut down on exit; an existing cluster is left running.
    """
    dd = distributed()
    if scheduler:
        client = _connect(dd, scheduler)
        with contextlib.closing(client):
            warm_up_workers(client, scheduler)
            yield client
        return
    if workers is not None and workers < 1:
        raise CreepOnlineError(f"--workers must be at least 1 (got {workers})")
    import dask
    with _workers_ignore_ctrl_c(), dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}):
        cluster = dd.LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address="127.0.0.1:0", silence_logs=WORKER_LOG_LEVEL)
    with contextlib.closing(cluster), contextlib.closing(dd.Client(cluster)) as client:
        warm_up_workers(client, "the local cluster")
        yield client


def _connect(dd: Any, scheduler: str) -> Any:
    """A ``Client`` of the scheduler at ``scheduler``, or one CreepOnlineError within ``CONNECT_TIMEOUT_S`` (+5 s).

    Whatever answers there decides how the connection fails: nothing listening
    (Dask's own timeout), a service that is not Dask (an HTTP server made
    Dask's reader allocate exabytes, an echo server failed its assertions) or
    a port that accepts and stays silent (Dask's handshake waited without
    end). The client is built in a helper thread and waited for at most the
    timeout; every failure is the same one line.
    """
    result: dict[str, Any] = {}

    def attempt() -> None:
        try:
            result["client"] = dd.Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except BaseException as exc:  # noqa: BLE001 - reported below, on the caller's thread
            result["error"] = exc

    helper = threading.Thread(target=attempt, name="dask-connect", daemon=True)
    helper.start()
    helper.join(CONNECT_TIMEOUT_S + 5.0)
    if "client" in result:
        return result["client"]
    if "error" not in result:
        raise CreepOnlineError(f"no Dask scheduler answered at {scheduler} within {CONNECT_TIMEOUT_S + 5:g} s "
                               f"(is it a Dask scheduler's address, tcp://HOST:8786?)")
    exc = result["error"]
    if isinstance(exc, (OSError, TimeoutError)):
        raise CreepOnlineError(f"cannot reach the Dask scheduler at {scheduler}: {one_line(exc)}")
    raise CreepOnlineError(f"{scheduler} did not answer as a Dask scheduler ({type(exc).__name__}: "
                           f"{one_line(exc)[:120]})")


@contextlib.contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Ignore SIGINT while the worker processes start, so that they inherit "ignore".

    Ctrl-C on a terminal signals the whole foreground process group: without
    this every worker printed its own KeyboardInterrupt traceback. Python keeps
    an inherited "ignore" (it installs its KeyboardInterrupt handler only over
    the default), so the workers stay quiet and the batch process alone
    handles Ctrl-C: it cancels the queued records and shuts the cluster down.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def warm_up_workers(client: Any, where: str) -> dict[str, float]:
    """Run ``warm_up`` on every worker (imports, numba loads): {worker: seconds}.

    A worker that cannot import creep_online fails here, once, with a one-line
    error, rather than on every record.
    """
    from .job import warm_up
    try:
        return client.run(warm_up)
    except Exception as exc:  # noqa: BLE001 - whatever the remote side raised, say it on one line
        raise CreepOnlineError(f"the workers of {where} cannot run creep_online: {type(exc).__name__}: "
                               f"{one_line(exc)}") from None


def run_on_dask(jobs: Iterable[RecordJob], client: Any, *, diagnose_it: bool = False,
                identify_options: dict[str, Any] | None = None,
                stop: Callable[[], bool] | None = None, task: Callable[..., dict] | None = None,
                send_records: bool = False) -> Iterator[dict[str, Any]]:
    """Yield one row per job, in the order they finish (``run_record`` on the cluster's workers).

    ``send_records``: read each file record here, as it is submitted, and send its samples with its task
    (``RecordJob.carrying_samples``), for workers that cannot see the files; otherwise they read them by path.

    A record that was bad before any work (``job.error``) gets its row here at
    once. A task the cluster itself could not run (a worker died, creep_online
    missing on a remote worker) gets a row with that error. Closing the
    generator (e.g. on Ctrl-C) cancels what is still queued. ``stop`` is asked
    every ``STOP_POLL_S`` while records run; once it says True no more rows
    come and what is queued is cancelled (the batch command's Ctrl-C: a flag
    its SIGINT handler sets, so that no KeyboardInterrupt lands inside Dask's
    client code, which then printed a callback's traceback on the way out).

    One bad record never fails its neighbours: when a worker dies (a record
    too large for its memory), Dask fails every task that was on it with
    ``KilledWorker``, the healthy ones queued behind the culprit too. Those
    records are run again at the end, one at a time, so only the record that
    kills a worker on its own gets the error row. ``task`` replaces
    ``run_record`` (tests: a task that kills its worker).
    """
    from .job import run_record
    dd = distributed()
    task = task or run_record
    options = {"diagnose_it": diagnose_it, "identify_options": identify_options}
    pending = []
    for job in jobs:
        if job.error is not None:
            yield run_record(job, **options)
        else:
            pending.append(job)
    suspects: list[RecordJob] = []
    yield from _run_window(dd, client, task, pending, options, stop, suspects, send_records)
    for job in suspects:                   # alone now: a worker that dies is this record's doing
        if stop is not None and stop():
            return
        yield from _run_window(dd, client, task, [job], options, stop, None, send_records)


def _run_window(dd: Any, client: Any, task: Callable[..., dict], pending: list[RecordJob], options: dict,
                stop: Callable[[], bool] | None, suspects: list[RecordJob] | None,
                send_records: bool = False) -> Iterator[dict[str, Any]]:
    """The rows of ``pending`` run in a bounded window; with ``suspects`` a list, the records whose worker died
    go there instead of getting an error row. ``send_records``: each job carries its samples when submitted."""
    queue = iter(pending)
    in_flight: dict[str, tuple[Any, RecordJob]] = {}
    done = dd.as_completed()

    def submit(n: int) -> None:
        for job in islice(queue, n):
            if send_records:
                job = job.carrying_samples()
            future = client.submit(task, job, pure=False, **options)
            in_flight[future.key] = (future, job)
            done.add(future)

    threads = sum(client.nthreads().values()) or 1
    submit(WINDOW_PER_THREAD * threads)
    try:
        for future in _finished(done, stop):
            submit(1)
            job = in_flight.pop(future.key)[1]
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - the cluster failed this one record; go on
                if suspects is not None and type(exc).__name__ == "KilledWorker":
                    suspects.append(job)   # perhaps only queued behind the record that killed the worker
                    future.release()
                    continue
                row = empty_row(job)
                why = " (its worker died running it alone: too large for a worker's memory?)" \
                    if type(exc).__name__ == "KilledWorker" else ""
                row["error"] = f"the cluster could not run it: {type(exc).__name__}: {one_line(exc)}{why}"
            future.release()
            yield row
    finally:
        done.clear()
        if in_flight:
            client.cancel([future for future, _ in in_flight.values()])


def _finished(done: Any, stop: Callable[[], bool] | None) -> Iterator[Any]:
    """The futures of ``done`` (an ``as_completed``) as they finish, until it is empty or ``stop()`` is True."""
    if stop is None:
        yield from done
        return
    while not done.is_empty() and not stop():
        if done.has_ready():
            yield from done.next_batch(block=False)
        else:
            time.sleep(STOP_POLL_S)
