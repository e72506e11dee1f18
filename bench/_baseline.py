"""Run the previous code as a baseline: ``git archive`` of a commit into a temp dir, used from a subprocess.

The baseline runs in its own interpreter so the two versions of
``creep_online`` never share a process; its numba cache lives in the temp dir.
"""
from __future__ import annotations

import io
import os
import subprocess
import sys
import tarfile
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def extract(ref: str) -> tuple[str, str]:
    """(directory, full commit id) of ``ref`` exported from this repository into a fresh temp dir."""
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", ref], check=True, capture_output=True,
                            text=True).stdout.strip()
    data = subprocess.run(["git", "-C", ROOT, "archive", "--format=tar", commit], check=True,
                          capture_output=True).stdout
    path = tempfile.mkdtemp(prefix="creep_baseline_")
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(path)
    return path, commit


def _env(path: str) -> dict:
    """The baseline package first on sys.path, its numba cache beside it."""
    return dict(os.environ, PYTHONPATH=path, NUMBA_CACHE_DIR=os.path.join(path, ".numba_cache"))


def run_python(path: str, code: str, *args: str, timeout: float = 3600.0) -> str:
    """Run ``code`` with ``path`` first on sys.path (the baseline package); returns its stdout."""
    env = _env(path)
    out = subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True, text=True,
                         env=env, cwd=path, timeout=timeout)
    return out.stdout


def start_worker(ref: str, code: str) -> tuple[subprocess.Popen, str]:
    """(process, commit): ``code`` run by the code of ``ref`` as a worker that reads requests on stdin and answers
    on stdout; it must print ``ready`` once it has imported what it needs (RuntimeError if it does not)."""
    path, commit = extract(ref)
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env=_env(path), cwd=path)
    if proc.stdout.readline().strip() != "ready":
        raise RuntimeError("the previous code's worker did not start")
    return proc, commit
