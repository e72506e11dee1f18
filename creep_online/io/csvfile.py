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
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import DataError, DataWarning
from ..record import MIN_SAMPLES, Record
from .input_files import check_kind, read_text


#: Longest line accepted (bytes): a t,u,y row is ~60; a file of one endless line is not a CSV.
MAX_LINE_BYTES = 65536


def _check_kind(path: Path) -> None:
    """DataError unless ``path`` is a regular file, a pipe or a FIFO (``-``: standard input)."""
    check_kind(path, "CSV file")


def _read_text(path: Path) -> str:
    """The CSV file's text (``input_files.read_text``)."""
    return read_text(path, what="CSV file", max_line=MAX_LINE_BYTES)


#: Delimiters a header is sniffed for (the most frequent one in the header line wins; comma on a tie).
DELIMITERS = (",", ";", "\t")
#: Other names of the three columns (case-insensitive; a unit may follow, ``t [s]``, ``t (s)``, ``t / s``).
ALIASES = {"time": "t", "input": "u", "output": "y"}
#: Time units the time column may name, as factors to seconds (it is converted to seconds on reading).
TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "\u00b5s": 1e-6, "\u03bcs": 1e-6, "ns": 1e-9}
_UNIT = re.compile(r"^(?P<name>.*?)\s*(?:\[(?P<b>[^\]]*)\]|\((?P<p>[^)]*)\)|/\s*(?P<s>[^/\s]+))$")
#: What a missing-column message suggests.
NAMING_HINT = ("name the columns t/time, u/input, y/output (units allowed, e.g. 't [s]'), "
               "or choose them with --t-column/--u-column/--y-column")


def sniff_delimiter(line: str) -> str:
    """The header's delimiter: the most frequent of ``DELIMITERS`` (comma when none or a tie)."""
    counts = [line.count(d) for d in DELIMITERS]
    best = max(range(len(DELIMITERS)), key=lambda k: (counts[k], -k))
    return DELIMITERS[best] if counts[best] > 0 else ","


def split_name(cell: str) -> tuple[str, str]:
    """(name, unit) of a header cell: ``'t [ms]'`` -> ('t', 'ms'); no unit -> (name, ''); lower-case name."""
    cell = cell.strip()
    m = _UNIT.match(cell)
    if m and m.group("name"):
        unit = next(g for g in (m.group("b"), m.group("p"), m.group("s")) if g is not None)
        return m.group("name").strip().lower(), unit.strip()
    return cell.lower(), ""


def _matches(cell: str, wanted: str) -> bool:
    """Whether header cell ``cell`` names column ``wanted`` (its full text, its name, or the name's alias)."""
    name, _ = split_name(cell)
    return cell.strip().lower() == wanted or name == wanted or ALIASES.get(name) == wanted


def _header(path: Path, line: str, required: tuple[str, ...], delimiter: str = ",") -> list[int]:
    """Indices of the ``required`` columns in the header ``line``; DataError naming what is missing or doubled."""
    return _header_units(path, line, required, delimiter)[0]


def _header_units(path: Path, line: str, required: tuple[str, ...],
                  delimiter: str = ",") -> tuple[list[int], dict[str, str]]:
    """(indices, units by required name) of the required columns in the header ``line``."""
    cells = next(csv.reader([line], delimiter=delimiter))
    found = {c: [i for i, cell in enumerate(cells) if _matches(cell, c)] for c in required}
    missing = [c for c in required if not found[c]]
    if missing:
        shown = delimiter.join(c.strip() for c in cells)[:80]
        other = [d for d in DELIMITERS if d != delimiter and d in line]
        hint = f"the header is {_delimiter_name(delimiter)}-separated" + (
            f" and also holds {_delimiter_name(other[0])}s" if other else "")
        raise DataError(f"{path}: missing column(s) {','.join(missing)} in header '{shown}' (need "
                        f"{','.join(required)}); {hint}: {NAMING_HINT}")
    for c in required:
        if len(found[c]) > 1:
            where = [i + 1 for i in found[c]]
            raise DataError(f"{path}: column {c} appears {len(where)} times in the header "
                            f"(columns {', '.join(map(str, where))}); which one is meant is ambiguous")
    idx = [found[c][0] for c in required]
    return idx, {c: split_name(cells[i])[1] for c, i in zip(required, idx)}


