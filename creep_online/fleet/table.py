"""The fleet table on disk: CSV (always available) or Parquet (pyarrow, the ``fleet`` extra).

Both are written atomically (temporary file, then rename), so an interrupted
batch never leaves half a table. A failed record's numbers are empty cells in
CSV and nulls in Parquet. Text cells of the CSV (a record's name, its error)
that a spreadsheet would read as a formula are written as text
(``safe_files.spreadsheet_text``).
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from ..errors import CreepOnlineError, OutputError, printable
from ..io.safe_files import atomic_write, check_output, spreadsheet_text
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
                writer.writerow({k: _cell(r.get(k)) for k in COLUMNS})
    return out


def _cell(value: Any) -> Any:
    """A CSV cell: empty for a missing number; text with control characters escaped (a carriage return in a
    record's name would split its row) and neutralised for spreadsheets (record names, errors)."""
    if value is None:
        return ""
    return spreadsheet_text(printable(value, keep_return=False)) if isinstance(value, str) else value


def _write_parquet(rows: list[dict[str, Any]], out: Path) -> None:
    pa = _pyarrow()
    strings = {"id", "source", "warnings", "verdict", "outlier", "error"}
    schema = pa.schema([(k, pa.string() if k in strings else pa.int64() if k == "samples" else pa.float64())
                        for k in COLUMNS])
    table = pa.Table.from_pylist([{k: r.get(k) for k in COLUMNS} for r in rows], schema=schema)
    with atomic_write(out, mode="wb") as fh:
        pa.parquet.write_table(table, fh)
