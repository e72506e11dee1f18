"""The fleet table on disk: CSV (always available) or Parquet (pyarrow, the ``fleet`` extra).

Both are written atomically (temporary file, then rename), so an interrupted
batch never leaves half a table. A failed record's numbers are empty cells in
CSV and nulls in Parquet. Text cells of the CSV (a record's name, its error)
that a spreadsheet would read as a formula are written as text
(``safe_files.spreadsheet_text``).

Each table carries its metadata (``table_metadata``: the tool and its
version, the batch's options, the unit of every column). Parquet keeps it in
the file's key-value metadata (``creep_online.version``, ``creep_online.options``,
``creep_online.units``, JSON text; each column's unit also in its field's
``unit``). A CSV file cannot hold it without tripping readers (a comment line
breaks a header-first reader), so it goes to a sidecar beside the table:
``fleet.csv.meta.json`` (``sidecar_path``), the same keys as one JSON object.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from ..errors import CreepOnlineError, OutputError, printable
from ..io.safe_files import WRITTEN_BY, atomic_write, check_output, spreadsheet_text
from .row import COLUMNS, UNITS

TOOL = "creep-online"
#: Suffix added to a CSV table's name for its metadata sidecar.
SIDECAR_SUFFIX = ".meta.json"

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


def table_metadata(options: dict[str, Any] | None = None) -> dict[str, Any]:
    """The table's metadata: ``tool``, ``version``, ``options`` (as given: the batch's settings), ``units``."""
    from .. import __version__
    return {"tool": TOOL, "version": __version__, "options": dict(options or {}),
            "units": {k: UNITS[k] for k in COLUMNS}}


def sidecar_path(table: str | Path) -> Path:
    """Where a CSV table's metadata goes: ``fleet.csv`` -> ``fleet.csv.meta.json``."""
    table = Path(table)
    return table.with_name(table.name + SIDECAR_SUFFIX)


def write_table(rows: list[dict[str, Any]], path: str | Path, options: dict[str, Any] | None = None) -> Path:
    """Write ``rows`` (the ``COLUMNS``) to ``path`` with its metadata (``options``: the batch's settings);
    the format follows the suffix."""
    out = check_table_path(path)
    meta = table_metadata(options)
    if out.suffix.lower() == ".parquet":
        _write_parquet(rows, out, meta)
        return out
    with atomic_write(out) as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: _cell(r.get(k)) for k in COLUMNS})
    with atomic_write(sidecar_path(out)) as fh:
        json.dump({"written_by": WRITTEN_BY, "table": out.name, **meta}, fh, indent=1, sort_keys=False)
        fh.write("\n")
    return out


def _cell(value: Any) -> Any:
    """A CSV cell: empty for a missing number; text with control characters escaped (a carriage return in a
    record's name would split its row) and neutralised for spreadsheets (record names, errors)."""
    if value is None:
        return ""
    return spreadsheet_text(printable(value, keep_return=False)) if isinstance(value, str) else value


def _write_parquet(rows: list[dict[str, Any]], out: Path, meta: dict[str, Any]) -> None:
    pa = _pyarrow()
    strings = {"id", "source", "warnings", "verdict", "outlier", "error"}
    fields = [pa.field(k, pa.string() if k in strings else pa.int64() if k == "samples" else pa.float64(),
                       metadata={"unit": UNITS[k]} if UNITS[k] else None) for k in COLUMNS]
    file_meta = {f"creep_online.{key}": value if isinstance(value, str) else json.dumps(value)
                 for key, value in meta.items() if key != "tool"}
    schema = pa.schema(fields, metadata={"creep_online.tool": meta["tool"], **file_meta})
    table = pa.Table.from_pylist([{k: r.get(k) for k in COLUMNS} for r in rows], schema=schema)
    with atomic_write(out, mode="wb") as fh:
        pa.parquet.write_table(table, fh)
