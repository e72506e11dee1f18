"""Honest uncertainty of ``identify`` (issue 9, item 4): coverage of the reported 1-sigma over noise seeds.

For fixed plants and inputs, each seed draws new measurement noise (white, or
coloured: AR(1) with coefficient 0.9, the same variance); a parameter is
"covered" when |estimate - truth| <= its reported 1-sigma. Honest intervals
cover about 68 %; much less means they are optimistic.

Usage: python -m bench.bench_identify_coverage [--seeds 100] [--out FILE]
"""
from __future__ import annotations

import argparse
import json

import numpy as np


from creep_online import CreepModel, simulate  # noqa: E402
from creep_online.identification import identify  # noqa: E402
from hil_sim.experiments import FOUR_STEP, LOAD_CELL, STRONG_CREEP  # noqa: E402
from bench.harness import write_report  # noqa: E402

PARAMS = ("alpha", "a1", "a2", "b")


def noise(kind: str, std: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """White, or AR(1) (0.9) scaled to the same standard deviation."""
    e = rng.normal(0.0, std, n)
    if kind == "white":
        return e
    phi = 0.9
    out = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc = phi * acc + e[i]
        out[i] = acc
    return out * np.sqrt(1 - phi * phi)


def coverage(case, kind: str, seeds: int) -> dict:
    t, u = case.input()
    clean = simulate(case.model, t, u)
    std = float(np.sqrt(np.mean(clean * clean))) * 10 ** (-40.0 / 20)
    hits = dict.fromkeys(PARAMS, 0)
    z = {k: [] for k in PARAMS}
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        res = identify(t, u, clean + noise(kind, std, t.size, rng))
        for k in PARAMS:
            err = getattr(res.model, k) - getattr(case.model, k)
            sd = res.uncertainty.get(k, float("nan"))
            hits[k] += abs(err) <= sd
            z[k].append(err / sd)
    return {k: {"coverage_1sigma": hits[k] / seeds, "rms_z": float(np.sqrt(np.mean(np.square(z[k]))))}
            for k in PARAMS}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    report = {"bench": "identify_coverage", "seeds": args.seeds, "snr_db": 40.0, "cases": {}}
    for case in (LOAD_CELL, STRONG_CREEP, FOUR_STEP):
        report["cases"][case.name] = {kind: coverage(case, kind, args.seeds) for kind in ("white", "ar1_0.9")}
    write_report(report, args.out, indent=2)


if __name__ == "__main__":
    main()
