"""A fleet table's row: its columns (the table's schema, docs/fleet.md) and an empty one.

Light on purpose (no numerics): the table writer, the summary and the
runner's error rows use it without loading the identification.
"""
from __future__ import annotations

from typing import Any

from ..io.fleet_records import RecordJob

PARAMETERS = ("alpha", "a1", "a2", "b")
#: The table's columns, in order (docs/fleet.md). Numbers are None where a record failed.
COLUMNS = ("id", "source", "samples", "alpha", "a1", "a2", "b", "fn_hz", "zeta",
           "alpha_sd", "a1_sd", "a2_sd", "b_sd", "fit_percent", "noise_std", "warnings",
           "verdict", "outlier", "error", "seconds", "cpu_seconds")
#: The unit of each column (the table's metadata): u and y are in the records' own units, t in seconds.
UNITS = {"id": "", "source": "", "samples": "count", "alpha": "1", "a1": "s", "a2": "s^2",
         "b": "y-unit / (u-unit s^alpha)", "fn_hz": "Hz", "zeta": "1", "alpha_sd": "1", "a1_sd": "s",
         "a2_sd": "s^2", "b_sd": "y-unit / (u-unit s^alpha)", "fit_percent": "%", "noise_std": "y-unit",
         "warnings": "", "verdict": "", "outlier": "", "error": "", "seconds": "s", "cpu_seconds": "s"}
#: Joins a record's warnings in its one table cell.
WARNING_SEPARATOR = " | "


def empty_row(job: RecordJob) -> dict[str, Any]:
    """A row with the record's id and source and every result empty."""
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(id=job.id, source=job.source, warnings="", verdict="", outlier="", error="")
    return row
