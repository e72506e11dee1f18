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
file and what is wrong (no ``# END_HEADER``, no ``SAMPLE_TIME``, a column name
that does not exist: the message lists those that do); the data are then read
by pipython's own reader (``pipython.pitools.readgcsarray``). Time is
``k * SAMPLE_TIME``; input and output are the columns chosen by name
(default: NAME0 is the input, NAME1 the output, the order the ``pi:`` source
records them in).
"""
from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..record import MIN_SAMPLES, Record
from .csvfile import _read_text
from .input_files import is_stream

__all__ = ["is_gcs_file", "read_gcs_header", "load_gcs", "column_names", "column_index"]

_NAME_KEY = re.compile(r"NAME(\d+)$")


def is_gcs_file(path: str | Path) -> bool:
    """True when the file starts like a GCS data file (a ``#`` header line or ``[GCS_ARRAY``)."""
    if is_stream(path):       # a pipe is read once: look at the text kept from that read
        try:
            head = _read_text(Path(path))[:512].lstrip("\ufeff \t\r\n").encode()
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
    lines, first_data = _header_lines(path, _read_text(path))
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
    """NAME0 .. NAME{DIM-1} in order; DataError if one is missing."""
    dim = int(_number(Path(path), header, "DIM", int))
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


def _pipython_reader():
    try:
        from pipython.pitools import readgcsarray
    except ImportError:
        raise DataError("reading GCS data-recorder files needs pipython: pip install 'creep_online[pi]'") from None
    return readgcsarray


def _first_bad_row(path: Path, first_line: int, sep: str, dim: int) -> str:
    """Where pipython's reader failed, found again line by line for the message."""
    lines = _read_text(path).splitlines()
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
        copy.write_text(_read_text(path))
        return readgcsarray(str(copy))


def load_gcs(path: str | Path, u_column: str | None = None, y_column: str | None = None,
             min_samples: int = MIN_SAMPLES) -> Record:
    """A GCS data-recorder file as a validated Record (t from SAMPLE_TIME; u, y by column name)."""
    path = Path(path)
    header, first_data = read_gcs_header(path)
    dt = _number(path, header, "SAMPLE_TIME")
    names = column_names(path, header)
    if len(names) < 2:
        raise DataError(f"{path}: GCS file has {len(names)} column; need an input and an output column")
    sep = chr(int(_number(path, header, "SEPARATOR", int)))
    iu = column_index(path, names, u_column, "input") if u_column else 0
    iy = column_index(path, names, y_column, "output") if y_column else 1
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
    rec = Record(np.arange(u.size) * dt, u, y, source=str(path))
    return rec.validate(min_samples)
