"""Attributes of a package that load their module on first use (PEP 562).

numpy, numba and scipy take from ~40 ms to ~1 s to import: the package root and
the effects keep them out of ``import creep_online`` (and of the CLI's
``--help``) this way.
"""
from __future__ import annotations

import importlib
import sys
import types
from typing import Any, Callable


def lazy_attributes(package: str, table: dict[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__``: ``name`` in ``table`` is imported from the submodule ``table[name]``.

    The value is kept in the package once loaded. A name that is also a submodule's (``simulate``, the
    function in ``simulate.py``) stays the function: the package's class is changed so that loading the
    submodule, which binds the submodule to its name in the package, does not replace the function.
    """
    module = sys.modules[package]
    module.__class__ = _keeping(module.__class__, frozenset(table))

    def __getattr__(name: str) -> Any:
        if name in table:
            value = getattr(importlib.import_module(f".{table[name]}", package), name)
            vars(module)[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


def _keeping(base: type, names: frozenset[str]) -> type:
    """A module class whose attributes in ``names`` are never bound to a submodule."""

    class LazyPackage(base):  # type: ignore[misc, valid-type]
        def __setattr__(self, name: str, value: Any) -> None:
            if name in names and isinstance(value, types.ModuleType):
                return      # a submodule named like a lazy attribute: the attribute keeps its meaning
            super().__setattr__(name, value)

    return LazyPackage
