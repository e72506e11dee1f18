"""What the public API takes as a number, a count or an array: checked in one place, DataError otherwise.

A number is a Python ``int`` or ``float`` or a numpy integer or floating
scalar of any width (``np.float32`` included); ``bool``, strings, bytes,
complex numbers, dates and ``None`` are not numbers here, even where
``float()`` would convert them (``float("1.0")``, ``float(True)``): a value of
the wrong kind is a mistake of the caller, said in one line, never silently
read. An array is anything numpy turns into a real numeric array of the
documented shape; boolean, complex, date, text and object arrays are refused
for the same reason.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from .errors import DataError

#: numpy dtype kinds that are real numbers (signed, unsigned, floating).
_REAL_KINDS = "iuf"


def is_real(x: object) -> bool:
    """Is ``x`` a real number (int, float, Fraction, numpy integer/floating of any width), not a bool?"""
    return isinstance(x, (numbers.Real, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def number(x: object, name: str) -> float:
    """``x`` as a float, or DataError when it is not a real number or too large for a float."""
    if not is_real(x):
        raise DataError(f"{name} must be a number, got {_shown(x)}")
    try:
        return float(x)
    except OverflowError:
        raise DataError(f"{name} is too large for a floating-point number, got {_shown(x)}") from None


def finite(x: object, name: str) -> float:
    """``x`` as a finite float, or DataError."""
    value = number(x, name)
    if not math.isfinite(value):
        raise DataError(f"{name} must be a finite number, got {_shown(x)}")
    return value


def positive(x: object, name: str, *, maximum: float | None = None, unit: str = "") -> float:
    """``x`` as a finite float > 0 (and <= ``maximum`` when given), or DataError."""
    value = number(x, name)
    if not (math.isfinite(value) and value > 0):
        raise DataError(f"{name} must be a positive finite number{unit}, got {_shown(x)}")
    if maximum is not None and value > maximum:
        raise DataError(f"{name} must be at most {maximum:g}{unit}, got {_shown(x)}")
    return value


def count(x: object, name: str, *, minimum: int = 1, maximum: int | None = None) -> int:
    """``x`` as an int >= ``minimum`` (an integer or an integral float), or DataError."""
    if isinstance(x, (float, np.floating)) and is_real(x) and math.isfinite(x) and float(x).is_integer():
        x = int(x)
    if not isinstance(x, (int, np.integer)) or isinstance(x, (bool, np.bool_)):
        raise DataError(f"{name} must be a whole number, got {_shown(x)}")
    value = int(x)
    if value < minimum or (maximum is not None and value > maximum):
        upper = f" and at most {maximum}" if maximum is not None else ""
        raise DataError(f"{name} must be at least {minimum}{upper}, got {_shown(x)}")
    return value


def real_array(x: object, name: str, *, ndim: int | None = 1) -> np.ndarray:
    """``x`` as a float64 array of ``ndim`` dimensions (any when None), or DataError: no text, bool, complex,
    date or object data, no ragged nesting."""
    if x is None or isinstance(x, (str, bytes, bytearray, dict, set)):
        raise DataError(f"{name} must be an array of numbers, got {type(x).__name__}")
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name} must be an array of numbers ({str(exc).splitlines()[0][:80]})") from None
    if a.dtype.kind not in _REAL_KINDS and not (a.size == 0 and a.dtype.kind in "OU"):
        if not (a.dtype.kind == "O" and all(is_real(v) for v in a.ravel().tolist())):
            raise DataError(f"{name} must hold real numbers, got {_kind(a.dtype)} data")
    if ndim is not None and a.ndim != ndim:
        raise DataError(f"{name} must be {ndim}-dimensional, got shape {a.shape}")
    try:
        return np.asarray(a, dtype=float)
    except (OverflowError, TypeError, ValueError):
        raise DataError(f"{name} holds a number too large for a floating-point value") from None


def _kind(dtype: np.dtype) -> str:
    return {"b": "boolean", "c": "complex", "M": "date-time", "m": "time-delta", "U": "text", "S": "bytes",
            "O": "object", "V": "structured"}.get(dtype.kind, str(dtype))


def _shown(x: object) -> str:
    text = repr(x)
    return text if len(text) <= 60 else text[:57] + "..."
