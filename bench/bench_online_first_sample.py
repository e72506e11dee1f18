"""Records that start with the step: the paper's experiment, the estimate at t_c + 5 s, both feeding modes.

Usage (from the repository root, with the package installed or ``PYTHONPATH=.``)::

    python -m bench.bench_online_first_sample [--plants 20] [--seed-offset 0] [--snr-db 80]
        [--rest 0,1,10] [--modes block,single] [--out bench/results/online_first_sample_80db.json]

Each plant is drawn over the ranges of the scenario families (``hil_sim.scenarios``): even seeds from
strong_creep's (alpha 0.005-0.7, fn 1 Hz-fs/4, zeta 0.01-1, b +-10^U(-3,3), 1-10 kHz), odd seeds from the
stationary families' (alpha 0.01-0.5, fn 100-2500 Hz, zeta 0.02-0.5, b +-10^U(-1,1), 10 kHz). The input is one step
to a level +-10^U(-1,1) held for 8 s, at the first sample (``--rest 0``: the input at its level from the first
sample, the plant at rest before it) or after 1 or 10 samples of rest; white noise ``--snr-db`` below the output's
rms. The estimator is fed in chunks of 0.1 s (``update_block``, or ``update()`` per sample in mode ``single``) and
read at the first chunk end at or after t_c + 5 s (t_c: the estimate's search window).

Per (rest, mode) the JSON gives the fraction of plants with alpha and b within 0.3 % (each and both), and the same
over the plants whose data determine them to that accuracy: the Cramer-Rao bound of the relative error over the
samples read (``bench_online_scenarios.cramer_rao_rel``, no forgetting: optimistic), times 1.96, within 0.3 %.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from bench.harness import results_path, write_report  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

#: The paper's accuracy on alpha and b (relative).
ACCURACY = 0.003
#: Read the estimate this long after its search window t_c (s).
AFTER_TC_S = 5.0
#: Record length (s): t_c is at most the estimator's t_c_max (2 s).
DURATION_S = 8.0
CHUNK_S = 0.1
DETERMINED_Z = 1.96


def plant(seed: int) -> dict:
    """The plant and step of ``seed`` (module docstring)."""
    from hil_sim import scenarios as S
    rng = np.random.default_rng([seed, 99])
    if seed % 2 == 0:
        p = S._strong_creep_plant(rng)
        fs, ranges = p["fs"], "strong_creep"
    else:
        p = S._stationary_plant(rng, 100.0, 2500.0)
        fs, ranges = 1e4, "stationary"
    level = float(rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(-1.0, 1.0))
    return {"seed": seed, "ranges": ranges, "fs": fs, "level": level, "noise_seed": int(rng.integers(1 << 31)),
            **{k: float(p[k]) for k in ("alpha", "a1", "a2", "b", "fn", "zeta")}}


def record(p: dict, rest: int, snr_db: float):
    """(scenario, clean output) for plant ``p`` with ``rest`` samples at 0 before the step."""
    from hil_sim import scenarios as S
    h = 1.0 / p["fs"]
    n = int(DURATION_S / h)
    u = np.full(n, p["level"])
    u[:rest] = 0.0
    truth = {k: p[k] for k in ("alpha", "a1", "a2", "b")}
    clean = S.simulate_tv(h, u, **truth)
    std = float(np.sqrt(np.mean(clean ** 2)) * 10 ** (-snr_db / 20))
    y = clean + np.random.default_rng(p["noise_seed"]).normal(0.0, std, n)
    arrays = {k: np.full(n, v) for k, v in truth.items()}
    scen = S.Scenario(family="first_sample", seed=p["seed"], h=h, t=np.arange(n) * h, u=u, y=y,
                      params={**p, "noise_std": std}, **arrays)
    return scen


def run(scen, mode: str) -> dict:
    """Feed ``scen`` in chunks; the estimate at the first chunk end at or after t_c + AFTER_TC_S."""
    from creep_online.online import OnlineEstimator
    est = OnlineEstimator(scen.h)
    step = max(1, int(round(CHUNK_S / scen.h)))
    u, y = scen.u, scen.y
    e = None
    for k in range(0, u.size, step):
        if mode == "block":
            est.update_block(u[k:k + step], y[k:k + step])
        else:
            for a, b in zip(u[k:k + step].tolist(), y[k:k + step].tolist()):
                est.update(a, b)
        e = est.estimate
        if e.phase == "tracking" and e.t_c is not None and e.t >= e.t_c + AFTER_TC_S:
            break
    out = {"t": e.t, "t_c": e.t_c, "phase": e.phase, "quality": e.quality, "start": e.start, "reason": e.reason}
    for k in ("alpha", "a1", "a2", "b"):
        v = getattr(e, k)
        out[k] = None if v is None else float(v)
    return out


def rel(v: float | None, truth: float) -> float:
    return math.inf if v is None or not math.isfinite(v) else abs(v / truth - 1.0)


def main(argv: list[str] | None = None) -> dict:
    from bench.bench_online_scenarios import cramer_rao_rel
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--seed-offset", type=int, default=0)
    ap.add_argument("--snr-db", type=float, default=80.0)
    ap.add_argument("--rest", default="0,1,10", help="samples of rest before the step (comma-separated)")
    ap.add_argument("--modes", default="block,single")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    rests = [int(v) for v in args.rest.split(",")]
    modes = args.modes.split(",")
    start = time.perf_counter()
    rows = []
    for seed in range(args.seed_offset, args.seed_offset + args.plants):
        p = plant(seed)
        for rest in rests:
            scen = record(p, rest, args.snr_db)
            results = {mode: run(scen, mode) for mode in modes}
            t_read = max(r["t"] for r in results.values())
            crb = cramer_rao_rel(scen, window_s=t_read)
            for mode, r in results.items():
                err = {k: rel(r[k], p[k]) for k in ("alpha", "b", "a1", "a2")}
                rows.append({"seed": seed, "rest": rest, "mode": mode, "plant": p, **r, "rel_error": err,
                             "crb_rel": crb,
                             "determined": all(DETERMINED_Z * crb[k] <= ACCURACY for k in ("alpha", "b")),
                             "within": {k: err[k] <= ACCURACY for k in ("alpha", "b")}})
                print(f"seed {seed:3d} rest {rest:2d} {mode:6s} alpha {100 * err['alpha']:.3f} % b "
                      f"{100 * err['b']:.3f} % (crb {100 * crb['alpha']:.3f} / {100 * crb['b']:.3f} %) "
                      f"{r['quality']} {r['start']}", file=sys.stderr, flush=True)
    summary = {}
    for rest in rests:
        for mode in modes:
            sel = [r for r in rows if r["rest"] == rest and r["mode"] == mode]
            det = [r for r in sel if r["determined"]]
            both = [r["within"]["alpha"] and r["within"]["b"] for r in sel]
            summary[f"rest_{rest}_{mode}"] = {
                "runs": len(sel), "within_alpha": sum(r["within"]["alpha"] for r in sel) / len(sel),
                "within_b": sum(r["within"]["b"] for r in sel) / len(sel), "within_both": sum(both) / len(sel),
                "determined_runs": len(det),
                "within_both_where_determined": (sum(r["within"]["alpha"] and r["within"]["b"] for r in det)
                                                 / len(det)) if det else None,
                "max_rel_error": {k: max(r["rel_error"][k] for r in sel) for k in ("alpha", "b")},
                "starts": sorted({r["start"] for r in sel})}
    doc = {"command": " ".join(["python -m bench.bench_online_first_sample", *sys.argv[1:]]),
           "config": {"plants": args.plants, "seed_offset": args.seed_offset, "snr_db": args.snr_db,
                      "rest_samples": rests, "modes": modes, "accuracy": ACCURACY, "after_t_c_s": AFTER_TC_S},
           "summary": summary, "runs": rows, "elapsed_s": time.perf_counter() - start}
    out = args.out or results_path(f"online_first_sample_{args.snr_db:g}db")
    write_report(doc, out, default=str, echo=False)
    print(json.dumps(summary, indent=1))
    return doc


if __name__ == "__main__":
    main()
