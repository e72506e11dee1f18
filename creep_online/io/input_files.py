"""Every input file read the same way: a regular file, a pipe, a FIFO, ``/dev/stdin`` or ``-``, bounded.

``read_input(path)`` returns the bytes of what the user named:

* a regular file, at most ``MAX_INPUT_BYTES`` (a larger one is refused
  before it is read);
* a pipe or a FIFO (``identify - < x.csv``, ``identify <(zcat x.csv.gz)``,
  ``/dev/stdin``, ``mkfifo``) read as a stream to its end, bounded the same
  way, and never waited on forever: a FIFO nobody writes to, or a writer that
  stays silent, gets a one-line answer after ``read_timeout()`` seconds
  (``CREEP_ONLINE_READ_TIMEOUT``, default 30 s);
* ``-`` is standard input (refused when it is a terminal);
* devices (``/dev/zero``), sockets and folders are refused by name.

A pipe can be read only once, while a reader may look at its input twice (is
it a GCS file? a CSV?), so the content of the last pipe read is kept for the
process (``remembered``), keyed by the pipe's identity.
"""
from __future__ import annotations

import os
import select
import stat
import warnings
from pathlib import Path

from ..errors import DataError, DataWarning

#: Largest input read (bytes): a t,u,y CSV of ~17 million rows. ``CREEP_ONLINE_MAX_INPUT_BYTES`` overrides it.
MAX_INPUT_BYTES = 1 << 30
#: Seconds a pipe or FIFO may stay silent (no writer, or a writer that writes nothing) before the read gives up.
READ_TIMEOUT_S = 30.0
_CHUNK = 1 << 20
_remembered: dict[tuple, bytes] = {}


def read_timeout() -> float:
    """The silence allowed on a pipe or FIFO (s): ``CREEP_ONLINE_READ_TIMEOUT`` or ``READ_TIMEOUT_S``."""
    return _env_number("CREEP_ONLINE_READ_TIMEOUT", READ_TIMEOUT_S)


def max_input_bytes() -> int:
    """The largest input read: ``CREEP_ONLINE_MAX_INPUT_BYTES`` or ``MAX_INPUT_BYTES``."""
    return int(_env_number("CREEP_ONLINE_MAX_INPUT_BYTES", MAX_INPUT_BYTES))


