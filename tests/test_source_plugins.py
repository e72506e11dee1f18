"""Sources as plug-ins: the registry, per-source options, and a third-party source streamed by the CLI.

The third-party source is ``tests/plugins/toy_creep_source.py`` (not part of
the package). It is added once through ``register_source`` and once through
an entry point of a tiny distribution installed into a temporary folder on
``PYTHONPATH`` (a real ``.dist-info`` that ``importlib.metadata`` finds), then
``creep-online stream`` runs on it in a separate process.
"""
from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from creep_online.cli import main
from creep_online.errors import DataError, TransportError
from creep_online.io import registry
from creep_online.io.registry import available_sources, open_source, register_source, unregister_source

PLUGINS = Path(__file__).parent / "plugins"
REPO = Path(__file__).resolve().parents[1]
TOY_MODEL = "alpha=0.06,fn=6,zeta=0.1,b=0.02"
DROP = 97            # the toy loses every 97th sample
N = 2400


@pytest.fixture
def toy_registered(monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))
    register_source("toy", "toy_creep_source:ToyCreepSource")
    yield
    unregister_source("toy")


def _installed_distribution(folder: Path, entry_points: str) -> Path:
    """A minimal installed distribution ``toy-sources`` whose metadata declares ``entry_points``."""
    info = folder / "toy_sources-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-sources\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[creep_online.sources]\n{entry_points}\n")
    return folder


def _stream_in_subprocess(site: Path, spec: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(PLUGINS), str(REPO)]))
    return subprocess.run([sys.executable, "-m", "creep_online", "stream", "--json", "--source", spec],
                          capture_output=True, text=True, env=env, timeout=300)


def _check_toy_stream(out: dict) -> None:
    lost = N // DROP
    assert out["end"] == {"reason": "end_of_stream", "exit_code": 0, "message": ""}
    assert out["source_stats"]["samples"] == N - lost and out["source_stats"]["missing"] == lost
    assert out["gaps"] == lost and out["samples"] == N          # gaps reached the estimator as lost samples
    assert out["alpha"] == pytest.approx(0.06, rel=0.03)


# ------------------------------------------------------------------ third-party source, end to end
def test_registered_source_streams_through_the_cli(toy_registered, capsys):
    assert main(["stream", "--json", "--source", f"toy:{TOY_MODEL}?drop={DROP}"]) == 0
    _check_toy_stream(json.loads(capsys.readouterr().out))


def test_entry_point_source_streams_through_the_cli(tmp_path):
    site = _installed_distribution(tmp_path, "toy = toy_creep_source:ToyCreepSource")
    proc = _stream_in_subprocess(site, f"toy:{TOY_MODEL}?drop={DROP}&rate=200")
    assert proc.returncode == 0, proc.stderr
    _check_toy_stream(json.loads(proc.stdout))


def test_entry_point_source_is_listed_and_cannot_shadow_a_builtin(tmp_path, monkeypatch):
    site = _installed_distribution(tmp_path, "toy = toy_creep_source:ToyCreepSource\n"
                                             "serial = toy_creep_source:ToyCreepSource")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(PLUGINS))
    registry.refresh_entry_points()
    try:
        table = available_sources()
        assert table["toy"] == "toy_creep_source:ToyCreepSource"
        assert table["serial"] == registry.BUILTIN_SOURCES["serial"]
        with open_source(f"toy:{TOY_MODEL}?samples=10", on_event=None) as src:
            assert type(src).__name__ == "ToyCreepSource" and len(src.read()) == 10
    finally:
        monkeypatch.undo()
        registry.refresh_entry_points()
    assert "toy" not in available_sources()


def test_entry_point_whose_module_is_missing_is_a_one_line_error(tmp_path):
    site = _installed_distribution(tmp_path, "ghost = no_such_module_here:Ghost")
    proc = _stream_in_subprocess(site, "ghost:x")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1     # with --json: one JSON object
    assert json.loads(proc.stderr) == {"command": "stream", "type": "TransportError", "exit_code": 2,
                                       "error": "source kind 'ghost' needs no_such_module_here, which is not installed"}


# ------------------------------------------------------------------ options are the source's own
def test_unknown_option_names_the_sources_options(toy_registered, capsys):
    assert main(["stream", "--source", f"toy:{TOY_MODEL}?baud=9600"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "unknown option 'baud'" in err and "(options: drop, noise, rate, samples)" in err


@pytest.mark.parametrize("spec, words", [
    (f"toy:{TOY_MODEL}?samples=many", "option samples='many' is not valid"),
    ("csv:x.csv?rate=100", "unknown option 'rate'"),
    ("canlog:x.asc?reconnect=0", "unknown option 'reconnect'"),
    ("serial:/dev/ttyUSB9?dbc=a.dbc", "unknown option(s) 'dbc=a.dbc' for a serial port"),
    ("serial:/dev/ttyUSB9?format=bin", "expected one of auto, ascii, binary"),
    ("serial:/dev/ttyUSB9?reconnect=maybe", "option reconnect='maybe' is not valid"),
    ("nosuch:thing", "unknown source kind 'nosuch' (csv, serial, can, canlog, pi, capancdt, toy)"),
    ("toy:", "missing model parameters after 'toy:'"),
])
def test_bad_specs_are_one_line_errors(toy_registered, capsys, spec, words):
    assert main(["stream", "--source", spec]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err


def test_pyserial_url_keeps_its_own_options():
    with open_source("serial:loop://?logging=debug&rate=100&reconnect=0", on_event=None) as src:
        assert src.port == "loop://?logging=debug" and src.rate == 100.0 and src.reconnect is False


@pytest.mark.parametrize("kind", sorted(registry.BUILTIN_SOURCES))
def test_declared_defaults_are_the_constructors(kind):
    cls = registry.source_class(kind)
    for option in cls.options:
        assert option.default == _constructor_default(cls, option.argument), (kind, option.name)


def _constructor_default(cls: type, name: str):
    """The default of keyword ``name`` in the first __init__ along the MRO that names it."""
    for klass in cls.__mro__:
        params = inspect.signature(klass.__init__).parameters if "__init__" in vars(klass) else {}
        if name in params:
            return params[name].default
    raise AssertionError(f"{cls.__name__} takes no keyword {name!r}")


# ------------------------------------------------------------------ the registry itself
def test_register_refuses_a_taken_name_unless_replacing(toy_registered):
    with pytest.raises(ValueError, match="already registered"):
        register_source("serial", "toy_creep_source:ToyCreepSource")
    with pytest.raises(ValueError, match="module:Class"):
        register_source("toy2", "toy_creep_source")
    register_source("toy", "toy_creep_source:ToyCreepSource", replace=True)


def test_a_class_that_is_not_a_source_is_refused(toy_registered):
    register_source("notasource", "toy_creep_source:Option")
    try:
        with pytest.raises(TransportError, match="not a SampleSource subclass"):
            open_source("notasource:x")
    finally:
        unregister_source("notasource")


def test_base_module_imports_no_concrete_source():
    code = ("import sys, creep_online.io.sources as s, creep_online.errors as e; "
            "assert s.TransportError is e.TransportError; "
            "print(sorted(m for m in sys.modules if m.endswith('_source')))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


def test_unknown_kind_is_a_data_error():
    with pytest.raises(DataError, match="unknown source kind 'nope'"):
        open_source("nope:x")
