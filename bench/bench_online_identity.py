"""Does this tree's online estimator behave exactly as a baseline revision's? Trajectories side by side.

Usage (from the repository root)::

    python -m bench.bench_online_identity --baseline main [--plants 3] [--families payload,drift]
        [--mode block|single] [--kwargs '{"refit": "recursive"}'] [--snr-db 80] [--rest-samples 0]

A restructuring of ``creep_online/online`` must not change a single estimate. This runs the scenario
records of ``bench.bench_online_scenarios`` (same generator, same feeding, the estimate read after every
0.1 s chunk) through this tree and through ``git archive BASELINE creep_online``, and compares the two
trajectories chunk by chunk: the quality strings must match and every parameter must agree to ``--rtol``
(NaN equals NaN: not estimated on both sides). It prints one JSON document: per family, the runs
compared, the runs identical, the largest relative difference and the first chunk where a run differs;
``identical`` is true only when every run of every family is.

Both sides run alike: each in a worker process of its own (the same worker, the same BLAS threads), compiling
its kernels into a numba cache of its own that starts empty. A revision whose online kernels carry fast-math
flags (reassociation, contraction) compiles machine code, and so the last bits of an estimate, that depend on
which of the kernels they call were already in the cache: run from a tree whose cache grew over earlier runs
(another tracker first, say) it differs from a fresh compile by ~1e-7, and where a decision hangs on those bits
a trajectory parts for good. From empty caches such a baseline compares alike too.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import bench_online_scenarios
from bench.bench_online_scenarios import PARAMS, ROOT, baseline_tree, generate
from bench.harness import results_path, write_report


def compare_runs(cur: dict, base: dict, rtol: float) -> dict:
    """One record: identical or where and by how much the two trajectories part."""
    if cur["error"] or base["error"]:
        same = cur["error"] == base["error"]
        return {"identical": same, "max_rel_diff": 0.0 if same else math.inf, "first_diff_chunk": None if same else 0,
                "errors": [cur["error"], base["error"]]}
    tc, tb = cur["traj"], base["traj"]
    worst, first = 0.0, None
    n = min(len(tc["samples"]), len(tb["samples"]))
    for k in range(n):
        diff = 0.0 if tc["quality"][k] == tb["quality"][k] else math.inf
        for p in PARAMS:
            a, b = tc[p][k], tb[p][k]
            if math.isnan(a) and math.isnan(b):
                continue
            if math.isnan(a) or math.isnan(b):
                diff = math.inf
                continue
            diff = max(diff, abs(a - b) / max(abs(b), 1e-300))
        worst = max(worst, diff)
        if first is None and diff > rtol:
            first = k
    if len(tc["samples"]) != len(tb["samples"]):
        worst, first = math.inf, n if first is None else first
    return {"identical": first is None, "max_rel_diff": worst, "first_diff_chunk": first}


def start_side(tree: Path, files: list[Path], mode: str, kwargs: dict, work: Path) -> tuple[subprocess.Popen, Path]:
    """One side's worker (``bench_online_scenarios --worker``): ``tree`` first on the path, an empty numba cache of
    its own in ``work``; returns the process and the path its report will be written to."""
    work.mkdir(parents=True, exist_ok=True)
    spec, out = work / "spec.json", work / "out.json"
    spec.write_text(json.dumps({"files": [str(f) for f in files], "mode": mode, "kwargs": kwargs, "out": str(out)}))
    env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": str(work / "numba_cache")}
    with open(work / "stderr.txt", "w") as err:   # a file, not a pipe: nobody reads it until the end
        proc = subprocess.Popen([sys.executable, bench_online_scenarios.__file__, "--worker", str(spec)],
                                env=env, cwd=str(work), stderr=err)
    return proc, out


def finish_side(proc: subprocess.Popen, out: Path, name: str) -> dict:
    """A side's report once its worker has ended (SystemExit naming the side if it failed)."""
    if proc.wait() != 0 or not out.exists():
        raise SystemExit(f"{name} worker failed: {(out.parent / 'stderr.txt').read_text()[-2000:]}")
    return json.loads(out.read_text())


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", required=True, help="git revision to compare against (e.g. main)")
    ap.add_argument("--plants", type=int, default=3, help="records per family")
    ap.add_argument("--seed-offset", type=int, default=0)
    ap.add_argument("--families", default=None, help="comma-separated subset of hil_sim.scenarios.FAMILIES")
    ap.add_argument("--mode", choices=("block", "single"), default="block")
    ap.add_argument("--kwargs", default="{}", help="JSON dict passed to OnlineEstimator(dt, **kwargs) on both sides")
    ap.add_argument("--snr-db", type=float, default=None)
    ap.add_argument("--rest-samples", type=int, default=None)
    ap.add_argument("--rtol", type=float, default=0.0, help="relative difference still counted as identical")
    ap.add_argument("--out", default=str(results_path("online_identity")))
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> dict:
    from hil_sim import scenarios
    from hil_sim.scenarios import FAMILIES
    args = parse_args(argv)
    families = args.families.split(",") if args.families else list(FAMILIES)
    if args.rest_samples is not None:
        families = [f for f in families if f in scenarios.FROM_REST]
    kwargs = json.loads(args.kwargs)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="online_identity_") as tmp:
        work = Path(tmp)
        (work / "scenarios").mkdir()
        truth = generate(families, args.plants, work / "scenarios", args.seed_offset, args.snr_db, args.rest_samples)
        files = sorted((work / "scenarios").glob("*.npz"))
        base_tree = baseline_tree(args.baseline, work / "baseline_src")
        sides = {"current": start_side(ROOT, files, args.mode, kwargs, work / "current"),
                 "baseline": start_side(base_tree, files, args.mode, kwargs, work / "baseline")}
        reports = {name: finish_side(proc, out, name) for name, (proc, out) in sides.items()}
        for name, tree in (("current", ROOT), ("baseline", base_tree)):
            if not Path(reports[name]["package"]).is_relative_to(tree):
                raise SystemExit(f"the {name} worker imported {reports[name]['package']}, not {tree}")
        current, base = reports["current"]["results"], reports["baseline"]["results"]
    per_family: dict[str, dict] = {}
    for cur, bas in zip(current, base):
        fam = truth[cur["file"]]["family"]
        row = per_family.setdefault(fam, {"runs": 0, "identical": 0, "max_rel_diff": 0.0, "differing": []})
        cmp = compare_runs(cur, bas, args.rtol)
        row["runs"] += 1
        row["identical"] += int(cmp["identical"])
        row["max_rel_diff"] = max(row["max_rel_diff"], cmp["max_rel_diff"])
        if not cmp["identical"]:
            row["differing"].append({"file": cur["file"], **cmp})
    doc = {"config": {**vars(args), "families": families},
           "sides": "each in a worker process of its own (the same BLAS threads), its numba cache starting empty",
           "identical": all(r["runs"] == r["identical"] for r in per_family.values()),
           "families": per_family, "elapsed_s": time.perf_counter() - start,
           "max_rel_diff": float(np.max([r["max_rel_diff"] for r in per_family.values()]))}
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
