"""Outputs that never destroy data: checked paths, atomic files, all-or-nothing report folders.

* ``check_output(path, inputs)`` refuses, before any work is done, an output
  that is an input (the same file, compared by identity: another spelling, a
  symlink or a hard link is still the same file), a directory, in a missing
  or unwritable folder, or an empty name.
* ``check_default_output(path, inputs)``: the same for a name the tool chose
  (``batch``'s ``fleet.html`` beside the table); an existing file is replaced
  only if this tool wrote it (``WRITTEN_BY`` in its first bytes).
* ``atomic_write(path)`` writes to a temporary file in the same folder and
  renames it over the target only when everything was written and synced: a
  reader (or a second writer) sees the old file or the new one, never a mix;
  an error, Ctrl-C or SIGTERM leaves the old file untouched and no temporary file.
* ``spreadsheet_text(value)`` neutralises a text cell of a CSV output (OWASP's
  rule against formula injection): a record name ``=cmd|' /C calc'!A0`` is
  written ``'=cmd|...`` and a spreadsheet shows it as text.
* ``report_dir(path)`` builds a report folder in a temporary sibling and swaps
  it in at the end. A folder is written only if it is new, empty, or holds
  nothing but an earlier report of this tool: its marker file
  (``REPORT_MARKER``) lists the files that report wrote, and a folder with
  anything else (the user's own files) is refused before any work.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import IO, Iterable, Iterator

from .._signals import temporary
from ..errors import OutputError

#: The marker file of a report folder: which tool wrote it and the files it holds (JSON).
REPORT_MARKER = ".creep-online-report"
#: What a file this tool wrote says in its first bytes (an HTML comment in the pages it writes).
WRITTEN_BY = "written by creep-online"
_SNIFF_BYTES = 4096


#: First characters that make a spreadsheet read a cell as a formula (OWASP, "CSV Injection").
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def spreadsheet_text(value: str) -> str:
    """A text cell a spreadsheet shows as text: one starting like a formula gets a leading ``'`` (a plain number
    such as ``-1.5`` stays as it is)."""
    if not value.startswith(FORMULA_STARTS):
        return value
    try:
        float(value)
        return value
    except ValueError:
        return "'" + value


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def _checked_name(path: str | Path, what: str) -> Path:
    """``path`` as a Path; OutputError for an empty name or one the system cannot look up (too long, ...)."""
    if not str(path).strip():
        raise OutputError(f"{what} name is empty")
    out = Path(path)
    try:
        os.stat(out)
    except (FileNotFoundError, NotADirectoryError):
        pass
    except OSError as exc:
        shown = str(path) if len(str(path)) <= 80 else str(path)[:77] + "..."
        raise OutputError(f"{shown}: cannot be written ({exc.strerror or exc})") from None
    except ValueError as exc:                    # an embedded NUL
        raise OutputError(f"{str(path)[:80]!r}: not a usable file name ({exc})") from None
    return out


def check_output(path: str | Path, inputs: Iterable[str | Path] = ()) -> Path:
    """The output path, or OutputError when writing it would fail or destroy an input."""
    out = _checked_name(path, "an output file")
    for src in inputs:
        if str(src) == "-":
            continue
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


def check_default_output(path: str | Path, inputs: Iterable[str | Path] = (), *, flag: str = "") -> Path:
    """``check_output`` for a name the tool chose: an existing file it did not write is refused (``flag``: the
    option that names another file)."""
    out = check_output(path, inputs)
    if out.exists() and not written_by_us(out):
        hint = f"; give {flag} FILE" if flag else ""
        raise OutputError(f"{out}: exists and was not written by creep-online; not replacing it{hint}")
    return out


def written_by_us(path: str | Path) -> bool:
    """Does the file say, in its first bytes, that this tool wrote it (``WRITTEN_BY``)?"""
    try:
        with open(path, "rb") as fh:
            return WRITTEN_BY.encode() in fh.read(_SNIFF_BYTES)
    except OSError:
        return False


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
        with temporary(tmp):
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
    """The report folder, or OutputError if it cannot be written or holds anything but an earlier report."""
    out = _checked_name(path, "the report folder")
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    if out.is_dir():
        foreign = _not_report_files(out)
        if foreign:
            shown = ", ".join(sorted(foreign)[:3]) + (", ..." if len(foreign) > 3 else "")
            raise OutputError(f"{out}: folder holds files that are not an earlier creep-online report ({shown}); "
                              f"choose a new or empty folder")
    parent = out.absolute().parent
    if not parent.is_dir():
        raise OutputError(f"{out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{out}: folder {parent} is not writable")
    return out


def _not_report_files(folder: Path) -> list[str]:
    """The entries of ``folder`` that its report marker does not list (all of them without a marker)."""
    try:
        names = [p.name for p in folder.iterdir()]
    except OSError as exc:
        raise OutputError(f"{folder}: cannot list the folder ({exc.strerror})") from None
    listed = _report_files(folder)
    return [n for n in names if n != REPORT_MARKER and n not in listed]


def _report_files(folder: Path) -> set[str]:
    """The files the marker of ``folder`` lists (none if there is no readable marker of this tool)."""
    marker = folder / REPORT_MARKER
    try:
        if not marker.is_file() or marker.stat().st_size > 1 << 20:
            return set()
        data = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set()
    if not isinstance(data, dict) or data.get("tool") != "creep-online" or not isinstance(data.get("files"), list):
        return set()
    return {f for f in data["files"] if isinstance(f, str) and f and "/" not in f and f not in (".", "..")}


@contextlib.contextmanager
def report_dir(path: str | Path) -> Iterator[Path]:
    """Yield a temporary sibling folder; on success its marker is written and it replaces ``path`` (an old
    report is removed)."""
    out = check_report_dir(path)
    parent = out.absolute().parent
    try:
        tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{out.name}.", suffix=".tmp"))
    except OSError as exc:
        raise OutputError(f"{out}: cannot create the report folder ({exc.strerror})") from None
    try:
        with temporary(tmp):
            yield tmp
            files = sorted(p.name for p in tmp.iterdir() if p.name != REPORT_MARKER)
            (tmp / REPORT_MARKER).write_text(json.dumps({"tool": "creep-online", "files": files}, indent=1) + "\n",
                                             encoding="utf-8")
            tmp.chmod(0o777 & ~_umask())
            check_report_dir(out)     # still only a report of ours (the user may have put files there meanwhile)
            _swap_in(tmp, out)
    except OutputError:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
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