def _delimiter_name(d: str) -> str:
    return {",": "comma", ";": "semicolon", "\t": "tab"}[d]


def _number(cell: str, delimiter: str) -> float:
    """A cell as a float; with a semicolon or tab delimiter a decimal comma is accepted too."""
    try:
        return float(cell)
    except ValueError:
        if delimiter != "," and cell.count(",") == 1 and "." not in cell:
            return float(cell.replace(",", "."))
        raise


def read_columns(path: str | Path, required: tuple[str, ...] = ("t", "u", "y")) -> dict[str, np.ndarray]:
    """The named columns of a CSV file as float arrays; DataError on any malformed cell."""
    return read_table(path, required)[0]


def read_table(path: str | Path, required: tuple[str, ...] = ("t", "u", "y")) -> tuple[dict[str, np.ndarray],
                                                                                       dict[str, str]]:
    """(columns, units): the named columns as float arrays and the unit each header cell names ('' if none).

    The delimiter is sniffed from the header (comma, semicolon or tab); columns match by name, alias
    or ``name [unit]`` (``_matches``). DataError on any malformed cell.
    """
    path = Path(path)
    text = _read_text(path)
    lines = text.splitlines()
    if lines and max(map(len, lines)) > MAX_LINE_BYTES:
        lineno = next(i for i, ln in enumerate(lines, 1) if len(ln) > MAX_LINE_BYTES)
        raise DataError(f"{path}: line {lineno} is longer than {MAX_LINE_BYTES} characters: not a t,u,y CSV file")
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise DataError(f"{path}: empty file (expected a header {','.join(required)})")
    delimiter = sniff_delimiter(lines[first])
    cols, units = _header_units(path, lines[first], required, delimiter)
    _check_last_line(path, text, lines[first + 1:], cols, first + 1, delimiter)
    fast = _fast_parse(lines[first + 1:], cols, delimiter)
    if fast is not None:
        return {name: fast[:, k].copy() for k, name in enumerate(required)}, units
    width = max(cols) + 1
    out = np.empty((len(lines) - first - 1, len(cols)))
    n = 0
    rows = csv.reader(io.StringIO("\n".join(lines[first + 1:])), delimiter=delimiter)
    for lineno, row in enumerate(rows, start=first + 2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) < width:
            raise DataError(f"{path}: line {lineno} has {len(row)} field(s), expected at least {width}")
        for k, c in enumerate(cols):
            cell = row[c].strip()
            try:
                value = _number(cell, delimiter)
            except ValueError:
                raise DataError(f"{path}: line {lineno}, column {required[k]}: not a number: {cell[:30]!r}") from None
            if not math.isfinite(value):
                raise DataError(f"{path}: line {lineno}, column {required[k]}: {cell!r} (NaN/inf not allowed)")
            out[n, k] = value
        n += 1
    return {name: out[:n, k].copy() for k, name in enumerate(required)}, units


def _check_last_line(path: Path, text: str, body: list[str], cols: list[int], offset: int,
                     delimiter: str = ",") -> None:
    """A last line without end-of-line was perhaps cut (file copied or still being written): say so.

    Cut mid-row (too few fields, or a cell that is not a number): DataError.
    Complete-looking: a DataWarning, since its last number may still be cut short.
    """
    if not body or text.endswith(("\n", "\r")) or not body[-1].strip():
        return
    lineno = offset + len(body)
    cells = next(csv.reader([body[-1]], delimiter=delimiter), [])
    try:
        ok = len(cells) > max(cols) and all(math.isfinite(_number(cells[c].strip(), delimiter)) for c in cols)
    except ValueError:
        ok = False
    if not ok:
        raise DataError(f"{path}: last line {lineno} is incomplete (no end-of-line and cut mid-row: "
                        f"file truncated or still being written?)")
    warnings.warn(f"{path}: last line {lineno} has no end-of-line; if the file was cut or is still being "
                  f"written, its last number may be incomplete", DataWarning, stacklevel=3)


