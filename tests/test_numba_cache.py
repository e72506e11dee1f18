"""Compiled kernels are never stale: ``_numba_cache.clear_stale_kernels`` against a package laid out in a temporary
directory (its modules and numba's cache files), and the real package's caches against ``KERNEL_MODULES``."""
from __future__ import annotations

import os
from pathlib import Path

from creep_online import _numba_cache as C

MODULES = ("kernels.py", "online/_kernels/layout.py", "online/_kernels/window.py")


def _package(root: Path) -> Path:
    package = root / "pkg"
    for name in MODULES:
        (package / name).parent.mkdir(parents=True, exist_ok=True)
        (package / name).write_text("X = 1\n")
    return package


def _compiled(package: Path, cache_root: str | None) -> list[Path]:
    """Two cache files per module where numba would put them, and one of a module not in MODULES."""
    out = []
    for name in MODULES + ("online/_kernels/other.py",):
        source = package / name
        folder = C.cache_dir_of(source.parent, cache_root)
        folder.mkdir(parents=True, exist_ok=True)
        for suffix in ("py311.nbi", "py311.1.nbc"):
            path = folder / f"{source.stem}.kernel-10.{suffix}"
            path.write_bytes(b"x")
            out.append(path)
    return out


def test_a_changed_kernel_module_clears_every_kernel_modules_compiled_kernels_once(tmp_path):
    """No stamp yet: everything of the kernel modules is cleared (a cache of unknown age), the other module's kept;
    the same sources again: nothing; one module edited (another size): all of them again, in __pycache__ and under
    a NUMBA_CACHE_DIR alike."""
    package = _package(tmp_path)
    for cache_root in (None, str(tmp_path / "cache")):
        files = _compiled(package, cache_root)
        assert C.clear_stale_kernels(package, MODULES, cache_root) == 6
        assert [p.exists() for p in files] == [False] * 6 + [True] * 2
        files = _compiled(package, cache_root)
        assert C.clear_stale_kernels(package, MODULES, cache_root) == 0
        assert all(p.exists() for p in files)
        (package / "online/_kernels/layout.py").write_text("X = 22\n")
        assert C.clear_stale_kernels(package, MODULES, cache_root) == 6
        assert [p.exists() for p in files] == [False] * 6 + [True] * 2


def test_every_compiled_kernel_of_the_package_is_a_kernel_modules():
    """After the online kernels are loaded (``warm_kernels``), every cache file in the package's cache directories
    belongs to a module of ``KERNEL_MODULES``: a module whose functions numba compiles and that the stamp does not
    watch would keep stale constants after an edit."""
    from creep_online.online import warm_kernels
    warm_kernels()
    package = C.PACKAGE_DIR
    watched = {(C.cache_dir_of((package / m).parent), Path(m).stem) for m in C.KERNEL_MODULES}
    folders = {C.cache_dir_of(Path(root)) for root, _, _ in os.walk(package) if "__pycache__" not in root}
    found = [(folder, path.name.split(".")[0]) for folder in folders if folder.is_dir()
             for path in folder.glob("*.nb[ci]")]
    assert found
    assert set(found) <= watched, sorted(set(found) - watched)
