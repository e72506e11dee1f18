"""Block-mode throughput (``update_block``) of both trackers on 100k-sample 10 kHz records, against a baseline revision.

Usage (from the repository root)::

    nice -n 10 .venv/bin/python -m bench.bench_online_block --baseline main [--runs 5] [--chunk 10000]
        [--out bench/results/online_block.json]

Records (10 kHz, 100,000 samples each): the latency stream of ``bench_online`` (its first 10 s: rest, steps to
random levels every second), and the first 10 s of ``hil_sim.scenarios`` payload seed 0 and mid_operation seed 0
(taken in operation). Per tracker (``refit="window"``, ``"recursive"``) and record: one warm-up run, then
``--runs`` runs, each a fresh ``OnlineEstimator(dt, refit=...)`` fed by ``update_block`` in chunks of ``--chunk``
samples; samples per second by wall time and by the thread's CPU time (``time.thread_time``), start-up
included. Both trees run in interpreters of their own, one after the other, each with a fresh numba cache
(this tree from the checkout, the baseline from ``git archive`` of the revision, ``bench._baseline``): code
compiled in the process and code loaded from a cache can round differently (the recursive tracker's estimates
on a stream in operation differ between the two, on every revision), so both sides compile alike. Reported: per tracker and record, the runs' samples/s (p50, max) for both
and their ratio (current / baseline, p50), and whether the final estimates are the same (``==``, both
trees feed the same chunks). The machine is a shared 2-core box: compare within one document.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import subprocess  # noqa: E402
import sys  # noqa: E402

from bench._baseline import ROOT, extract  # noqa: E402
from bench.bench_online import H, make_stream  # noqa: E402
from bench.harness import dist, results_path, write_report  # noqa: E402

SAMPLES = 100_000
TRACKERS = ("window", "recursive")

#: The measurement, as source: run in this process for this tree and in a subprocess for the baseline (it uses only
#: ``OnlineEstimator(dt, refit=...)``, ``update_block`` and ``estimate``, present in both).
MEASURE = '''
import gc, json, sys, time
import numpy as np
from creep_online.online import OnlineEstimator


def measure(records, trackers, runs, chunk):
    """{tracker: {record: {"wall": [samples/s...], "cpu": [...], "final": [alpha, a1, a2, b, quality]}}}."""
    out = {}
    for refit in trackers:
        per = out.setdefault(refit, {})
        for name, path in records.items():
            with np.load(path) as z:
                u, y, h = z["u"], z["y"], float(z["h"])
            wall, cpu = [], []
            for run in range(runs + 1):                 # (run 0 warms the caches: not counted)
                est = OnlineEstimator(h, refit=refit)
                gc.collect()
                w0, c0 = time.perf_counter(), time.thread_time()
                for k in range(0, u.size, chunk):
                    est.update_block(u[k:k + chunk], y[k:k + chunk])
                w, c = time.perf_counter() - w0, time.thread_time() - c0
                if run:
                    wall.append(u.size / w)
                    cpu.append(u.size / c)
            e = est.estimate
            per[name] = {"wall": wall, "cpu": cpu, "final": [e.alpha, e.a1, e.a2, e.b, e.quality]}
    return out


if __name__ == "__main__":
    spec = json.loads(sys.argv[1])
    print(json.dumps(measure(spec["records"], spec["trackers"], spec["runs"], spec["chunk"])))
'''


def make_records(folder: Path) -> dict[str, str]:
    """The three 100k-sample records as npz files (module docstring); name -> path."""
    from hil_sim import scenarios
    stream = make_stream(seconds=SAMPLES * H)
    data = {"latency_stream": (stream["u"], stream["y"], H)}
    for family in ("payload", "mid_operation"):
        scen = scenarios.make(family, 0)
        data[f"{family}_0"] = (scen.u[:SAMPLES], scen.y[:SAMPLES], scen.h)
    paths = {}
    for name, (u, y, h) in data.items():
        path = folder / f"{name}.npz"
        np.savez(path, u=u, y=y, h=h)
        paths[name] = str(path)
    return paths


def run_tree(path: str, spec: dict, cache: Path) -> dict:
    """MEASURE in a fresh interpreter with ``path`` first on sys.path and an empty numba cache ``cache``."""
    env = dict(os.environ, PYTHONPATH=path, NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, "-c", MEASURE, json.dumps(spec)], check=True, capture_output=True,
                         text=True, env=env, cwd=path)
    return json.loads(out.stdout.strip().splitlines()[-1])


def summary(cur: dict, base: dict | None) -> dict:
    """Per tracker and record: p50/max samples/s, the ratio of the p50s, the final estimates' identity."""
    out = {}
    for refit, records in cur.items():
        for name, r in records.items():
            row = {"current": {"wall": dist(r["wall"]), "cpu": dist(r["cpu"])}, "final_current": r["final"]}
            if base is not None:
                b = base[refit][name]
                row["baseline"] = {"wall": dist(b["wall"]), "cpu": dist(b["cpu"])}
                row["ratio_p50"] = {k: row["current"][k]["p50"] / row["baseline"][k]["p50"] for k in ("wall", "cpu")}
                row["same_final_estimate"] = r["final"] == b["final"]
            out.setdefault(refit, {})[name] = row
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", default="main", help="git revision measured in the same run ('none': skip)")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--chunk", type=int, default=10_000)
    ap.add_argument("--out", default=str(results_path("online_block")))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="online_block_") as tmp:
        records = make_records(Path(tmp))
        spec = {"records": records, "trackers": list(TRACKERS), "runs": args.runs, "chunk": args.chunk}
        cur = run_tree(ROOT, spec, Path(tmp) / "cache_current")
        base, commit = None, None
        if args.baseline != "none":
            path, commit = extract(args.baseline)
            base = run_tree(path, spec, Path(tmp) / "cache_baseline")
    doc = {"config": {**vars(args), "samples": SAMPLES, "baseline_commit": commit, "records": list(records)},
           "goal_samples_per_s": 2_000_000, "trackers": summary(cur, base)}
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
