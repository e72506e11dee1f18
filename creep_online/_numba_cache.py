"""Where numba keeps its compiled-kernel cache when the installed package is read-only.

The kernels are compiled with ``cache=True``, which numba writes next to the
source (``__pycache__``) or, failing that, into ``~/.cache/numba``. A service
account on a system-wide install can do neither (no write access to the
package, no home directory) and numba then refuses to import the kernels
("cannot cache function ...: no locator available"). ``configure()`` runs once,
before numba is imported, and only when the user has not set
``NUMBA_CACHE_DIR``: if the package directory is not writable it points numba at
the first writable per-user directory of

1. ``$XDG_CACHE_HOME/creep_online/numba`` (default ``~/.cache/creep_online/numba``;
   ``%LOCALAPPDATA%`` on Windows),
2. ``<tmp>/creep_online-<uid>/numba`` (created 0700; not used if another user owns it),

and, if none can be written, at a private temporary directory for this process
only (kernels are then compiled on every start) with a one-time note on stderr.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def _writable(directory: Path) -> bool:
    """True when ``directory`` exists (or can be created) and a file can be written in it."""
    probe = directory / f".creep_online-probe-{os.getpid()}-{os.urandom(4).hex()}"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        os.close(os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        os.unlink(probe)
    except OSError:
        return False
    return True


def _private_tmp() -> Path | None:
    """``<tmp>/creep_online-<uid>``, created 0700 and owned by us; None if someone else holds the name.

    numba's cache files are pickles: a directory in a shared /tmp that another
    user could have created (or can write) must not be used.
    """
    import tempfile   # here, not at the top: every start of the program runs configure()

    root = Path(tempfile.gettempdir()) / f"creep_online-{_user_name()}"
    try:
        root.mkdir(mode=0o700, exist_ok=True)
        st = root.lstat()
    except OSError:
        return None
    if hasattr(os, "getuid") and (st.st_uid != os.getuid() or st.st_mode & 0o022 or root.is_symlink()):
        return None
    return root / "numba"


def _user_name() -> str:
    try:
        return str(os.getuid())
    except AttributeError:  # Windows
        return os.environ.get("USERNAME", "user")


def candidates() -> list[Path]:
    """Per-user cache directories, most preferred first."""
    out: list[Path] = []
    base = os.environ.get("XDG_CACHE_HOME") or os.environ.get("LOCALAPPDATA")
    if base:
        out.append(Path(base) / "creep_online" / "numba")
    home = os.path.expanduser("~")
    if home and home != "~":
        out.append(Path(home) / ".cache" / "creep_online" / "numba")
    private = _private_tmp()
    if private is not None:
        out.append(private)
    return out


def package_writable() -> bool:
    """Whether numba can cache next to the source (``creep_online/__pycache__``)."""
    pycache = PACKAGE_DIR / "__pycache__"
    target = pycache if pycache.is_dir() else PACKAGE_DIR
    return os.access(target, os.W_OK) and _writable(target)


def configure() -> str | None:
    """Set ``NUMBA_CACHE_DIR`` when needed (see the module notes); the directory chosen, or None."""
    if os.environ.get("NUMBA_CACHE_DIR") or package_writable():
        return None
    for directory in candidates():
        if _writable(directory):
            os.environ["NUMBA_CACHE_DIR"] = str(directory)
            return str(directory)
    import tempfile

    private = tempfile.mkdtemp(prefix="creep_online-numba-")
    os.environ["NUMBA_CACHE_DIR"] = private
    print(f"creep_online: note: no writable cache directory (package, ~/.cache and {tempfile.gettempdir()} "
          f"are read-only); compiled kernels are not kept between runs", file=sys.stderr)
    return private
