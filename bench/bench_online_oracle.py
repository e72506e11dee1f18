"""An oracle estimator on the scenario records: how often can any estimator end within the tolerances?

Usage (repository root)::

    python -m bench.bench_online_oracle [--families drift,payload] [--plants 20] [--seed-offset 0]
        [--snr-db 40] [--last 10] [--compare bench/results/online_scenarios_single_40db_X.json]
        [--processes 2] [--from ORACLE.json] [--out bench/results/online_oracle.json]

For each record of ``hil_sim.scenarios`` (the seeds and noise draws of
``bench_online_scenarios.py`` at the same ``--snr-db``) the maximum-likelihood
fit of the four parameters on the record's last ``--last`` seconds (the online
estimator's window) *with everything else given*: the plant's structure, the
change time, the drift's linear form, the state before the window, the output
offset and the noise level. It fits four factors, each parameter's whole true
trajectory scaled by exp(x) (as the Cramer-Rao bound's sensitivities are
taken in ``bench_online_crb.py``), by ``scipy.optimize.least_squares`` on the
exact simulator (``Scenario.clean``: a mid-operation record's history
included), started at the truth. The online estimator
knows none of this, so where the oracle ends outside a tolerance on a record,
that record's data do not put that parameter within it: the oracle's fraction
within all four tolerances is what the data allow, and an online estimator
is not expected above it. With ``--compare`` (a ``bench_online_scenarios.py``
JSON of the same seeds and SNR) each run is cross-tabulated: the estimator
within where the oracle is, and the runs the estimator misses although the
oracle is within (the estimator's own shortfall). ``--from`` takes the fits of
an earlier run of this bench (they do not depend on the estimator) and only
cross-tabulates them against ``--compare``.

close_modes is left out (its truth is the best second-order fit of a plant
with more modes: no structure to hand an oracle). Output: JSON (also to
``--out``): per family the fraction within all four tolerances and per run
the oracle's relative errors.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")   # one core per worker process

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

from bench.bench_online_scenarios import PARAMS, TOL  # noqa: E402  (the scenario bench's tolerances: the same "within")
from bench.harness import results_path, write_report  # noqa: E402
#: Largest |ln factor| the fit may take (a factor of e^5 ~ 150: far beyond any tolerance, keeps the simulator
#: inside its stable range on a flat cost).
LN_FACTOR_BOUND = 5.0


def oracle_fit(scen, last_s: float) -> dict:
    """The oracle's relative error of each parameter on the record's last ``last_s`` seconds, and its cost.

    Minimizes sum((y - Scenario.clean(trajectories x exp(x)))^2) over the window in x (one ln factor per
    parameter), started at x = 0 (the truth). Returns ``rel`` (exp(x) - 1 per parameter), ``cost_ratio`` (the
    fit's window RMS over the noise std: ~1 when the fit is the data's optimum) and ``evaluations``."""
    from scipy.optimize import least_squares

    last = slice(max(0, scen.u.size - int(round(last_s / scen.h))), scen.u.size)
    y = np.asarray(scen.y[last], dtype=float)
    std = float(scen.params["noise_std"])

    def residual(x: np.ndarray) -> np.ndarray:
        return (scen.clean(**{k: math.exp(float(x[i])) for i, k in enumerate(PARAMS)})[last] - y) / std

    fit = least_squares(residual, np.zeros(len(PARAMS)), bounds=(-LN_FACTOR_BOUND, LN_FACTOR_BOUND),
                        x_scale="jac", diff_step=1e-5)
    return {"rel": {k: math.expm1(float(fit.x[i])) for i, k in enumerate(PARAMS)},
            "cost_ratio": float(math.sqrt(np.mean(fit.fun**2))), "evaluations": int(fit.nfev)}


def _one(job: tuple[str, int, float | None, float]) -> dict:
    """Worker: one record (family, seed, snr_db, last_s) -> its row."""
    fam, seed, snr_db, last_s = job
    from hil_sim import scenarios
    if snr_db is not None:
        scenarios.SNR_DB = float(snr_db)
    scen = scenarios.make(fam, seed)
    res = oracle_fit(scen, last_s)
    within = {k: abs(res["rel"][k]) <= TOL[k] for k in PARAMS}
    return {"family": fam, "seed": seed, **res, "within": within, "within_all": all(within.values())}


def _compared(rows: list[dict], estimator: dict | None) -> dict:
    """Per family: the oracle's fraction within all tolerances and, against the estimator's runs, the
    cross-tabulation."""
    out = {"runs": len(rows), "oracle_within_all": sum(r["within_all"] for r in rows) / len(rows)}
    if estimator is None:
        return out
    ours = {r["seed"]: bool(r.get("within_all")) for r in estimator["runs_detail"]}
    both = [r for r in rows if r["seed"] in ours]
    for r in both:
        r["estimator_within_all"] = ours[r["seed"]]
    oracle_in = [r for r in both if r["within_all"]]
    out.update(estimator_within_all=sum(ours[r["seed"]] for r in both) / len(both) if both else None,
               estimator_within_where_oracle_within=(sum(ours[r["seed"]] for r in oracle_in) / len(oracle_in)
                                                     if oracle_in else None),
               estimator_misses_oracle_within=sorted(r["seed"] for r in oracle_in if not ours[r["seed"]]),
               estimator_within_oracle_outside=sorted(r["seed"] for r in both
                                                      if ours[r["seed"]] and not r["within_all"]))
    return out


def main(argv: list[str] | None = None) -> dict:
    from hil_sim.scenarios import FAMILIES, SNR_DB
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--families", default=",".join(f for f in FAMILIES if f != "close_modes"))
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--seed-offset", type=int, default=0)
    ap.add_argument("--snr-db", type=float, default=None, help=f"output SNR (default the scenarios' {SNR_DB:g} dB)")
    ap.add_argument("--last", type=float, default=10.0, help="seconds at the end of the record (the window)")
    ap.add_argument("--compare", default=None, help="a bench_online_scenarios.py JSON of the same seeds and SNR")
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--from", dest="source", default=None, help="this bench's JSON: its fits, cross-tabulated anew")
    ap.add_argument("--out", default=str(results_path("online_oracle")))
    args = ap.parse_args(argv)
    families = [f for f in args.families.split(",") if f in FAMILIES and f != "close_modes"]
    estimator = json.loads(Path(args.compare).read_text())["current"]["families"] if args.compare else {}
    start = time.perf_counter()
    if args.source:
        earlier = json.loads(Path(args.source).read_text())
        config = {**earlier["config"], "compare": args.compare, "from": args.source}
        families = [f for f in earlier["families"] if f in families]
        rows = [r for f in families for r in earlier["families"][f]["runs_detail"]]
    else:
        jobs = [(fam, seed, args.snr_db, args.last) for fam in families
                for seed in range(args.seed_offset, args.seed_offset + args.plants)]
        with get_context("spawn").Pool(max(1, args.processes)) as pool:
            rows = pool.map(_one, jobs, chunksize=1)
        config = {"families": families, "plants": args.plants, "seed_offset": args.seed_offset,
                  "snr_db": SNR_DB if args.snr_db is None else args.snr_db, "last_s": args.last,
                  "tolerances": TOL, "compare": args.compare}
    doc = {"config": config, "families": {}, "elapsed_s": None}
    for fam in families:
        mine = [r for r in rows if r["family"] == fam]
        doc["families"][fam] = {**_compared(mine, estimator.get(fam)), "runs_detail": mine}
    doc["elapsed_s"] = time.perf_counter() - start
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
