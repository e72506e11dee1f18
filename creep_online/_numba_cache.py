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

numba keys each cached kernel on its own source file, but a kernel compiles in the
constants and inlined functions it takes from other modules (the online state's
offsets from ``_kernels/layout.py`` and ``_kernels/hysteresis.py``): a kernel module
edited while another's cache stays would run the old offsets. ``clear_stale_kernels``
therefore keeps a stamp of every kernel module (``KERNEL_MODULES``: path, size and
modification time) beside the cache and removes all their compiled kernels when it
changes (an edit, a checkout, a new version in place), under a lock so that parallel
test workers clear once.
"""
from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
#: The modules whose functions numba compiles (``online/policy/change.py``'s pure rules are compiled by
#: ``_kernels/recursive.py``; a test checks that every cached kernel is one of theirs): a change to any of them clears
#: the compiled kernels of all of them (``clear_stale_kernels``).
KERNEL_MODULES = ("kernels.py", "online/compensator_kernels.py", "online/rest.py", "online/search.py",
                  "online/policy/change.py", "online/_kernels/coefficients.py", "online/_kernels/fit_machine.py",
                  "online/_kernels/hysteresis.py", "online/_kernels/layout.py", "online/_kernels/recursive.py",
                  "online/_kernels/window.py")
#: The stamp's file name in the package's cache directory.
STAMP = "creep_online-kernels.stamp"


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
    """Set ``NUMBA_CACHE_DIR`` when needed and clear stale compiled kernels (see the module notes); the directory
    chosen, or None."""
    chosen = _choose_directory()
    try:
        clear_stale_kernels()
    except OSError:       # (a cache that cannot be cleaned is numba's to report when it loads)
        pass
    return chosen


def _choose_directory() -> str | None:
    """``NUMBA_CACHE_DIR`` set when the package directory is not writable; the directory chosen, or None."""
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


def cache_dir_of(source_dir: Path, cache_root: str | None = None) -> Path:
    """Where numba caches the kernels of the modules in ``source_dir``: ``__pycache__`` beside them, or under
    ``NUMBA_CACHE_DIR`` (``cache_root``) at the directory's own path, as numba's user-provided locator does."""
    root = os.environ.get("NUMBA_CACHE_DIR") if cache_root is None else cache_root
    if not root:
        return source_dir / "__pycache__"
    return Path(root) / os.path.splitdrive(str(source_dir.resolve()))[1].lstrip(os.sep)


def kernel_stamp(package_dir: Path = PACKAGE_DIR, modules: tuple[str, ...] = KERNEL_MODULES) -> str:
    """A digest of every kernel module's path, size and modification time (a missing one counts as such)."""
    digest = hashlib.sha1()
    for name in modules:
        try:
            st = (package_dir / name).stat()
            digest.update(f"{name}:{st.st_size}:{st.st_mtime_ns};".encode())
        except OSError:
            digest.update(f"{name}:missing;".encode())
    return digest.hexdigest()


def clear_stale_kernels(package_dir: Path = PACKAGE_DIR, modules: tuple[str, ...] = KERNEL_MODULES,
                        cache_root: str | None = None) -> int:
    """Remove the compiled kernels of every module in ``modules`` if any of them changed since the stamp was written
    (no stamp: as if changed), then write the stamp; the number of files removed. Holds a lock on the stamp's
    directory while it checks, removes and writes (POSIX; elsewhere unlocked)."""
    stamp_dir = cache_dir_of(package_dir, cache_root)
    stamp_file = stamp_dir / STAMP
    now = kernel_stamp(package_dir, modules)
    try:
        if stamp_file.read_text() == now:
            return 0
    except OSError:
        pass
    stamp_dir.mkdir(parents=True, exist_ok=True)
    with _locked(stamp_dir / (STAMP + ".lock")):
        try:
            if stamp_file.read_text() == now:       # (another process cleared them while this one waited)
                return 0
        except OSError:
            pass
        removed = 0
        for name in modules:
            source = package_dir / name
            folder = cache_dir_of(source.parent, cache_root)
            for path in folder.glob(f"{source.stem}.*.nb[ci]") if folder.is_dir() else ():
                path.unlink(missing_ok=True)
                removed += 1
        tmp = stamp_file.with_name(f"{STAMP}.{os.getpid()}")
        tmp.write_text(now)
        os.replace(tmp, stamp_file)
    return removed


class _locked:
    """An exclusive advisory lock on ``path`` while inside (``fcntl.flock``; a no-op where there is none)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd: int | None = None

    def __enter__(self) -> "_locked":
        try:
            import fcntl
        except ImportError:      # Windows: unlocked
            return self
        self.fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o600)
        fcntl.flock(self.fd, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            os.close(self.fd)    # (closing releases the lock)
