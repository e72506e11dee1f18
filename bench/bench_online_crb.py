"""Cramer-Rao bounds of the four parameters on the scenario records: what the data can determine.

Usage (repository root)::

    python -m bench.bench_online_crb [--families drift] [--plants 20] [--seed-offset 0] [--last 10]
        [--out bench/results/online_crb.json]

For each record of ``hil_sim.scenarios`` (the same seeds as
``bench_online_scenarios.py``) the Fisher information of (ln alpha, ln a1, ln a2,
ln b, offset) over the last ``--last`` seconds and over the whole record, with
the Jacobian by forward differences (relative step 1e-4) of the exact
noise-free simulation ``Scenario.clean`` along the true parameter trajectories
(a drift scales the whole trajectory) and the record's white noise variance.
The relative 1-sigma bounds (%) say which misses of the scenario bench are
information-limited: an estimator whose window is the last 10 s cannot
determine a parameter whose bound there exceeds the tolerance (5 % for a1 and
a2), and should say so (quality "provisional", "a1 not yet determined").
close_modes is left out (its truth is the best second-order fit of a plant with
more modes). Output: JSON, per family and seed.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from bench.harness import results_path, write_report  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ("alpha", "a1", "a2", "b")
STEP = 1e-4


def bounds(scen, last_s: float) -> dict:
    """Relative 1-sigma CRB (%) of alpha, a1, a2, b over the last ``last_s`` seconds and the whole record."""
    y0 = scen.clean()
    cols = [(scen.clean(**{k: 1 + STEP}) - y0) / STEP for k in PARAMS]     # dy / d ln(parameter)
    cols.append(np.ones_like(y0))                                            # the output offset
    J = np.array(cols).T
    var = scen.params["noise_std"] ** 2
    out = {}
    for name, rows in (("last", slice(-int(round(last_s / scen.h)), None)), ("whole", slice(None))):
        cov = np.linalg.inv(J[rows].T @ J[rows] / var)
        out[name] = {k: 100 * math.sqrt(cov[i, i]) for i, k in enumerate(PARAMS)}
    return out


def main(argv: list[str] | None = None) -> dict:
    from hil_sim.scenarios import FAMILIES, make
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--families", default="drift")
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--seed-offset", type=int, default=0)
    ap.add_argument("--last", type=float, default=10.0, help="seconds at the end of the record (the window)")
    ap.add_argument("--out", default=str(results_path("online_crb")))
    args = ap.parse_args(argv)
    families = [f for f in args.families.split(",") if f in FAMILIES and f != "close_modes"]
    doc = {"config": {"last_s": args.last, "plants": args.plants, "seed_offset": args.seed_offset,
                      "unit": "relative 1-sigma, %"}, "families": {}}
    for fam in families:
        rows = {}
        for seed in range(args.seed_offset, args.seed_offset + args.plants):
            scen = make(fam, seed)
            rows[seed] = {"input": scen.params.get("input"), "fn": scen.params.get("fn"),
                          "zeta": scen.params.get("zeta"), **bounds(scen, args.last)}
        doc["families"][fam] = rows
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
