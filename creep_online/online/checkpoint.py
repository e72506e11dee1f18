"""Pickling and deep-copying the online objects at any moment, the copy continuing bit for bit.

A control application checkpoints its estimator (``pickle.dumps(est)``,
``copy.deepcopy(est)``) and expects the copy to go on exactly as the original
would. Two things stand in the way of plain pickling, and this module handles
both for every class that derives from :class:`Checkpointable`:

* **Background work is generators** (a search, a tracker's re-fit or
  re-search, the tracker's start), and generators cannot be pickled. Before
  its state is taken an object finishes that work now (``_checkpoint``: the
  original does it too, so original and copy are the same object from then
  on); a job that waits for samples still to come goes on with those already
  there.
* **State arrays share memory**: a tracker's scalars are a slice of its state
  vector, trackers share the estimator's sample ring, and numba kernels return
  views whose ``base`` is numba's own allocation, not an array. Pickle would
  copy each array on its own, and the copy's kernels would update arrays its
  Python side no longer reads. Here every group of arrays that overlap in
  memory is written as one block of bytes and its members as views of it
  (offset, shape, strides), so the copy's arrays overlap exactly as the
  original's did.

The whole object graph goes through one pickler (``__reduce_ex__`` returns its
bytes), so ``pickle``, ``copy.copy`` and ``copy.deepcopy`` all give the same
result.

A checkpoint carries the fingerprint of the state's layout (``state_layout``):
the compiled kernels index the state vectors without bounds checks, so a
checkpoint laid out by another version would be read at the wrong places, or
past the arrays' ends. Loading one whose layout differs (or is not recorded)
raises a one-line ``DataError`` instead.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib
import inspect
import io
import pickle
from collections import deque
from typing import Any

import numpy as np

from ..errors import DataError

#: The modules whose integer constants lay out the state vectors the compiled kernels index.
LAYOUT_MODULES = ("layout", "window", "recursive", "hysteresis", "fit_machine", "coefficients")


class Checkpointable:
    """Base of the objects that pickle and deep-copy at any moment (module docstring).

    Subclasses override ``_checkpoint`` (finish background work, so that no
    generator is left) and, for a state that needs rebuilding on load,
    ``_state`` / ``_restore_state``.
    """

    def _checkpoint(self) -> None:
        """Finish the background work under way (no generator may remain); nothing by default."""

    def _state(self) -> dict:
        """The state to pickle (after ``_checkpoint``)."""
        return dict(self.__dict__)

    def _restore_state(self, state: dict) -> None:
        """Take a state produced by ``_state``."""
        self.__dict__.update(state)

    def __reduce_ex__(self, protocol: int):
        return _loads, (dumps(self), state_layout())


def dumps(obj: Any) -> bytes:
    """``obj`` (a Checkpointable and what it holds) as bytes: background work finished, shared memory kept."""
    for item in _walk(obj):
        if isinstance(item, Checkpointable):
            item._checkpoint()
    buffer = io.BytesIO()
    _SharingPickler(buffer, _shared_views(obj)).dump(obj)
    return buffer.getvalue()


@functools.lru_cache(maxsize=1)
def state_layout() -> str:
    """A fingerprint of the online state's layout: every integer constant (an index into a state vector, a block's
    size) of the kernels' modules, with its module and name."""
    items = []
    for name in LAYOUT_MODULES:
        module = importlib.import_module(f"{__package__}._kernels.{name}")
        items += [f"{name}.{key}={value}" for key, value in sorted(vars(module).items())
                  if key.isupper() and type(value) is int]
    return hashlib.sha256("\n".join(items).encode()).hexdigest()[:16]


def _loads(data: bytes, layout: str | None = None) -> Any:
    """The object of a checkpoint, refused (``DataError``) when its state is laid out otherwise than here."""
    if layout != state_layout():
        raise DataError(f"this checkpoint's online state is laid out otherwise (layout {layout or 'not recorded'}, "
                        f"this creep_online's {state_layout()}): resume it with the version that wrote it, "
                        "or start a new estimator")
    return pickle.loads(data)


def _rebuild(cls: type, state: dict) -> Any:
    obj = cls.__new__(cls)
    obj._restore_state(state)
    return obj


def _view(block: np.ndarray, offset: int, shape: tuple, strides: tuple, dtype: np.dtype) -> np.ndarray:
    return np.ndarray(shape, dtype=dtype, buffer=block, offset=offset, strides=strides)


def _walk(obj: Any) -> list:
    """Every object reachable from ``obj`` through creep_online objects' attributes and plain containers."""
    seen: set[int] = set()
    out: list = []
    stack = [obj]
    while stack:
        item = stack.pop()
        if id(item) in seen:
            continue
        seen.add(id(item))
        out.append(item)
        if isinstance(item, (list, tuple, set, frozenset, deque)):
            stack.extend(item)
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif type(item).__module__.startswith("creep_online") and hasattr(item, "__dict__") \
                and not isinstance(item, type):
            stack.extend(vars(item).values())
    return out


def _extent(a: np.ndarray) -> tuple[int, int]:
    """[low, high) byte addresses ``a`` spans."""
    start = a.__array_interface__["data"][0]
    low = high = start
    for n, stride in zip(a.shape, a.strides):
        span = (n - 1) * stride
        low += min(span, 0)
        high += max(span, 0)
    return low, high + a.itemsize


def _shared_views(obj: Any) -> dict[int, tuple]:
    """id(array) -> (block, offset) for every array that overlaps another one in memory (``block``: a copy of
    the bytes the group spans, of which each member is rebuilt as a view)."""
    arrays = [a for a in _walk(obj) if isinstance(a, np.ndarray) and a.size and a.dtype.kind in "biufc"]
    spans = sorted((_extent(a) + (a,) for a in arrays), key=lambda s: s[0])
    groups: list[list] = []
    for low, high, a in spans:
        if groups and low < groups[-1][1]:
            groups[-1][1] = max(groups[-1][1], high)
            groups[-1][2].append((low, a))
        else:
            groups.append([low, high, [(low, a)]])
    views: dict[int, tuple] = {}
    for low, high, members in groups:
        if len(members) < 2:
            continue
        block = np.frombuffer((ctypes.c_char * (high - low)).from_address(low), dtype=np.uint8).copy()
        for _, a in members:
            views[id(a)] = (block, a.__array_interface__["data"][0] - low)
    return views


class _SharingPickler(pickle.Pickler):
    """Reduces Checkpointable objects by their ``_state`` and the arrays of ``views`` as views of their block."""

    def __init__(self, file: io.BytesIO, views: dict[int, tuple]) -> None:
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self._views = views

    def reducer_override(self, obj: Any):
        if isinstance(obj, Checkpointable):
            return _rebuild, (type(obj), obj._state())
        if isinstance(obj, np.ndarray):
            shared = self._views.get(id(obj))
            if shared is not None:
                block, offset = shared
                return _view, (block, offset, obj.shape, obj.strides, obj.dtype)
            return NotImplemented
        if inspect.isgenerator(obj):
            raise pickle.PicklingError(f"background work under way ({obj.__qualname__}) could not be finished "
                                       "before the checkpoint")
        return NotImplemented
