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
import io
import math
from array import array
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable

import numpy as np

from ..errors import CreepOnlineWarning, DataError, one_line
from ..record import MIN_SAMPLES, Record
# the CSV module's own file checks and header rule, so a long-format file fails exactly like a t,u,y one
from .csvfile import _check_kind, _header, _read_text, load_csv
from .input_files import is_stream

#: Columns of a long-format file (any order; other columns are ignored).
LONG_COLUMNS = ("id", "t", "u", "y")
_GLOB_CHARS = set("*?[")


@dataclass(frozen=True)
class RecordJob:
    """One record of a fleet: a ``t,u,y`` file (``path``) or samples from a long-format file (``samples``).

    ``path`` is absolute (resolved where the batch runs): the workers of an
    existing cluster run in directories of their own. ``source`` is the name
    as the user gave it (the table's ``source`` column).

    ``error`` is set when the record is known to be bad before any work (a bad
    cell in a long-format file); ``load`` then raises it. ``notes``: warnings
    of reading it where the batch runs (``carrying_samples``), for its row.
    """

    id: str
    source: str
    path: str | None = None
    samples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    error: str | None = None
    notes: tuple[str, ...] = ()

    def carrying_samples(self) -> "RecordJob":
        """This record with its file read here, its samples to travel with its task (``batch --send-records``:
        workers that cannot see the file); an unreadable file gives a job carrying the one-line error."""
        if self.path is None:
            return self
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CreepOnlineWarning)
            try:
                rec = load_csv(self.path)
            except DataError as exc:
                return replace(self, path=None, error=one_line(exc))
        notes = tuple(str(w.message) for w in caught if issubclass(w.category, CreepOnlineWarning))
        return replace(self, path=None, samples=(rec.t, rec.u, rec.y), notes=self.notes + notes)

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
    return [RecordJob(name, str(p), path=str(p.resolve())) for name, p in zip(_unique_ids(files), files)]


def _unique_ids(files: list[Path]) -> list[str]:
    """The file names without suffix; the paths without suffix where two names collide."""
    stems = [p.stem for p in files]
    return [s if stems.count(s) == 1 else str(p.with_suffix("")) for s, p in zip(stems, files)]


def _jobs_of_file(path: Path) -> list[RecordJob]:
    """One file: long format when its header has an ``id`` column, else a single record.

    A long file is parsed as it is read (never all of its text in memory at
    once); a record's samples cost 24 bytes a row.
    """
    _check_kind(path)
    if is_stream(path):   # a pipe or FIFO: read once here, its records carry their samples to the workers
        return _jobs_of_stream(path)
    try:
        with path.open(encoding="utf-8-sig", newline="") as fh:
            lineno, header = 0, ""
            for lineno, header in enumerate(fh, start=1):
                if header.strip():
                    break
            if not header.strip():
                raise DataError(f"{path}: empty file (expected a header id,t,u,y)")
            names = [c.strip().lower() for c in next(csv.reader([header]))]
            if "id" not in names:
                return [RecordJob(path.stem, str(path), path=str(path.resolve()))]
            return read_long(path, fh, _header(path, header, LONG_COLUMNS), lineno + 1)
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a UTF-8 text file (undecodable byte)") from None
    except csv.Error as exc:
        raise DataError(f"{path}: not a CSV file ({exc})") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None


def _jobs_of_stream(path: Path) -> list[RecordJob]:
    """A pipe's records: long format, or one t,u,y record (read here, not by a worker that cannot reopen it)."""
    text = _read_text(path)
    first = next((line for line in text.splitlines() if line.strip()), "")
    names = [c.strip().lower() for c in next(csv.reader([first]), [])]
    if "id" not in names:
        rec = load_csv(path)
        return [RecordJob(path.name, str(path), samples=(rec.t, rec.u, rec.y))]
    body = io.StringIO(text)
    lineno = 0
    for lineno, line in enumerate(body, start=1):
        if line.strip():
            break
    return read_long(path, body, _header(path, first, LONG_COLUMNS), lineno + 1)


def read_long(path: Path, body: Iterable[str], cols: list[int], first_lineno: int) -> list[RecordJob]:
    """Group the rows of a long-format body by id; each record's numbers checked on their own.

    Each id's numbers go straight into a flat array of doubles (24 bytes a
    row), so a long file costs little more memory than its text.
    """
    groups: dict[str, _Group] = {}
    width = max(cols) + 1
    c_id, c_t, c_u, c_y = cols
    for lineno, row in enumerate(csv.reader(body), start=first_lineno):
        if not row or all(not c.strip() for c in row):
            continue
        key = row[c_id].strip() if len(row) > c_id else ""
        if not key:
            raise DataError(f"{path}: line {lineno}: no id (every row of a long-format file needs one)")
        group = groups.get(key)
        if group is None:
            group = groups[key] = _Group()
        if group.error is not None:
            continue
        if len(row) < width:
            group.error = f"{path}: line {lineno} (id {key}) has {len(row)} field(s), expected at least {width}"
            continue
        try:
            t, u, y = float(row[c_t]), float(row[c_u]), float(row[c_y])
        except ValueError:
            group.error = _bad_cell(path, lineno, key, row, cols)
            continue
        if (t - t) or (u - u) or (y - y):   # NaN or inf (x - x is NaN for both, 0 otherwise)
            group.error = _bad_cell(path, lineno, key, row, cols)
            continue
        group.values.extend((t, u, y))
    if not groups:
        raise DataError(f"{path}: no data rows")
    return [group.job(path, key) for key, group in groups.items()]


class _Group:
    """The samples of one id so far (flat t,u,y doubles), or its first error."""

    def __init__(self) -> None:
        self.values = array("d")
        self.error: str | None = None

    def job(self, path: Path, key: str) -> RecordJob:
        source = f"{path}[id={key}]"
        if self.error is not None:
            return RecordJob(key, source, error=self.error)
        tuy = np.frombuffer(self.values, dtype=float).reshape(-1, 3)
        return RecordJob(key, source, samples=(tuy[:, 0].copy(), tuy[:, 1].copy(), tuy[:, 2].copy()))


def _bad_cell(path: Path, lineno: int, key: str, row: list[str], cols: list[int]) -> str:
    """The one-line error of the first cell of ``row`` that is not a finite number."""
    for name, c in zip(LONG_COLUMNS[1:], cols[1:]):
        cell = row[c].strip()
        try:
            value = float(cell)
        except ValueError:
            return f"{path}: line {lineno} (id {key}), column {name}: not a number: {cell[:30]!r}"
        if not math.isfinite(value):
            return f"{path}: line {lineno} (id {key}), column {name}: {cell!r} (NaN/inf not allowed)"
    raise AssertionError("no bad cell in a row that failed")  # pragma: no cover - callers checked
