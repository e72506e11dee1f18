"""The one-way layer rule: errors <- model (CreepModel, ExtendedModel, simulate, effects) <- {io, fit, online}
<- diagnostics <- reports <- commands / cli. ``hil_sim`` imports creep_online, never the reverse (only the
demo command starts it).

The rule is written once, as the import-linter contracts in ``pyproject.toml`` (``[tool.importlinter]``);
both checks here read it from there, so they cannot disagree:

- ``test_import_linter_contracts`` runs import-linter (the ``test`` extra installs it). It follows chains
  of imports, so it also catches an upward path through another package (e.g. through ``hil_sim``) and
  an effect reaching ``model.py`` indirectly.
- The AST checks read every module's own import statements (imports inside functions count, those under
  ``if TYPE_CHECKING:`` do not, as in the contracts). They see what import-linter cannot: a module taking
  a name from the package root (``from creep_online import identify``), which the root's ``__getattr__``
  resolves by importing a higher layer; import-linter sees that only as an import of the container.
"""
from __future__ import annotations

import ast
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "creep_online"
PYPROJECT = ROOT / "pyproject.toml"


def _contracts() -> dict[str, dict]:
    config = tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]
    return {c["id"]: c for c in config["contracts"]}


CONTRACTS = _contracts()

#: Layer of each top-level module or sub-package (a module may import its own layer and those below),
#: from the contract's list (highest first); the package root's ``__init__`` stands above them all.
LAYERS = {tail.strip(): rank
          for rank, layer in enumerate(reversed(CONTRACTS["layers"]["layers"]))
          for tail in layer.split(":")}
LAYERS["__init__"] = len(CONTRACTS["layers"]["layers"])
#: The only library modules allowed to import the simulated plant (the contract's one ignored import).
MAY_IMPORT_HIL_SIM = {rule.split("->")[0].strip() for rule in CONTRACTS["no-hil-sim"]["ignore_imports"]}


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


def test_import_linter_contracts():
    """The contracts in pyproject.toml hold (what `lint-imports` checks; CI runs only pytest)."""
    from importlinter.cli import lint_imports  # the `test` extra installs import-linter

    assert set(CONTRACTS) == {"layers", "no-hil-sim", "effects-not-model", "online-policy-pure", "online-kernels-below",
                              "online-kernels-private", "online-tracker-protocol"}
    saved = sys.path[:]                    # lint_imports puts the working directory on sys.path
    try:
        status = lint_imports(config_filename=str(PYPROJECT), no_cache=True, no_logo=True)
    finally:
        sys.path[:] = saved
    assert status == 0, "an import-linter contract is broken: see the captured output above"


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
    contract = CONTRACTS["effects-not-model"]
    assert contract["source_modules"] == ["creep_online.effects"]
    assert contract["forbidden_modules"] == ["creep_online.model"]
    for path in (PACKAGE / "effects").glob("*.py"):
        assert "creep_online.model" not in _imports(path), path.name


@pytest.mark.parametrize("contract", ["online-policy-pure", "online-tracker-protocol"])
def test_the_online_rules_and_the_estimator_import_no_tracker_module(contract):
    """The online policy modules, and the estimator's own modules, import none of the forbidden modules in their
    own statements (the tracker protocol's contract allows them only through the start-up, which builds trackers)."""
    rule = CONTRACTS[contract]
    forbidden = set(rule["forbidden_modules"])
    for source in rule["source_modules"]:
        base = PACKAGE.parent / Path(*source.split("."))
        paths = sorted(base.glob("*.py")) if base.is_dir() else [base.with_suffix(".py")]
        assert paths, source
        for path in paths:
            hits = {m for m in _imports(path) for f in forbidden if m == f or m.startswith(f + ".")}
            assert not hits, f"{_module_name(path)} imports {sorted(hits)}"
