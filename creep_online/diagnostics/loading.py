"""Read a record for diagnosis: ``load_record`` (CSV or PI GCS file) plus two documented readings of creep-test logs.

* Repeated time stamps (a logger rounding early times, e.g. to 1 ms) are
  merged into one sample at their mean output (counted in the notes).
* A record whose input is constant and non-zero from its first sample, with
  t[0] > 0, is read as a step from 0 applied at t = 0 before logging began
  (``u_pre = 0``, ``t_pre = 0``): the usual creep-test log.

Every other problem is the ``DataError`` of ``creep_online.io.csvfile.load_record``.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError, DataWarning
from ..io.csvfile import in_seconds, load_record, read_table
from ..io.gcsfile import is_gcs_file
from ..record import MIN_SAMPLES, Record


@dataclass
class DiagnosisInput:
    """A validated record plus how the input before the record is to be read."""

    record: Record
    u_pre: float | None = None
    t_pre: float | None = None
    notes: list[str] = field(default_factory=list)


def merge_repeated_times(t: np.ndarray, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Merge runs of equal time stamps (mean y; u must agree); (t, u, y, samples merged)."""
    keep = np.concatenate(([True], np.diff(t) != 0))
    if keep.all():
        return t, u, y, 0
    groups = np.cumsum(keep) - 1
    count = np.bincount(groups)
    y_m = np.bincount(groups, weights=y) / count
    u_first = u[keep]
    if np.any(np.abs(np.bincount(groups, weights=u) / count - u_first) > 1e-12 * max(1.0, np.max(np.abs(u)))):
        raise DataError("repeated time stamps with different inputs")
    return t[keep], u_first, y_m, int(t.size - keep.sum())


def load_for_diagnosis(path: str | Path, u_column: str | None = None, y_column: str | None = None,
                       t_column: str | None = None, dt: float | None = None) -> DiagnosisInput:
    """Load a record for diagnosis (see the module notes); DataError naming file and problem otherwise.

    ``t_column``/``u_column``/``y_column`` choose the columns by name (``load_record``).
    A GCS file's time comes from its sample time (or ``dt``), so only the CSV readings apply to CSV files.
    """
    try:
        return DiagnosisInput(load_record(path, u_column, y_column, t_column=t_column, dt=dt))
    except DataError as first:
        if is_gcs_file(path) or dt is not None:
            raise
        names = tuple(c.strip().lower() for c in (t_column or "t", u_column or "u", y_column or "y"))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)   # already said by load_record
            cols, units = read_table(path, names)  # raises the file-level errors itself
        t, units[names[0]] = in_seconds(path, cols[names[0]], units[names[0]])
        u, y = cols[names[1]], cols[names[2]]
        notes = []
        if t.size >= 2 and np.all(np.diff(t) >= 0) and np.any(np.diff(t) == 0):
            try:
                t, u, y, merged = merge_repeated_times(t, u, y)
            except DataError as exc:
                raise DataError(f"{path}: {exc}") from None
            notes.append(f"{merged} sample(s) with repeated time stamps merged (mean output)")
        found = {"t": units[names[0]], "u": units[names[1]], "y": units[names[2]]}
        rec = Record(t, u, y, source=str(path), units={k: v for k, v in found.items() if v})
        u_pre = t_pre = None
        if t.size and np.ptp(u) == 0.0 and u[0] != 0.0 and t[0] > 0.0:
            u_pre, t_pre = 0.0, 0.0
            notes.append(f"constant input {u[0]:g} from t = {t[0]:g} s read as a step from 0 at t = 0")
            rec.u = rec.u.copy()
            rec_check = Record(np.concatenate(([0.0], t)), np.concatenate(([0.0], u)),
                               np.concatenate(([0.0], y)), str(path))
            rec_check.validate(MIN_SAMPLES)
        elif notes:
            rec.validate(MIN_SAMPLES)
        else:
            raise first
        return DiagnosisInput(rec, u_pre, t_pre, notes)
