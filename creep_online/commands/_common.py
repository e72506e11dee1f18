"""Helpers shared by the sub-commands: JSON output and parameter parsing."""
from __future__ import annotations

import sys
from typing import Any

from ..io.jsonable import json_text
from ..io.params import parse_params

__all__ = ["print_json", "parse_params"]


def print_json(obj: Any) -> None:
    """Write one JSON document to stdout (non-finite numbers as null: ``creep_online.io.jsonable``)."""
    sys.stdout.write(json_text(obj))
    sys.stdout.write("\n")
