"""PI GCS data-recorder files (``# KEY = value`` header, ``# END_HEADER``, columns), read with pipython.

A PI controller's data recorder (PIMikroMove, ``pipython.pitools.savegcsarray``,
or a ``qDRR`` answer saved to disk) writes::

    # TYPE = 1
    # SEPARATOR = 32
    # DIM = 2
    # SAMPLE_TIME = 0.0001
    # NDATA = 5000
    # NAME0 = Piezo Voltage of axis 1
    # NAME1 = Actual Position of axis 1
    # END_HEADER
    0.000000 0.000012
    ...

The header is checked here first, so that every problem is one line naming the
file and what is wrong (no ``# END_HEADER``, a column name that does not exist:
the message lists those that do); the data are then read by pipython's own
reader (``pipython.pitools.readgcsarray``). Time is ``k * SAMPLE_TIME``, or
``k * dt`` for a file without it (``pitools.savegcsarray(path, None, data)``
writes none) when the caller gives ``dt``. Input and output are the columns
chosen by name; by default, in a two-column file NAME0 is the input and NAME1
the output (the order the ``pi:`` source records them in), and in a file with
more columns they are chosen by meaning (:func:`columns_by_meaning`).
"""
from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..record import MIN_SAMPLES, Record
from .input_files import is_stream, read_text

__all__ = ["is_gcs_file", "read_gcs_header", "load_gcs", "column_names", "column_index", "columns_by_meaning"]

_NAME_KEY = re.compile(r"NAME(\d+)$")

#: Words of a channel name that make it the input: what drives the piezo (its voltage, the open-loop
#: control value). A target position is a set point, not what reaches the actuator, so it is neither.
INPUT_WORDS = ("voltage", "open loop", "open-loop", "control value", "command")
#: Words that make it the output: what the sensor measured (a position error is neither).
OUTPUT_WORDS = ("current position", "actual position", "sensor")


def is_gcs_file(path: str | Path) -> bool:
    """True when the file starts like a GCS data file (a ``#`` header line or ``[GCS_ARRAY``)."""
    if is_stream(path):       # a pipe is read once: look at the text kept from that read
        try:
            head = _text(Path(path))[:512].lstrip("\ufeff \t\r\n").encode()
        except DataError:
            return False
    else:
        try:
            with open(path, "rb") as fh:
                head = fh.read(512).lstrip(b"\xef\xbb\xbf \t\r\n")
        except OSError:
            return False
    return head.startswith((b"#", b"[GCS_ARRAY"))


def _header_lines(path: Path, text: str) -> tuple[list[str], int]:
    """The header lines (``#`` ones, up to ``# END_HEADER``) and the line number where data start."""
    lines = text.splitlines()
    header: list[str] = []
    for number, line in enumerate(lines, 1):
        stripped = line.strip()
        if not header and (not stripped or stripped.upper().startswith("[GCS_ARRAY")):
            continue
        if not stripped.startswith("#"):
            break
        header.append(stripped)
        if stripped.lstrip("#").strip().upper() == "END_HEADER":
            return header, number + 1
    raise DataError(f"{path}: malformed GCS header: no '# END_HEADER' line before the data "
                    f"({len(header)} header line(s) read)")


def read_gcs_header(path: str | Path) -> tuple[dict[str, str], int]:
    """``{KEY: value text}`` of the header and the first data line number; DataError if malformed."""
    path = Path(path)
    lines, first_data = _header_lines(path, _text(path))
    header: dict[str, str] = {}
    for line in lines:
        body = line.lstrip("#").strip()
        if "=" not in body:
            continue            # '#', '# END_HEADER', '# REM ...' comments
        key, _, value = body.partition("=")
        header[key.strip().upper()] = value.strip()
    return header, first_data


#: What a GCS header may say (a data recorder has a few dozen channels; SEPARATOR is a character code).
HEADER_LIMITS = {"DIM": (1, 1024), "SEPARATOR": (1, 255)}


