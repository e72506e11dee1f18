"""A read-only install runs for another user: no numba cache error at import.

The package is copied (without any __pycache__) into a directory the test user
cannot write, and run by an unprivileged user (``setpriv`` to nobody when the
tests run as root; as root, permissions are not enforced). Its runtime
dependencies (the closure of the package's base requirements, no extras) are
installed from this environment into the same world-readable temporary tree, so
the test does not depend on where the clone and its virtual environment live
(a private home directory with mode 700 included). HOME is a writable temporary
directory in one run and missing in the other (a service account).
"""
from __future__ import annotations

import importlib.metadata as metadata
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import creep_online

NOBODY = 65534
SCRIPT = ("import os, numpy as np, creep_online as c; t = np.arange(200) * 1e-3; "
          "y = c.simulate(c.CreepModel(0.3, 0.01, 1e-4), t, (t > 0.01) * 1.0); "
          "print('ok', float(y[-1]) > 0, os.environ.get('NUMBA_CACHE_DIR'))")


def _interpreter_for_others() -> str | None:
    """A Python of this minor version that another user can execute (the venv's may live under /root)."""
    here = Path(sys.executable).resolve()
    version = "%d.%d" % sys.version_info[:2]
    candidates = [here, *(Path(d) / f"python{v}" for d in ("/usr/bin", "/usr/local/bin") for v in (version, "3"))]
    for exe in candidates:
        if not exe.exists():
            continue
        probe = _as_nobody([str(exe), "-c", "import sys; print(sys.version_info[:2])"], env={"HOME": "/"})
        if probe.returncode == 0 and probe.stdout.strip() == str(tuple(sys.version_info[:2])):
            return str(exe)
    return None


def _as_nobody(cmd: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    prefix: list[str] = []
    if os.geteuid() == 0:
        prefix = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
    full_env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), **env}
    return subprocess.run(prefix + cmd, capture_output=True, text=True, env=full_env, timeout=600)


def _base_requirements(dist: metadata.Distribution) -> list[str]:
    """Names of what a distribution needs without extras (markers other than ``extra`` taken as true)."""
    names = []
    for req in dist.requires or []:
        if "extra" in req.partition(";")[2]:
            continue
        names.append(re.match(r"[A-Za-z0-9._-]+", req).group(0))
    return names


def _runtime_closure(name: str) -> list[metadata.Distribution]:
    """The installed distributions ``name`` needs to run, recursively, without itself."""
    seen: dict[str, metadata.Distribution] = {}
    todo = _base_requirements(metadata.distribution(name))
    while todo:
        dep = todo.pop()
        key = re.sub(r"[-_.]+", "-", dep).lower()
        if key in seen:
            continue
        seen[key] = metadata.distribution(dep)
        todo.extend(_base_requirements(seen[key]))
    return list(seen.values())


def _install_copy(dist: metadata.Distribution, target: Path) -> None:
    """Put an installed distribution's files (its RECORD, scripts outside site-packages left out) under target.

    A file others can already read is hard-linked (fast, no space; its mode is never changed);
    anything else, or across file systems, is copied and made readable by all.
    """
    for rel in dist.files or []:
        if ".." in rel.parts:
            continue
        src = Path(dist.locate_file(rel))
        if not src.is_file():
            continue
        dst = target / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        try:
            if not src.stat().st_mode & 0o004:
                raise PermissionError("not readable by others")
            os.link(src, dst)
        except OSError:
            shutil.copyfile(src, dst)
            dst.chmod(0o644)


@pytest.fixture(scope="module")
def readonly_install():
    if os.geteuid() == 0 and shutil.which("setpriv") is None:
        pytest.skip("running as root and no setpriv to drop privileges: permissions would not be enforced")
    if not hasattr(os, "geteuid"):
        pytest.skip("POSIX permissions needed")
    root = Path(tempfile.mkdtemp(prefix="creep_ro_"))
    site = root / "site"
    shutil.copytree(Path(creep_online.__file__).parent, site / "creep_online",
                    ignore=shutil.ignore_patterns("__pycache__"))
    home = root / "home"
    home.mkdir()
    for p in [root, *root.rglob("*")]:
        p.chmod(0o755 if p.is_dir() else 0o644)   # readable by all, writable by the owner only
    deps = root / "deps"
    for dist in _runtime_closure("creep_online"):
        _install_copy(dist, deps)
    for p in [deps, *deps.rglob("*")]:
        if p.is_dir():
            p.chmod(0o755)
    if os.geteuid() == 0:
        os.chown(home, NOBODY, NOBODY)
    else:
        for p in [site, *site.rglob("*")]:
            if p.is_dir():
                p.chmod(0o555)
    exe = _interpreter_for_others()
    if exe is None:
        shutil.rmtree(root, ignore_errors=True)
        pytest.skip("no Python of this version executable by an unprivileged user")
    yield exe, f"{site}{os.pathsep}{deps}", home
    for p in [root, *root.rglob("*")]:
        if p.is_dir():
            p.chmod(0o755)
    shutil.rmtree(root, ignore_errors=True)


def test_package_dir_is_really_read_only_for_the_test_user(readonly_install):
    exe, path, home = readonly_install
    site = path.split(os.pathsep)[0]
    r = _as_nobody([exe, "-c", f"import os; print(os.access({site + '/creep_online'!r}, os.W_OK))"],
                   {"HOME": str(home)})
    assert r.stdout.strip() == "False", r.stderr


def test_help_runs_from_a_read_only_install(readonly_install):
    exe, path, home = readonly_install
    r = _as_nobody([exe, "-m", "creep_online", "--help"], {"HOME": str(home), "PYTHONPATH": path})
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "identify" in r.stdout


@pytest.mark.parametrize("home_kind", ["writable", "missing"])
def test_kernels_compile_and_cache_in_a_per_user_dir(readonly_install, home_kind):
    exe, path, home = readonly_install
    env = {"PYTHONPATH": path, "HOME": str(home) if home_kind == "writable" else "/nonexistent"}
    r = _as_nobody([exe, "-c", SCRIPT], env)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-2000:]
    ok, positive, cache_dir = r.stdout.split()
    assert ok == "ok" and positive == "True"
    if home_kind == "writable":
        assert cache_dir == str(home / ".cache" / "creep_online" / "numba")
        assert any((home / ".cache" / "creep_online" / "numba").rglob("*.nbi"))
    else:
        assert "creep_online" in cache_dir
