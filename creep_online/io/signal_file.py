"""Sampled signals written to a file whose suffix says its format (``simulate -o``).

``.csv`` (or no suffix) comma-separated ``t,u,y``, ``.tsv``/``.tab`` tab-separated,
``.parquet`` a Parquet table (pyarrow, the ``fleet`` extra). Any other suffix is
refused before the work: a name promises a format, and writing CSV text into
``x.parquet`` or ``x.xlsx`` would hand the next program a file it cannot read.
Every file is written atomically (``safe_files.atomic_write``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import CreepOnlineError, OutputError
from .safe_files import atomic_write, check_output

#: Suffix -> format ("" = no suffix: CSV, as before suffixes were read).
FORMATS = {"": "csv", ".csv": "csv", ".txt": "csv", ".tsv": "tsv", ".tab": "tsv", ".parquet": "parquet"}


def check_signal_output(path: str | Path, inputs=()) -> Path:
    """The output path, or a one-line error: unknown suffix, no pyarrow for .parquet, unwritable, an input."""
    out = check_output(path, inputs)
    kind = FORMATS.get(out.suffix.lower())
    if kind is None:
        known = ", ".join(s for s in FORMATS if s)
        raise OutputError(f"{out}: unknown output format {out.suffix!r}; use one of {known}")
    if kind == "parquet":
        _pyarrow()
    return out


def save_signals(path: str | Path, columns: dict[str, np.ndarray]) -> Path:
    """Write equal-length columns (in order, e.g. t, u, y) in the format the suffix names; the path written."""
    out = check_signal_output(path)
    kind = FORMATS[out.suffix.lower()]
    names = list(columns)
    if kind == "parquet":
        pa = _pyarrow()
        table = pa.table({k: np.asarray(v, dtype=float) for k, v in columns.items()})
        with atomic_write(out, mode="wb") as fh:
            pa.parquet.write_table(table, fh)
        return out
    sep = "," if kind == "csv" else "\t"
    arr = np.column_stack([np.asarray(columns[k], dtype=float) for k in names])
    with atomic_write(out) as fh:
        np.savetxt(fh, arr, delimiter=sep, header=sep.join(names), comments="", fmt="%.17g")
    return out


def _pyarrow():
    try:
        import pyarrow
        import pyarrow.parquet  # noqa: F401 - the writer
    except ImportError:
        raise CreepOnlineError("a .parquet output needs pyarrow (pip install 'creep_online[fleet]'), "
                               "or write .csv") from None
    return pyarrow
