"""Helpers shared by the sub-commands: JSON output and parameter parsing."""
from __future__ import annotations

import sys
from typing import Any

from ..io.jsonable import json_text
from ..io.params import parse_params

__all__ = ["print_json", "parse_params", "add_column_options"]


def add_column_options(parser) -> None:
    """``--u-column`` / ``--y-column``: the same two flags in every command that reads a record file."""
    parser.add_argument("--u-column", default=None, metavar="NAME",
                        help="input column: a CSV header name (default u) or, in a PI GCS data-recorder file, "
                             "a NAMEi text or NAMEi itself (default NAME0)")
    parser.add_argument("--y-column", default=None, metavar="NAME",
                        help="output column: a CSV header name (default y) or a GCS NAMEi (default NAME1)")


def print_json(obj: Any) -> None:
    """Write one JSON document to stdout (non-finite numbers as null: ``creep_online.io.jsonable``)."""
    sys.stdout.write(json_text(obj))
    sys.stdout.write("\n")
