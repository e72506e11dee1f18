"""Constructor parameters stored verbatim, read and changed as scikit-learn and river estimators do.

``OnlineEstimator``, ``CreepCompensator`` and ``ModelGate`` store every
constructor argument under its own name, unchanged, and build derived values
in ``reset()``. ``StoredParams`` gives them, from the constructor's signature:

- ``get_params(deep=True)``: the arguments as given (``deep`` adds those of
  arguments that have parameters themselves, as ``name__sub``);
- ``set_params(**params)``: checked like the constructor's, then ``reset()``
  (derived values are rebuilt from the new settings, so what was learned goes:
  the object is the one the constructor would make); returns the object;
- ``clone(new_params=None)``: river's form, a new object with the same
  (deep-copied) parameters, some replaced; ``sklearn.base.clone`` works too;
- a ``repr`` that names the parameters differing from their defaults
  (scikit-learn's rule: compared by ``repr``).

A name that is not a parameter is a one-line ``DataError`` listing the names.
"""
from __future__ import annotations

import copy
import inspect
import math
from typing import Any, TypeVar

from ..errors import DataError

#: Parameter separator of nested names (``model__alpha``), as in scikit-learn.
NESTED = "__"

_T = TypeVar("_T", bound="StoredParams")


class StoredParams:
    """Parameter conventions for a class whose constructor stores each argument as an attribute of its name."""

    @classmethod
    def _param_names(cls) -> list[str]:
        return [name for name, p in inspect.signature(cls.__init__).parameters.items()
                if name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]

    @classmethod
    def _defaults(cls) -> dict[str, Any]:
        return {name: p.default for name, p in inspect.signature(cls.__init__).parameters.items()
                if name != "self" and p.default is not p.empty}

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Constructor arguments as given (``type(self)(**self.get_params(deep=False))`` is an equal object).

        ``deep``: also the parameters of arguments that have them (``get_params``), named ``arg__param``."""
        params = {name: getattr(self, name) for name in self._param_names()}
        if deep:
            for name, value in list(params.items()):
                if hasattr(value, "get_params") and not isinstance(value, type):
                    params.update((f"{name}{NESTED}{k}", v) for k, v in value.get_params(deep=True).items())
        return params

    def set_params(self: _T, **params: Any) -> _T:
        """Change constructor arguments (checked as the constructor checks them) and ``reset()``; returns self.

        Unknown names, or a bad value, are a one-line ``DataError`` and leave the object unchanged (a nested
        ``arg__param`` goes to the argument's own ``set_params``)."""
        if not params:
            return self
        own: dict[str, Any] = {}
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, sep, sub = key.partition(NESTED)
            self._check_name(name)
            if not sep:
                own[name] = value
            elif hasattr(getattr(self, name), "set_params"):
                nested.setdefault(name, {})[sub] = value
            else:
                raise DataError(f"{type(self).__name__}.{name} has no parameters of its own to set ({key!r})")
        before = {name: getattr(self, name) for name in own}
        for name, value in own.items():
            setattr(self, name, value)
        try:
            self._validate()
            for name, sub in nested.items():
                getattr(self, name).set_params(**sub)
        except Exception:
            for name, value in before.items():
                setattr(self, name, value)
            raise
        self.reset()
        return self

    def clone(self: _T, new_params: dict[str, Any] | None = None) -> _T:
        """A new object with this one's parameters (deep copies), those in ``new_params`` replaced (river's
        ``clone``); nothing learned is carried over."""
        params = {name: copy.deepcopy(value) for name, value in self.get_params(deep=False).items()}
        for name in new_params or {}:
            self._check_name(name)
        params.update(new_params or {})
        return type(self)(**params)

    def __repr__(self) -> str:
        defaults = self._defaults()
        shown = [f"{name}={value!r}" for name, value in self.get_params(deep=False).items()
                 if name not in defaults or _differs(value, defaults[name])]
        return f"{type(self).__name__}({', '.join(shown)})"

    def _check_name(self, name: str) -> None:
        names = self._param_names()
        if name not in names:
            raise DataError(f"{type(self).__name__} has no parameter {name!r}; its parameters: "
                            f"{', '.join(names) or 'none'}")

    def _validate(self) -> None:
        """Check the stored arguments (DataError); the classes with arguments override it."""

    def reset(self: _T) -> _T:  # pragma: no cover - every class using the mixin defines it
        raise NotImplementedError


def _differs(value: Any, default: Any) -> bool:
    """scikit-learn's rule for a changed parameter: a different ``repr`` (NaN equals NaN)."""
    if value is default:
        return False
    both_nan = isinstance(value, float) and isinstance(default, float) and math.isnan(value) and math.isnan(default)
    return repr(value) != repr(default) and not both_nan
