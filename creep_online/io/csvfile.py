"""CSV files with header ``t,u,y`` (other columns ignored; the rules: docs/reliability.md).

``load_record`` is the one entry point of the file commands: it also takes PI
GCS data-recorder files (recognised by their ``#`` header, read by
``creep_online.io.gcsfile``) and lets the input and output columns be chosen
by name in both kinds of file.

Every problem becomes a DataError whose one-line message names the file, the
row and what is wrong; nothing is silently dropped or repaired.
"""
from __future__ import annotations

import csv
import io
import math
import warnings
from pathlib import Path

import numpy as np

from ..errors import DataError, DataWarning
from ..record import MIN_SAMPLES, Record
from .input_files import check_kind, read_input


#: Longest line accepted (bytes): a t,u,y row is ~60; a file of one endless line is not a CSV.
MAX_LINE_BYTES = 65536


def _check_kind(path: Path) -> None:
    """DataError unless ``path`` is a regular file, a pipe or a FIFO (``-``: standard input)."""
    check_kind(path, "CSV file")


def _read_text(path: Path) -> str:
    """The file's text, read once whatever it is (``input_files.read_input``: bounded, pipes never waited on
    forever, a pipe's content remembered for a second look)."""
    data = read_input(path, what="CSV file", max_line=MAX_LINE_BYTES)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text file (undecodable byte at offset {exc.start})") from None


def _header(path: Path, line: str, required: tuple[str, ...]) -> list[int]:
    names = [c.strip().lower() for c in next(csv.reader([line]))]
    missing = [c for c in required if c not in names]
    if missing:
        shown = ",".join(names)[:80]
        raise DataError(f"{path}: missing column(s) {','.join(missing)} in header '{shown}' (need {','.join(required)})")
    for c in required:
        if names.count(c) > 1:
            where = [i + 1 for i, n in enumerate(names) if n == c]
            raise DataError(f"{path}: column {c} appears {len(where)} times in the header "
                            f"(columns {', '.join(map(str, where))}); which one is meant is ambiguous")
    return [names.index(c) for c in required]


def read_columns(path: str | Path, required: tuple[str, ...] = ("t", "u", "y")) -> dict[str, np.ndarray]:
    """The named columns of a CSV file as float arrays; DataError on any malformed cell."""
    path = Path(path)
    text = _read_text(path)
    lines = text.splitlines()
    if lines and max(map(len, lines)) > MAX_LINE_BYTES:
        lineno = next(i for i, ln in enumerate(lines, 1) if len(ln) > MAX_LINE_BYTES)
        raise DataError(f"{path}: line {lineno} is longer than {MAX_LINE_BYTES} characters: not a t,u,y CSV file")
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise DataError(f"{path}: empty file (expected a header {','.join(required)})")
    cols = _header(path, lines[first], required)
    _check_last_line(path, text, lines[first + 1:], cols, first + 1)
    fast = _fast_parse(lines[first + 1:], cols)
    if fast is not None:
        return {name: fast[:, k].copy() for k, name in enumerate(required)}
    width = max(cols) + 1
    out = np.empty((len(lines) - first - 1, len(cols)))
    n = 0
    for lineno, row in enumerate(csv.reader(io.StringIO("\n".join(lines[first + 1:]))), start=first + 2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) < width:
            raise DataError(f"{path}: line {lineno} has {len(row)} field(s), expected at least {width}")
        for k, c in enumerate(cols):
            cell = row[c].strip()
            try:
                value = float(cell)
            except ValueError:
                raise DataError(f"{path}: line {lineno}, column {required[k]}: not a number: {cell[:30]!r}") from None
            if not math.isfinite(value):
                raise DataError(f"{path}: line {lineno}, column {required[k]}: {cell!r} (NaN/inf not allowed)")
            out[n, k] = value
        n += 1
    return {name: out[:n, k].copy() for k, name in enumerate(required)}


def _check_last_line(path: Path, text: str, body: list[str], cols: list[int], offset: int) -> None:
    """A last line without end-of-line was perhaps cut (file copied or still being written): say so.

    Cut mid-row (too few fields, or a cell that is not a number): DataError.
    Complete-looking: a DataWarning, since its last number may still be cut short.
    """
    if not body or text.endswith(("\n", "\r")) or not body[-1].strip():
        return
    lineno = offset + len(body)
    cells = next(csv.reader([body[-1]]), [])
    try:
        ok = len(cells) > max(cols) and all(math.isfinite(float(cells[c])) for c in cols)
    except ValueError:
        ok = False
    if not ok:
        raise DataError(f"{path}: last line {lineno} is incomplete (no end-of-line and cut mid-row: "
                        f"file truncated or still being written?)")
    warnings.warn(f"{path}: last line {lineno} has no end-of-line; if the file was cut or is still being "
                  f"written, its last number may be incomplete", DataWarning, stacklevel=3)


def _fast_parse(body: list[str], cols: list[int]) -> np.ndarray | None:
    """numpy's parser for the clean common case; None sends the file to the careful path."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": reported by the careful path
            arr = np.loadtxt(io.StringIO("\n".join(body)), delimiter=",", usecols=cols, ndmin=2, dtype=float)
    except (ValueError, IndexError):
        return None
    if arr.shape[0] == 0 or not np.all(np.isfinite(arr)):
        return None
    return arr


def load_csv(path: str | Path, min_samples: int = MIN_SAMPLES, need_output: bool = True) -> Record:
    """Load and validate a ``t,u,y`` record; raise DataError with a one-line reason."""
    required = ("t", "u", "y") if need_output else ("t", "u")
    cols = read_columns(path, required)
    y = cols.get("y", np.zeros_like(cols["t"]))
    rec = Record(cols["t"], cols["u"], y, source=str(path))
    return rec.validate(min_samples)


def load_record(path: str | Path, u_column: str | None = None, y_column: str | None = None,
                min_samples: int = MIN_SAMPLES) -> Record:
    """A ``t,u,y`` CSV or a GCS data-recorder file (told apart by content), input/output columns by name.

    CSV: ``u_column``/``y_column`` name header columns (default ``u``, ``y``;
    time is always ``t``). GCS: they name NAMEi columns (default NAME0, NAME1).
    """
    from .gcsfile import is_gcs_file, load_gcs
    if is_gcs_file(path):
        return load_gcs(path, u_column, y_column, min_samples)
    if u_column is None and y_column is None:
        return load_csv(path, min_samples)
    names = ("t", (u_column or "u").strip().lower(), (y_column or "y").strip().lower())
    if len(set(names)) < 3:
        raise DataError(f"{path}: time, input and output must be three different columns (got {','.join(names)})")
    cols = read_columns(path, names)
    rec = Record(cols["t"], cols[names[1]], cols[names[2]], source=str(path))
    return rec.validate(min_samples)


def save_csv(path: str | Path, t: np.ndarray, u: np.ndarray, y: np.ndarray) -> None:
    """Write ``t,u,y`` with full double precision (repr round-trips), atomically (temp file + rename)."""
    from .safe_files import atomic_write
    arr = np.column_stack([t, u, y])
    with atomic_write(path) as fh:
        np.savetxt(fh, arr, delimiter=",", header="t,u,y", comments="", fmt="%.17g")
