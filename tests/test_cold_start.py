"""What the program and the package import before they need it: behaviour, not timing.

``creep-online --help``, ``--version`` and ``identify --help`` print from argparse alone, so they load
neither numpy nor scipy nor numba (the other commands' --help: no scipy or numba); ``import creep_online``
loads only its errors, and every public name still imports as before (bench/bench_cold_start.py measures the time this saves).
"""
from __future__ import annotations

import subprocess
import sys

import pytest

import creep_online

HEAVY = ("numpy", "scipy", "numba", "rich", "pandas", "dask")


def _run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          timeout=120).stdout.strip()


def _loaded_after(argv: list[str]) -> str:
    """The heavy modules in sys.modules after the CLI's ``main(argv)`` in a fresh interpreter."""
    return _run("import io, sys, contextlib\nfrom creep_online.cli import main\n"
                f"with contextlib.redirect_stdout(io.StringIO()) as out:\n    code = main({argv!r})\n"
                "assert code == 0 and out.getvalue(), (code, out.getvalue())\n"
                f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")


@pytest.mark.parametrize("argv", [["--help"], ["--version"], ["identify", "--help"], ["batch", "--help"]])
def test_help_and_version_import_no_numpy_scipy_or_numba(argv):
    assert _loaded_after(argv) == "[]"


@pytest.mark.parametrize("command", ["simulate", "stream", "diagnose", "fit", "demo", "compare"])
def test_command_help_imports_no_scipy_or_numba(command):
    loaded = _loaded_after([command, "--help"])
    assert "scipy" not in loaded and "numba" not in loaded, loaded


def test_the_program_prints_its_help_without_numpy():
    out = _run("import runpy, sys, io, contextlib\nsys.argv = ['creep-online', '--help']\n"
               "buf = io.StringIO()\ntry:\n    with contextlib.redirect_stdout(buf):\n"
               "        runpy.run_module('creep_online', run_name='__main__')\n"
               "except SystemExit as stop:\n    assert stop.code == 0, stop.code\n"
               "assert 'identify' in buf.getvalue()\nprint('numpy' in sys.modules)")
    assert out == "False"


def test_import_creep_online_loads_only_the_errors():
    assert _run(f"import sys, creep_online\nprint(sorted(m for m in {HEAVY!r} if m in sys.modules))") == "[]"


@pytest.mark.parametrize("name", creep_online.__all__)
def test_every_public_name_imports_from_the_package(name):
    value = _run(f"from creep_online import {name}\nprint(type({name}).__name__, {name}.__module__)")
    kind, module = value.split()
    assert kind in ("type", "function") and module.startswith("creep_online.")


def test_public_names_are_the_objects_their_modules_define():
    from creep_online import identification, model, record
    from creep_online import simulate as simulate_module_or_function
    assert creep_online.CreepModel is model.CreepModel and creep_online.Record is record.Record
    assert creep_online.identify is identification.identify
    assert callable(simulate_module_or_function) and simulate_module_or_function.__name__ == "simulate"
    assert set(creep_online.__all__) <= set(dir(creep_online))


def test_loading_the_simulate_module_first_keeps_the_simulate_function():
    """``creep_online.simulate`` is the function (as the package exported it eagerly), whichever loads first."""
    out = _run("import creep_online.simulate, creep_online\nfrom creep_online import simulate\n"
               "import creep_online.simulate as again\nprint(simulate.__name__, type(simulate).__name__, "
               "again is simulate, creep_online.simulate is simulate)")
    assert out == "simulate function True True"


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        creep_online.nonexistent  # noqa: B018
    with pytest.raises(ImportError):
        exec("from creep_online import nonexistent", {})
