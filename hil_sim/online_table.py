"""Online, with the extended model (docs/measurements.md): hidden-effect records streamed through the plain and the extended estimator.

``python -m hil_sim.online_table [N] [SEEDS] [--cold]`` prints one JSON line
per (seed, effect): the batch residual before and after the extended fit and
the live online errors over the last quarter of the record, as multiples of
the true noise RMS. ``measure`` is one row (used by tests/test_diagnostics_online.py).
"""
from __future__ import annotations

import json
import math
import sys

import numpy as np

from creep_online.diagnostics.extended import fit_base, fit_extended, prepare
from creep_online.diagnostics.online import live_error
from creep_online.effects import EFFECTS

from .hidden_effects import hidden_dataset


def tail_rms(table: dict, fraction: float = 0.25) -> tuple[float, float]:
    """(plain, extended) RMS live error over the last ``fraction`` of the windows (NaN windows ignored)."""
    k = max(1, int(round(fraction * len(table["t"]))))
    out = []
    for key in ("base", "extended"):
        r = np.asarray(table[key][-k:], dtype=float)
        r = r[np.isfinite(r)]
        out.append(float(np.sqrt(np.mean(r * r))) if r.size else math.nan)
    return out[0], out[1]


def measure(effect: str | None, seed: int = 0, n: int = 20000, warm: bool = True) -> dict:
    """One row of the online table: a hidden-effect record, batch fits, both online runs.

    Live errors over the last quarter of the record, as multiples of the true noise RMS.
    """
    ds = hidden_dataset(effect, seed, n=n)
    data = prepare(ds.t, ds.u, ds.y)
    base = fit_base(data)
    fit = fit_extended(data, [effect], base) if effect else base
    params = fit.effect_params if effect else {}
    table = live_error(ds.t, ds.u, ds.y, params, window_s=1.0,
                       base_model=base.model if warm else None, extended_model=fit.model if warm else None)
    raw, comp = tail_rms(table)
    return {"effect": effect or "none", "seed": seed, "seconds": n * float(ds.t[1] - ds.t[0]),
            "batch_before": base.residual_rms / ds.noise_std, "batch_after": fit.residual_rms / ds.noise_std,
            "online_plain": raw / ds.noise_std, "online_extended": comp / ds.noise_std}


def main(argv: list[str] | None = None) -> int:
    """``python -m hil_sim.online_table [N] [SEEDS] [--cold]``: the online table (JSON lines)."""
    args = list(sys.argv[1:] if argv is None else argv)
    warm = "--cold" not in args
    args = [a for a in args if a != "--cold"]
    n = int(args[0]) if args else 20000
    seeds = [int(x) for x in args[1].split(",")] if len(args) > 1 else [0, 1, 2]
    for seed in seeds:
        for effect in (None, *EFFECTS):
            print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v)
                              for k, v in measure(effect, seed, n, warm).items()}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
