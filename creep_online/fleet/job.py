"""One record of a fleet into one table row: identify it (and, if asked, diagnose it).

``run_record`` never raises for a bad record: the row's ``error`` says what
went wrong in one line (the message ``creep-online identify`` would print), so
one bad file never stops a batch. It runs on Dask workers, so it takes and
returns plain picklable values.
"""
from __future__ import annotations

import time
import warnings
from typing import Any

from ..diagnostics import diagnose
from ..errors import CreepOnlineError, CreepOnlineWarning, one_line
from ..identification import identify
from ..io.fleet_records import RecordJob
from .row import PARAMETERS, WARNING_SEPARATOR, empty_row


def run_record(job: RecordJob, *, diagnose_it: bool = False,
               identify_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """The row of one record: parameters, uncertainties, fit, warnings, verdict, or the error.

    ``identify_options`` go to ``identify`` as they are (e.g. ``{"polish": False}``).
    ``seconds`` and ``cpu_seconds`` are the wall and thread CPU time of reading
    and identifying (and diagnosing) this record on its worker.
    """
    wall0, cpu0 = time.perf_counter(), time.thread_time()
    row = empty_row(job)
    notes: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CreepOnlineWarning)
            _fill(row, job, diagnose_it, identify_options or {}, notes)
        notes[:0] = [*job.notes, *(str(w.message) for w in caught if issubclass(w.category, CreepOnlineWarning))]
    except CreepOnlineError as exc:
        row["error"] = one_line(exc)
    except Exception as exc:  # noqa: BLE001 - a bug of ours must not stop the other records either
        row["error"] = f"internal error: {type(exc).__name__}: {one_line(exc)}"
    row["warnings"] = WARNING_SEPARATOR.join(dict.fromkeys(notes))
    row["seconds"] = time.perf_counter() - wall0
    row["cpu_seconds"] = time.thread_time() - cpu0
    return row


def _fill(row: dict[str, Any], job: RecordJob, diagnose_it: bool, options: dict[str, Any],
          notes: list[str]) -> None:
    rec = job.load()
    res = identify(rec.t, rec.u, rec.y, source=rec.source, **options)
    m = res.model
    values = dict(alpha=m.alpha, a1=m.a1, a2=m.a2, b=m.b, fn_hz=m.fn, zeta=m.zeta,
                  fit_percent=res.fit_percent, noise_std=res.noise_std,
                  **{f"{name}_sd": res.uncertainty.get(name) for name in PARAMETERS})
    row.update({k: None if v is None else float(v) for k, v in values.items()}, samples=len(rec))
    notes.extend(res.warnings)
    if diagnose_it:
        # one thread: the batch already runs one worker process per core (and times this thread's CPU)
        row["verdict"] = diagnose(rec, workers=1).verdict


def warm_up() -> float:
    """Identify a small simulated record, so that a worker's imports and numba loads are done before
    the first real record (whose time would otherwise include them); the seconds it took."""
    import numpy as np

    from ..model import CreepModel
    from ..simulate import simulate
    wall0 = time.perf_counter()
    t = np.arange(2000) / 1000.0
    u = np.where(t >= 0.1, 1.0, 0.0)
    y = simulate(CreepModel.from_resonance(0.05, 40.0, 0.1, 1.0), t, u)
    y = y + np.random.default_rng(0).normal(0.0, 1e-3, t.size)
    identify(t, u, y, source="<warm-up>")
    return time.perf_counter() - wall0
