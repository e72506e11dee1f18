"""The one JSON normaliser: numpy and other non-JSON values to plain Python, non-finite numbers to null.

Every JSON the package writes (``--json`` on stdout, the demo's
``summary.json``) goes through :func:`jsonable`, so it is valid JSON (no
``NaN`` / ``Infinity`` tokens, which strict parsers refuse) and a missing
number reads as ``null`` everywhere.
"""
from __future__ import annotations

import json
import math
import os
from typing import Any

import numpy as np


def jsonable(obj: Any) -> Any:
    """Plain Python for ``json``: dict keys as str, tuples/arrays as lists, numpy scalars as Python
    numbers/bools, paths as str, and NaN/inf as None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def json_text(obj: Any, indent: int | None = 2) -> str:
    """``obj`` as one valid JSON document (see :func:`jsonable`); anything else unknown becomes its str()."""
    return json.dumps(jsonable(obj), indent=indent, allow_nan=False, default=str)
