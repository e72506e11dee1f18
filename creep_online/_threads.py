"""Keep BLAS single-threaded around the many tiny linear-algebra calls of a fit.

The matrices here are 2x2 to 10x10 and the vectors a few 10^5 long; a
multi-threaded BLAS only adds synchronisation. Measured on the 2-core machine:
a 12,000-sample identification took 0.22 s with OpenBLAS threads and 0.035 s
without. ``threadpoolctl`` (when installed, as the package requires) limits
the threads for the duration of a call, whatever the user imported before us;
without it the environment default set in ``creep_online/__init__`` applies.
"""
from __future__ import annotations

import contextlib
import functools
from typing import Callable, ContextManager, TypeVar

try:  # optional at import time: the core runs on numpy/scipy/numba alone
    from threadpoolctl import ThreadpoolController
except ImportError:  # pragma: no cover - exercised only without the dependency
    ThreadpoolController = None

_controller = None


def single_threaded_blas() -> ContextManager:
    """Context manager limiting BLAS to one thread (no-op without threadpoolctl).

    The controller is built once: discovering the loaded libraries reads
    /proc and cost ~1.3 ms per call, a third of a small identification.
    """
    global _controller
    if ThreadpoolController is None:
        return contextlib.nullcontext()
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")


F = TypeVar("F", bound=Callable)


def single_threaded(fn: F) -> F:
    """Decorator: run ``fn`` with BLAS limited to one thread."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_threaded_blas():
            return fn(*args, **kwargs)
    return wrapper  # type: ignore[return-value]