def _number(path: Path, header: dict[str, str], key: str, kind=float) -> float:
    if key not in header:
        raise DataError(f"{path}: GCS header has no {key} line (need SAMPLE_TIME, DIM, SEPARATOR and NAME0..)")
    try:
        value = float(header[key])
    except ValueError:
        raise DataError(f"{path}: GCS header {key} = {header[key][:40]!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise DataError(f"{path}: GCS header {key} = {header[key][:40]!r} must be positive")
    if kind is int:
        lo, hi = HEADER_LIMITS.get(key, (1, 1 << 31))
        if not value.is_integer() or not lo <= value <= hi:
            raise DataError(f"{path}: GCS header {key} = {header[key][:40]!r} must be a whole number in {lo}..{hi}")
        return int(value)
    return value


def column_names(path: str | Path, header: dict[str, str]) -> list[str]:
    """NAME0 .. NAME{DIM-1} in order; DataError if one is missing.

    A file with no NAMEi line at all (``pitools.savegcsarray(path, None, data)``
    writes none) has its channels called ``NAME0``, ``NAME1``, ...
    """
    dim = int(_number(Path(path), header, "DIM", int))
    if not any(_NAME_KEY.match(key) for key in header):
        return [f"NAME{i}" for i in range(dim)]
    names = []
    for i in range(dim):
        if f"NAME{i}" not in header:
            raise DataError(f"{path}: GCS header has DIM = {dim} but no NAME{i} line")
        names.append(header[f"NAME{i}"])
    return names


def column_index(path: str | Path, names: list[str], wanted: str, role: str) -> int:
    """Index of the column called ``wanted`` (its NAMEi text, case and spacing ignored, or ``NAMEi``)."""
    def norm(s: str) -> str:
        return " ".join(s.split()).lower()
    key = _NAME_KEY.match(wanted.strip().upper())
    if key and int(key.group(1)) < len(names):
        return int(key.group(1))
    matches = [i for i, n in enumerate(names) if norm(n) == norm(wanted)]
    if len(matches) == 1:
        return matches[0]
    listing = "; ".join(f"NAME{i} = {n!r}" for i, n in enumerate(names))
    if matches:
        raise DataError(f"{path}: {role} column {wanted!r} matches {len(matches)} columns; "
                        f"give it as NAMEi ({listing})")
    raise DataError(f"{path}: no {role} column named {wanted!r} (columns: {listing})")


def columns_by_meaning(path: str | Path, names: list[str], iu: int | None = None,
                       iy: int | None = None) -> tuple[int, int]:
    """(input, output) column indices of a file with more than two channels, the missing ones chosen by name.

    The input is the one channel whose name has a word of ``INPUT_WORDS``, the
    output the one with a word of ``OUTPUT_WORDS``; when either is not exactly
    one channel (none, or several axes recorded), DataError: one line listing
    the names, to be chosen with --u-column / --y-column.
    """
    def matching(words: tuple[str, ...], taken: int | None) -> list[int]:
        return [i for i, n in enumerate(names) if i != taken and any(w in " ".join(n.lower().split()) for w in words)]
    u_found = [iu] if iu is not None else matching(INPUT_WORDS, iy)
    y_found = [iy] if iy is not None else matching(OUTPUT_WORDS, iu)
    if len(u_found) == 1 and len(y_found) == 1 and u_found != y_found:
        return u_found[0], y_found[0]
    listing = "; ".join(f"NAME{i} = {n!r}" for i, n in enumerate(names))
    raise DataError(f"{path}: {len(names)} channels and no single voltage/command input and position/sensor "
                    f"output among their names: choose them with --u-column and --y-column ({listing})")


def _pipython_reader():
    try:
        from pipython.pitools import readgcsarray
    except ImportError:
        raise DataError("reading GCS data-recorder files needs pipython: pip install 'creep_online[pi]'") from None
    return readgcsarray


def _first_bad_row(path: Path, first_line: int, sep: str, dim: int) -> str:
    """Where pipython's reader failed, found again line by line for the message."""
    lines = _text(path).splitlines()
    for number in range(first_line, len(lines) + 1):
        row = lines[number - 1].strip()
        if not row:
            continue
        cells = row.split(sep) if sep != " " else row.split()
        if len(cells) < dim:
            return f"line {number} has {len(cells)} value(s), expected {dim}"
        for cell in cells[:dim]:
            try:
                float(cell)
            except ValueError:
                return f"line {number}: not a number: {cell.strip()[:30]!r}"
    return "unreadable data"


def _read_data(readgcsarray, path: Path):
    """pipython's reader on ``path``; a pipe (already read) goes to it as a temporary copy of its text."""
    if not is_stream(path):
        return readgcsarray(str(path))
    with tempfile.TemporaryDirectory(prefix="creep_online_gcs_") as folder:
        copy = Path(folder) / "data.gcs"
        copy.write_text(_text(path))
        return readgcsarray(str(copy))


def _sample_time(path: Path, header: dict[str, str], dt: float | None) -> float:
    """SAMPLE_TIME, or ``dt`` for a file without one; a ``dt`` that contradicts the header is refused."""
    if dt is not None and not (math.isfinite(dt) and dt > 0):
        raise DataError(f"--dt must be a positive number of seconds, got {dt:g}")
    if "SAMPLE_TIME" not in header:
        if dt is None:
            raise DataError(f"{path}: GCS header has no SAMPLE_TIME line; give the sample time with --dt SECONDS")
        return float(dt)
    step = _number(path, header, "SAMPLE_TIME")
    if dt is not None and not math.isclose(dt, step, rel_tol=1e-6):
        raise DataError(f"--dt {dt:g} contradicts SAMPLE_TIME = {step:g} of {path}; drop --dt")
    return step


def load_gcs(path: str | Path, u_column: str | None = None, y_column: str | None = None,
             min_samples: int = MIN_SAMPLES, dt: float | None = None) -> Record:
    """A GCS data-recorder file as a validated Record (t from SAMPLE_TIME or ``dt``; u, y by column name)."""
    path = Path(path)
    header, first_data = read_gcs_header(path)
    step = _sample_time(path, header, dt)
    names = column_names(path, header)
    if len(names) < 2:
        raise DataError(f"{path}: GCS file has {len(names)} column; need an input and an output column")
    sep = chr(int(_number(path, header, "SEPARATOR", int))) if "SEPARATOR" in header else " "
    iu = column_index(path, names, u_column, "input") if u_column else None
    iy = column_index(path, names, y_column, "output") if y_column else None
    if len(names) > 2 and (iu is None or iy is None):
        iu, iy = columns_by_meaning(path, names, iu, iy)
    iu = 0 if iu is None else iu
    iy = 1 if iy is None else iy
    readgcsarray = _pipython_reader()
    try:
        _, data = _read_data(readgcsarray, path)
    except (ValueError, IndexError, KeyError, UnicodeDecodeError, OverflowError):
        raise DataError(f"{path}: {_first_bad_row(path, first_data, sep, len(names))}") from None
    u = np.asarray(data[iu], dtype=float)
    y = np.asarray(data[iy], dtype=float)
    for role, name, values in (("input", names[iu], u), ("output", names[iy], y)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise DataError(f"{path}: data row {bad[0] + 1}, {role} column {name!r}: NaN/inf not allowed")
    rec = Record(np.arange(u.size) * step, u, y, source=str(path))
    return rec.validate(min_samples)


#: Longest line accepted in a GCS file (bytes): a data row is short; a file of one endless line is not a record.
MAX_LINE_BYTES = 65536


def _text(path: str | Path) -> str:
    """The GCS file's text (``input_files.read_text``)."""
    return read_text(path, what="GCS file", max_line=MAX_LINE_BYTES)
