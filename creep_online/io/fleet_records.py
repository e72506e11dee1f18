"""The records of a fleet: a folder of CSV files, a glob, or one long-format CSV ``id,t,u,y``.

``find_records(spec)`` turns what the user named into ``RecordJob`` objects,
one per record, without reading the samples of per-file records (the worker
that identifies a record reads it, with ``load_csv`` and its one-line errors).
A long-format file is read once, here: its rows are grouped by ``id`` (in the
order the ids first appear; rows of one id keep their order) and each record
carries its samples. A bad cell spoils only its own record: that job carries
the one-line error (file, line, column, id) and the others go on.
"""
from __future__ import annotations

import csv
import glob
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..record import MIN_SAMPLES, Record
# the CSV module's own file checks and header rule, so a long-format file fails exactly like a t,u,y one
from .csvfile import _header, _read_text, load_csv

#: Columns of a long-format file (any order; other columns are ignored).
LONG_COLUMNS = ("id", "t", "u", "y")
_GLOB_CHARS = set("*?[")


@dataclass(frozen=True)
class RecordJob:
    """One record of a fleet: a ``t,u,y`` file (``path``) or samples from a long-format file (``samples``).

    ``error`` is set when the record is known to be bad before any work (a bad
    cell in a long-format file); ``load`` then raises it.
    """

    id: str
    source: str
    path: str | None = None
    samples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    error: str | None = None

    def load(self) -> Record:
        """The validated record; DataError with the one-line reason otherwise."""
        if self.error is not None:
            raise DataError(self.error)
        if self.path is not None:
            return load_csv(self.path)
        t, u, y = self.samples
        return Record(t, u, y, source=self.source).validate(MIN_SAMPLES)


def find_records(spec: str) -> list[RecordJob]:
    """The records named by ``spec`` (folder, glob or long-format CSV).

    A folder gives its ``*.csv`` files (not recursive); a glob its matching
    files (``**`` recurses); a file with an ``id`` column its records, one per
    id; a plain ``t,u,y`` file one record. DataError when nothing is found.
    """
    path = Path(spec)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() == ".csv" and p.is_file())
        where = f"{spec}: no .csv files in this folder"
    elif _GLOB_CHARS & set(spec) and not path.exists():
        files = sorted(Path(p) for p in glob.glob(spec, recursive=True) if Path(p).is_file())
        where = f"{spec}: no files match this pattern"
    elif path.exists():
        return _jobs_of_file(path)
    else:
        raise DataError(f"{spec}: no such file or folder (give a folder, a glob or a long-format id,t,u,y CSV)")
    if not files:
        raise DataError(where)
    return [RecordJob(name, str(p), path=str(p)) for name, p in zip(_unique_ids(files), files)]


def _unique_ids(files: list[Path]) -> list[str]:
    """The file names without suffix; the paths without suffix where two names collide."""
    stems = [p.stem for p in files]
    return [s if stems.count(s) == 1 else str(p.with_suffix("")) for s, p in zip(stems, files)]


def _jobs_of_file(path: Path) -> list[RecordJob]:
    """One file: long format when its header has an ``id`` column, else a single record."""
    text = _read_text(path)
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise DataError(f"{path}: empty file (expected a header id,t,u,y)")
    names = [c.strip().lower() for c in next(csv.reader([lines[first]]))]
    if "id" not in names:
        return [RecordJob(path.stem, str(path), path=str(path))]
    cols = _header(path, lines[first], LONG_COLUMNS)
    return read_long(path, lines[first + 1:], cols, first + 2)


def read_long(path: Path, body: list[str], cols: list[int], first_lineno: int) -> list[RecordJob]:
    """Group the rows of a long-format body by id; each record's numbers checked on their own."""
    rows: dict[str, list[tuple[int, list[str]]]] = {}
    for lineno, row in enumerate(csv.reader(body), start=first_lineno):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) <= cols[0] or not row[cols[0]].strip():
            raise DataError(f"{path}: line {lineno}: no id (every row of a long-format file needs one)")
        rows.setdefault(row[cols[0]].strip(), []).append((lineno, row))
    if not rows:
        raise DataError(f"{path}: no data rows")
    return [_long_job(path, key, group, cols) for key, group in rows.items()]


def _long_job(path: Path, key: str, group: list[tuple[int, list[str]]], cols: list[int]) -> RecordJob:
    """The job of one id: its samples, or the first bad cell as its error."""
    source = f"{path}[id={key}]"
    width = max(cols) + 1
    out = np.empty((len(group), 3))
    for n, (lineno, row) in enumerate(group):
        if len(row) < width:
            return RecordJob(key, source, error=f"{path}: line {lineno} (id {key}) has {len(row)} field(s), "
                                                f"expected at least {width}")
        for k, c in enumerate(cols[1:]):
            cell = row[c].strip()
            try:
                value = float(cell)
            except ValueError:
                return RecordJob(key, source, error=f"{path}: line {lineno} (id {key}), column "
                                                    f"{LONG_COLUMNS[k + 1]}: not a number: {cell[:30]!r}")
            if not math.isfinite(value):
                return RecordJob(key, source, error=f"{path}: line {lineno} (id {key}), column "
                                                    f"{LONG_COLUMNS[k + 1]}: {cell!r} (NaN/inf not allowed)")
            out[n, k] = value
    return RecordJob(key, source, samples=(out[:, 0].copy(), out[:, 1].copy(), out[:, 2].copy()))
