"""Outputs that never destroy data: checked paths, atomic files, all-or-nothing report folders.

* ``check_output(path, inputs)`` refuses, before any work is done, an output
  that is an input (same file), a directory, in a missing or unwritable folder.
* ``atomic_write(path)`` writes to a temporary file in the same folder and
  renames it over the target only when everything was written and synced: a
  reader (or a second writer) sees the old file or the new one, never a mix;
  an error or Ctrl-C leaves the old file untouched.
* ``report_dir(path)`` builds a report folder in a temporary sibling and swaps
  it in at the end. An existing folder is replaced only if it holds nothing
  but report files (``*.html``, ``*.png``, ``*.json``); anything else is refused.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import IO, Iterable, Iterator

from ..errors import OutputError

#: Files a report folder may hold; a folder with anything else is not replaced.
REPORT_SUFFIXES = (".html", ".png", ".json")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def check_output(path: str | Path, inputs: Iterable[str | Path] = ()) -> Path:
    """The output path, or OutputError when writing it would fail or destroy an input."""
    out = Path(path)
    for src in inputs:
        if _same_file(out, Path(src)):
            raise OutputError(f"{out}: refusing to overwrite the input file {src} (choose another output)")
    if out.is_dir():
        raise OutputError(f"{out}: is a directory (give a file name)")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(f"{out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{out}: folder {parent} is not writable")
    if out.exists() and not out.is_file():
        raise OutputError(f"{out}: exists and is not a regular file")
    return out


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", encoding: str | None = "utf-8") -> Iterator[IO]:
    """Open a temporary file beside ``path``; on success fsync and rename it over ``path``."""
    out = check_output(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=out.parent if str(out.parent) else ".", prefix=f".{out.name}.",
                                   suffix=".tmp")
    except OSError as exc:
        raise OutputError(f"{out}: cannot write ({exc.strerror})") from None
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else encoding) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        _keep_mode(out, tmp)
        os.replace(tmp, out)
    except OSError as exc:
        _unlink(tmp)
        raise OutputError(f"{out}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _unlink(tmp)
        raise


def _keep_mode(out: Path, tmp: str) -> None:
    """The new file gets the old file's permissions, or the usual umask-based ones (mkstemp uses 0600)."""
    try:
        mode = out.stat().st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(tmp, mode)


def _unlink(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def check_report_dir(path: str | Path) -> Path:
    """The report folder, or OutputError if it cannot be written or holds files that are not a report."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    if out.is_dir():
        foreign = [p.name for p in out.iterdir() if not (p.is_file() and p.suffix.lower() in REPORT_SUFFIXES)]
        if foreign:
            raise OutputError(f"{out}: folder holds other files ({', '.join(sorted(foreign)[:3])}"
                              f"{', ...' if len(foreign) > 3 else ''}); choose a new or empty folder")
    parent = out.absolute().parent
    if not parent.is_dir():
        raise OutputError(f"{out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{out}: folder {parent} is not writable")
    return out


@contextlib.contextmanager
def report_dir(path: str | Path) -> Iterator[Path]:
    """Yield a temporary sibling folder; on success it replaces ``path`` (an old report is removed)."""
    out = check_report_dir(path)
    parent = out.absolute().parent
    try:
        tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{out.name}.", suffix=".tmp"))
    except OSError as exc:
        raise OutputError(f"{out}: cannot create the report folder ({exc.strerror})") from None
    try:
        yield tmp
        tmp.chmod(0o777 & ~_umask())
        _swap_in(tmp, out)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"{out}: cannot write the report ({exc.strerror or exc})") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _swap_in(new: Path, out: Path) -> None:
    """Replace folder ``out`` by ``new``: the old report is moved aside first, then removed."""
    if not out.exists():
        os.replace(new, out)
        return
    old = Path(tempfile.mkdtemp(dir=new.parent, prefix=f".{out.name}.", suffix=".old"))
    os.replace(out, old / "report")
    try:
        os.replace(new, out)
    except OSError:
        os.replace(old / "report", out)   # put the old report back
        raise
    shutil.rmtree(old, ignore_errors=True)
