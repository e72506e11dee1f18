"""What every bench shares: the distribution summary, the JSON report writer and where results go.

Rule for results: one file per bench and table, ``bench/results/<what it measures>.json``, holding the
latest run; earlier runs live in git history, so a name never carries a commit id or a date.
"""
from __future__ import annotations

import json
import os
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any, Iterable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"

#: A commit id (7 to 40 hex digits with at least one digit) as one ``_``/``-`` separated word of a name.
_COMMIT_WORD = re.compile(r"(^|[_-])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}($|[_-])")


def dist(values: Iterable[float], per: float = 1.0) -> dict[str, float | int | None]:
    """p50/p99/max/mean/n of ``values`` divided by ``per`` (linear-interpolated percentiles); None for no values."""
    a = np.asarray(list(values) if not isinstance(values, np.ndarray) else values, dtype=float)
    if a.size == 0:
        return {"p50": None, "p99": None, "max": None, "mean": None, "n": 0}
    return {"p50": float(np.percentile(a, 50)) / per, "p99": float(np.percentile(a, 99)) / per,
            "max": float(a.max()) / per, "mean": float(a.mean()) / per, "n": int(a.size)}


def results_path(name: str) -> Path:
    """``bench/results/<name>.json``; ``name`` says what is measured (a commit id in it is refused)."""
    if _COMMIT_WORD.search(name) or "/" in name:
        raise ValueError(f"results name {name!r}: name what is measured, without commit ids or folders")
    return RESULTS / f"{name}.json"


def run_info(argv: list[str] | None = None) -> dict[str, Any]:
    """The command line, the package version, the load average and a UTC timestamp of this run."""
    from creep_online import __version__
    module = getattr(sys.modules.get("__main__"), "__spec__", None)
    prog = f"python -m {module.name}" if module is not None else f"python {sys.argv[0]}"
    args = sys.argv[1:] if argv is None else argv
    return {"command": " ".join([prog, *map(shlex.quote, args)]), "version": __version__,
            "load_average": list(os.getloadavg()), "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def write_report(doc: dict, out: str | os.PathLike | None = None, *, indent: int = 1, default: Any = float,
                 echo: bool = True, argv: list[str] | None = None) -> str:
    """Stamp ``doc`` with :func:`run_info` (key ``"run"``), print it (``echo``) and write it to ``out`` if given.

    ``default`` converts what json cannot (numpy scalars by default). Returns the JSON text.
    """
    doc.setdefault("run", run_info(argv))
    text = json.dumps(doc, indent=indent, default=default)
    if echo:
        print(text)
    if out:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(text + "\n")
    return text
