"""Helpers shared by the sub-commands: JSON output and parameter parsing."""
from __future__ import annotations

import json
import math
import sys
from typing import Any

import numpy as np

from ..errors import CreepOnlineError, ModelError
from ..model import CreepModel


def _plain(obj: Any) -> Any:
    """numpy scalars/arrays to plain Python; non-finite floats to None (valid JSON)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def print_json(obj: Any) -> None:
    """Write one JSON document to stdout."""
    json.dump(_plain(obj), sys.stdout, indent=2)
    sys.stdout.write("\n")


def parse_params(text: str) -> CreepModel:
    """``alpha=..,a1=..,a2=..,b=..`` (b defaults to 1) to a CreepModel; one-line errors."""
    values: dict[str, float] = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        key, sep, val = item.partition("=")
        key = key.strip()
        if not sep or key not in ("alpha", "a1", "a2", "b"):
            raise CreepOnlineError(f"--params: expected alpha=..,a1=..,a2=..,b=.., got {item!r}")
        if key in values:
            raise CreepOnlineError(f"--params: {key} given twice")
        try:
            values[key] = float(val)
        except ValueError:
            raise CreepOnlineError(f"--params: {key} is not a number: {val!r}") from None
    missing = [k for k in ("alpha", "a1", "a2") if k not in values]
    if missing:
        raise CreepOnlineError(f"--params: missing {', '.join(missing)}")
    try:
        return CreepModel(**values)
    except ModelError as exc:
        raise CreepOnlineError(f"--params: {exc}") from None