def _fast_parse(body: list[str], cols: list[int], delimiter: str = ",") -> np.ndarray | None:
    """numpy's parser for the clean common case; None sends the file to the careful path."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": reported by the careful path
            arr = np.loadtxt(io.StringIO("\n".join(body)), delimiter=delimiter, usecols=cols, ndmin=2, dtype=float)
    except (ValueError, IndexError):
        return None
    if arr.shape[0] == 0 or not np.all(np.isfinite(arr)):
        return None
    return arr


def load_csv(path: str | Path, min_samples: int = MIN_SAMPLES, need_output: bool = True) -> Record:
    """Load and validate a ``t,u,y`` record; raise DataError with a one-line reason."""
    required = ("t", "u", "y") if need_output else ("t", "u")
    cols, units = read_table(path, required)
    t, units["t"] = in_seconds(path, cols["t"], units["t"])
    y = cols.get("y", np.zeros_like(cols["t"]))
    rec = Record(t, cols["u"], y, source=str(path), units={k: v for k, v in units.items() if v})
    return rec.validate(min_samples)


def in_seconds(path, t: np.ndarray, unit: str) -> tuple[np.ndarray, str]:
    """(time in seconds, its unit): a time column whose header names ms, us or ns is converted; no unit: as is."""
    if not unit:
        return t, ""
    factor = TIME_UNITS.get(unit) or TIME_UNITS.get(unit.lower())
    if factor is None:
        raise DataError(f"{path}: time unit {unit!r} in the header is not one of {', '.join(TIME_UNITS)}")
    return (t * factor if factor != 1.0 else t), "s"


def load_record(path: str | Path, u_column: str | None = None, y_column: str | None = None,
                min_samples: int = MIN_SAMPLES, t_column: str | None = None, dt: float | None = None) -> Record:
    """A ``t,u,y`` CSV or a GCS data-recorder file (told apart by content), columns chosen by name.

    CSV: ``t_column``/``u_column``/``y_column`` name header columns (default ``t``, ``u``, ``y``, or
    their aliases ``time``, ``input``, ``output``; a unit may follow the name). A time column in
    ms/us/ns (named in its header) is converted to seconds. GCS: ``u_column``/``y_column`` name NAMEi
    columns (by meaning when there are more than two: ``gcsfile.columns_by_meaning``); its time comes
    from the sample time, or ``dt`` for a file without one. ``dt`` given for a CSV must agree with its
    time column. The record's ``units`` holds the units the header named.
    """
    from .gcsfile import is_gcs_file, load_gcs
    if is_gcs_file(path):
        if t_column is not None:
            raise DataError(f"{path}: a PI GCS data-recorder file has no time column to choose "
                            "(its time comes from the sample time): drop --t-column")
        return load_gcs(path, u_column, y_column, min_samples, dt=dt)
    rec = _load_csv_columns(path, u_column, y_column, min_samples, t_column)
    if dt is not None and not (rec.is_uniform and math.isclose(dt, rec.h, rel_tol=1e-6)):
        raise DataError(f"--dt {dt:g} contradicts the time column of {rec.source} (step {rec.h:.6g} s); "
                        f"drop --dt or fix the file")
    return rec


def _load_csv_columns(path: str | Path, u_column: str | None, y_column: str | None, min_samples: int,
                      t_column: str | None) -> Record:
    if u_column is None and y_column is None and t_column is None:
        return load_csv(path, min_samples)
    names = tuple(c.strip().lower() for c in (t_column or "t", u_column or "u", y_column or "y"))
    if len(set(names)) < 3:
        raise DataError(f"{path}: time, input and output must be three different columns (got {','.join(names)})")
    cols, units = read_table(path, names)
    t, t_unit = in_seconds(path, cols[names[0]], units[names[0]])
    found = {"t": t_unit, "u": units[names[1]], "y": units[names[2]]}
    rec = Record(t, cols[names[1]], cols[names[2]], source=str(path), units={k: v for k, v in found.items() if v})
    return rec.validate(min_samples)


def save_csv(path: str | Path, t: np.ndarray, u: np.ndarray, y: np.ndarray) -> None:
    """Write ``t,u,y`` with full double precision (repr round-trips), atomically (temp file + rename)."""
    from .safe_files import atomic_write
    arr = np.column_stack([t, u, y])
    with atomic_write(path) as fh:
        np.savetxt(fh, arr, delimiter=",", header="t,u,y", comments="", fmt="%.17g")
