"""The fleet table on disk: CSV (always available) or Parquet (pyarrow, the ``fleet`` extra).

Both are written atomically (temporary file, then rename), so an interrupted
batch never leaves half a table. A failed record's numbers are empty cells in
CSV and nulls in Parquet.
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from ..errors import CreepOnlineError, OutputError
from ..io.safe_files import atomic_write, check_output
from .row import COLUMNS

FORMATS = (".csv", ".parquet")


def check_table_path(path: str | Path, inputs: tuple[str | Path, ...] = ()) -> Path:
    """The table path, or a one-line error (unknown suffix, unwritable, an input, no pyarrow for .parquet)."""
    out = check_output(path, inputs)
    if out.suffix.lower() not in FORMATS:
        raise OutputError(f"{out}: the table must end in .csv or .parquet")
    if out.suffix.lower() == ".parquet":
        _pyarrow()
    return out


def _pyarrow():
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise CreepOnlineError("a .parquet table needs pyarrow (pip install 'creep_online[fleet]'), "
                               "or write .csv") from None
    return pyarrow


def write_table(rows: list[dict[str, Any]], path: str | Path) -> Path:
    """Write ``rows`` (the ``COLUMNS``) to ``path``; the format follows the suffix."""
    out = check_table_path(path)
    if out.suffix.lower() == ".parquet":
        _write_parquet(rows, out)
    else:
        with atomic_write(out) as fh:
            writer = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
            writer.writeheader()
            for r in rows:
                writer.writerow({k: "" if r.get(k) is None else r[k] for k in COLUMNS})
    return out


def _write_parquet(rows: list[dict[str, Any]], out: Path) -> None:
    pa = _pyarrow()
    strings = {"id", "source", "warnings", "verdict", "outlier", "error"}
    schema = pa.schema([(k, pa.string() if k in strings else pa.int64() if k == "samples" else pa.float64())
                        for k in COLUMNS])
    table = pa.Table.from_pylist([{k: r.get(k) for k in COLUMNS} for r in rows], schema=schema)
    with atomic_write(out, mode="wb") as fh:
        pa.parquet.write_table(table, fh)