def _env_number(name: str, default: float) -> float:
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise DataError(f"${name} must be a positive number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise DataError(f"${name} must be a positive number, got {text!r}")
    return value


def is_stream(path: str | Path) -> bool:
    """Is ``path`` standard input, a pipe or a FIFO (read once, as a stream)?"""
    if str(path) == "-":
        return True
    try:
        return stat.S_ISFIFO(os.stat(path).st_mode)
    except OSError:
        return False


def check_kind(path: str | Path, what: str = "file") -> os.stat_result:
    """The stat of ``path``; DataError unless it is a regular file, a pipe or a FIFO (``-``: standard input)."""
    name = str(path)
    try:
        st = os.fstat(0) if name == "-" else os.stat(path)
    except FileNotFoundError:
        raise DataError(f"{name}: no such file") from None
    except OSError as exc:
        raise DataError(f"{name[:80]}: cannot read ({exc.strerror or exc})") from None
    except ValueError as exc:                    # an embedded NUL
        raise DataError(f"{name[:80]!r}: not a usable file name ({exc})") from None
    mode = st.st_mode
    if name == "-" and (stat.S_ISCHR(mode) and os.isatty(0)):
        raise DataError("-: standard input is a terminal; pipe or redirect a file into it (identify - < data.csv)")
    if stat.S_ISDIR(mode):
        raise DataError(f"{name}: is a directory, not a {what}")
    if not (stat.S_ISREG(mode) or stat.S_ISFIFO(mode)):
        kind = "a character device" if stat.S_ISCHR(mode) else "a block device" if stat.S_ISBLK(mode) \
            else "a socket" if stat.S_ISSOCK(mode) else "not a regular file"
        raise DataError(f"{name}: is {kind}, not a {what}")
    return st


def read_input(path: str | Path, *, what: str = "file", max_line: int | None = None,
               limit: int | None = None, timeout: float | None = None) -> bytes:
    """All bytes of ``path`` (see the module docstring); DataError with the reason otherwise.

    ``max_line``: refuse as soon as a line grows longer (a stream of one endless line is not a text record).
    """
    name = str(path)
    st = check_kind(path, what)
    limit = max_input_bytes() if limit is None else limit
    if stat.S_ISREG(st.st_mode) and name != "-":
        if st.st_size > limit:
            raise DataError(f"{name}: {st.st_size} bytes, more than the {limit} this tool reads "
                            f"(CREEP_ONLINE_MAX_INPUT_BYTES)")
        return _read_regular(path, name, max_line, limit)
    key = (name, st.st_dev, st.st_ino)
    if key not in _remembered:
        data = _read_stream(name, max_line, limit, read_timeout() if timeout is None else timeout)
        _remembered.clear()                      # only the last pipe is kept
        _remembered[key] = data
    return _remembered[key]


def read_text(path: str | Path, *, what: str = "file", max_line: int | None = None) -> str:
    """The text of ``path`` read once whatever it is (``read_input``: bounded, pipes never waited on forever, a
    pipe's content remembered for a second look); a gzip file is read as the text it holds, bounded the same
    way. DataError for bytes that are not UTF-8 text."""
    data = read_input(path, what=what, max_line=max_line)
    if data[:2] == GZIP_MAGIC:
        data = _gunzip(path, data)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text file (undecodable byte at offset {exc.start})") from None


#: The first two bytes of a gzip file: ``run.csv.gz`` is read as the CSV it holds.
GZIP_MAGIC = b"\x1f\x8b"


def _gunzip(path: str | Path, data: bytes) -> bytes:
    """The bytes inside a gzip file, at most ``max_input_bytes``; DataError if it is corrupt or larger."""
    import gzip
    import io
    import zlib
    limit = max_input_bytes()
    try:
        with gzip.GzipFile(fileobj=io.BytesIO(data)) as fh:
            text = fh.read(limit + 1)
    except (OSError, EOFError, zlib.error) as exc:
        raise DataError(f"{path}: a gzip file that cannot be decompressed ({exc})") from None
    if len(text) > limit:
        raise DataError(f"{path}: decompresses to more than the {limit} bytes this tool reads "
                        f"(CREEP_ONLINE_MAX_INPUT_BYTES)")
    return text


def _read_regular(path: str | Path, name: str, max_line: int | None, limit: int) -> bytes:
    chunks: list[bytes] = []
    since_newline = total = 0
    try:
        with open(path, "rb") as fh:
            size0 = os.fstat(fh.fileno()).st_size
            while chunk := fh.read(_CHUNK):
                chunks.append(chunk)
                total += len(chunk)
                since_newline = _check_chunk(name, chunk, since_newline, max_line, total, limit)
            grown = os.fstat(fh.fileno()).st_size
    except IsADirectoryError:
        raise DataError(f"{name}: is a directory") from None
    except OSError as exc:
        raise DataError(f"{name}: cannot read ({exc.strerror or exc})") from None
    data = b"".join(chunks)
    if grown != size0 or grown != len(data):
        warnings.warn(f"{name}: the file changed size while it was read (still being written?); "
                      f"used the {len(data)} bytes read", DataWarning, stacklevel=4)
    return data


def _check_chunk(name: str, chunk: bytes, since_newline: int, max_line: int | None, total: int, limit: int) -> int:
    """The bytes since the last newline after ``chunk``; DataError past ``max_line`` or ``limit``."""
    nl = chunk.rfind(b"\n")
    since_newline = since_newline + len(chunk) if nl < 0 else len(chunk) - nl - 1
    if max_line is not None and since_newline > max_line:
        raise DataError(f"{name}: a line longer than {max_line} bytes: not a t,u,y CSV file")
    if total > limit:
        raise DataError(f"{name}: more than {limit} bytes, more than this tool reads (CREEP_ONLINE_MAX_INPUT_BYTES)")
    return since_newline


def _read_stream(name: str, max_line: int | None, limit: int, timeout: float) -> bytes:
    """A pipe, FIFO or standard input to its end, waiting at most ``timeout`` s for each next chunk."""
    try:
        # (O_NONBLOCK: a FIFO's open does not wait for a writer; poll below waits, at most ``timeout``)
        fd = os.dup(0) if name == "-" else os.open(name, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise DataError(f"{name}: cannot read ({exc.strerror or exc})") from None
    chunks: list[bytes] = []
    since_newline = total = 0
    poller = select.poll()
    poller.register(fd, select.POLLIN | select.POLLHUP)
    try:
        while True:
            if not poller.poll(timeout * 1000.0):
                raise DataError(f"{name}: nothing to read for {timeout:g} s "
                                + ("(a FIFO with no writer?)" if not total else f"after {total} bytes (writer stalled?)")
                                + "; CREEP_ONLINE_READ_TIMEOUT sets the wait")
            try:
                chunk = os.read(fd, _CHUNK)
            except BlockingIOError:
                continue
            except OSError as exc:
                raise DataError(f"{name}: cannot read ({exc.strerror or exc})") from None
            if not chunk:
                return b"".join(chunks)
            chunks.append(chunk)
            total += len(chunk)
            since_newline = _check_chunk(name, chunk, since_newline, max_line, total, limit)
    finally:
        os.close(fd)
