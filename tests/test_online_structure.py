"""The online estimator's structure: small classes, short orchestration files, a tracker used only through its
declared protocol (``online/trackers/protocol.py``)."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from creep_online.online.trackers import protocol

ONLINE = Path(__file__).resolve().parents[1] / "creep_online" / "online"
#: The estimator's orchestration: the API, the start-up, the input stage, the recovery, the report, the rules.
ORCHESTRATION = ["estimator.py", "startup.py", "handover.py", "inputs.py", "recovery.py", "report.py", "settings.py",
                 "policy/quality.py", "policy/input_gate.py", "trackers/protocol.py"]
#: The modules that hold a tracker only as a ``Tracker``.
PROTOCOL_USERS = ["estimator.py", "inputs.py", "recovery.py", "report.py"]


def _tree(name: str) -> ast.Module:
    return ast.parse((ONLINE / name).read_text())


@pytest.mark.parametrize("name", ORCHESTRATION)
def test_no_class_over_25_methods_and_no_file_over_500_lines(name):
    assert len((ONLINE / name).read_text().splitlines()) <= 500
    for node in ast.walk(_tree(name)):
        if isinstance(node, ast.ClassDef):
            methods = [m for m in node.body if isinstance(m, (ast.FunctionDef, ast.AsyncFunctionDef))]
            assert len(methods) <= 25, (node.name, len(methods))


def _protocol_members() -> set[str]:
    members = set()
    for node in ast.walk(ast.parse(Path(protocol.__file__).read_text())):
        if isinstance(node, ast.ClassDef) and node.name == "Tracker":
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    members.add(item.name)
                elif isinstance(item, ast.AnnAssign):
                    members.add(item.target.id)
    return members


@pytest.mark.parametrize("name", PROTOCOL_USERS)
def test_a_tracker_is_used_only_through_the_protocol(name):
    """Every attribute read or called on a tracker (``tr``, ``tracker``, ``self._tracker``, ``self._live``,
    ``est._tracker``, ``est._live``) is a member of ``Tracker``; no module here names a tracker class."""
    members = _protocol_members()
    tree = _tree(name)
    used = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        v = node.value
        if (isinstance(v, ast.Name) and v.id in ("tr", "tracker")) or \
                (isinstance(v, ast.Attribute) and v.attr in ("_tracker", "_live")):
            used.add(node.attr)
        if isinstance(node.value, ast.Name) and node.attr in ("WindowTracker", "RecursiveTracker"):
            pytest.fail(f"{name} names {node.attr}")
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    assert not names & {"WindowTracker", "RecursiveTracker"}, name
    assert used and used <= members, sorted(used - members)
