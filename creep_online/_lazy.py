"""Attributes of a package that load their module on first use (PEP 562).

numba and scipy take ~1 s to import: the package root and the effects keep
them out of ``import creep_online`` (and of the CLI's ``--help``) this way.
"""
from __future__ import annotations

import importlib
from typing import Any, Callable


def lazy_attributes(package: str, table: dict[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__``: ``name`` in ``table`` is imported from the submodule ``table[name]``."""

    def __getattr__(name: str) -> Any:
        if name in table:
            return getattr(importlib.import_module(f".{table[name]}", package), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
