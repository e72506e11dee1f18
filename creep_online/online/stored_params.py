"""Constructor parameters stored verbatim, as scikit-learn and river estimators keep them.

``OnlineEstimator`` and ``CreepCompensator`` store every constructor argument
under its own name and build derived values in ``reset()``; this base class
reads them back, so ``Cls(**obj.get_params())`` makes an equal object.
"""
from __future__ import annotations

import inspect


class StoredParams:
    """``get_params()`` from the constructor's signature (every argument is an attribute of that name)."""

    @classmethod
    def _param_names(cls) -> list[str]:
        return [p for p in inspect.signature(cls.__init__).parameters if p != "self"]

    def get_params(self) -> dict:
        """Constructor arguments as given (``type(self)(**self.get_params())`` is an equal object)."""
        return {name: getattr(self, name) for name in self._param_names()}
