"""The one-way layer rule, read from the source (imports inside functions count too).

errors <- model (CreepModel, ExtendedModel, simulate, effects) <- {io, identification, online}
<- diagnostics <- reports <- commands / cli. ``hil_sim`` imports creep_online, never the reverse
(only the demo command starts it).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "creep_online"

#: Layer of each top-level module or sub-package (a module may import its own layer and those below).
LAYERS = {
    "errors": 0,
    "_numba_cache": 1, "_threads": 1, "kernels": 1, "discretize": 1, "metrics": 1, "record": 1,
    "model": 1, "effects": 1, "simulate": 1, "plants": 1,
    "io": 2, "identification": 2, "online": 2,
    "global_fit": 2, "initial_state": 2, "timing": 2, "validation": 2,
    "diagnostics": 3,
    "reports": 4,
    "commands": 5, "cli": 5, "__main__": 5, "__init__": 5,
}
#: The only library modules allowed to import the simulated plant.
MAY_IMPORT_HIL_SIM = {"creep_online.commands.demo"}


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _runtime_nodes(tree: ast.AST):
    """Every node except those under ``if TYPE_CHECKING:`` (annotations only, never imported at run time)."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            yield from (n for child in node.orelse for n in [child, *_runtime_nodes(child)])
            continue
        yield node
        yield from _runtime_nodes(node)


def _imports(path: Path) -> set[str]:
    """Absolute names of every module ``path`` imports at run time (relative imports resolved)."""
    name = _module_name(path)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out = set()
    for node in _runtime_nodes(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                out |= {target} if node.module else {f"{target}.{a.name}" for a in node.names}
            else:
                out.add(node.module or "")
    return out


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "creep_online":
        return None
    return LAYERS.get(parts[1] if len(parts) > 1 else "__init__")


MODULES = sorted(PACKAGE.rglob("*.py"))


def test_every_module_has_a_layer():
    assert {p.relative_to(PACKAGE).parts[0].removesuffix(".py") for p in MODULES} <= set(LAYERS)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_point_down(path):
    name = _module_name(path)
    own = _layer(name) if path.name != "__init__.py" or name != "creep_online" else LAYERS["__init__"]
    upward = sorted(m for m in _imports(path) if (_layer(m) or 0) > own)
    assert not upward, f"{name} (layer {own}) imports from above: {upward}"
    if name not in MAY_IMPORT_HIL_SIM:
        assert not [m for m in _imports(path) if m.split(".")[0] == "hil_sim"], f"{name} imports hil_sim"


def test_effects_do_not_import_the_model_module():
    """model.py builds on the effects (ExtendedModel); the effects need only a model's four parameters."""
    for path in (PACKAGE / "effects").glob("*.py"):
        assert "creep_online.model" not in _imports(path), path.name
