"""Benchmark of ``diagnose``: time on 30,000 samples with all eight candidates, and the detection table.

Prints one JSON document:

* ``timing``: wall time of ``diagnose`` on 30,000-sample records (1 kHz, a
  staircase with reversals; clean and with hidden effects), p50/p99/max over
  all runs, against the previous code (``--previous``, default main: ``git
  archive``, its own interpreter, alternating with this code's runs so both see
  the same load) and the ratio, with the load average at the start and after
  each round, and the CPU seconds of both (``time.process_time``: less
  sensitive than the wall time to the other jobs of a shared machine; with
  the candidate fits on threads it counts every thread of the process);
  ``serial``: this code with ``workers=1`` on the same records in the same
  rounds (the threads' share of the gain); and an ablation in the same process
  (the same fits with every evaluation on the whole record, no exploration window).
* ``detection``: for each catalogue effect (and clean data) and >= 3 seeds,
  the rank of the correct effect, the verdict, fit% and residual/noise before
  and after adding the top effect.

Usage: ``python -m bench.bench_diagnose [--seeds 3] [--timing-records 4] [--previous REF] [--quick]``
"""
from __future__ import annotations

import argparse
import json
import os
import time


# creep_online before numpy, as in the command line and the previous code's worker: its default of one BLAS
# thread applies only if set before numpy loads BLAS (imported after numpy, diagnose ran ~25 % slower here)
import creep_online  # noqa: E402,F401
import numpy as np  # noqa: E402

from creep_online.diagnostics import diagnose  # noqa: E402
from creep_online.diagnostics import extended as ext  # noqa: E402
from creep_online.diagnostics.pool import default_workers  # noqa: E402
from creep_online.effects import EFFECTS  # noqa: E402
from hil_sim.hidden_effects import hidden_dataset  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402


def dist_min(x: list[float]) -> dict:
    """The harness summary with the fastest run."""
    return {**dist(x), "min": float(np.min(x))}


#: Runs in the previous code's interpreter: a worker that times diagnose on the record named on each stdin line.
PREVIOUS_WORKER = """
import json, sys, time
from creep_online.diagnostics import diagnose
from hil_sim.hidden_effects import hidden_dataset
ds = hidden_dataset(None, 1, n=4000)
diagnose((ds.t, ds.u, ds.y))      # imports, numba cache
print("ready", flush=True)
for line in sys.stdin:
    kind = line.strip()
    ds = hidden_dataset(None if kind == "none" else kind, 1, n=30_000)
    t0, c0 = time.perf_counter(), time.process_time()
    d = diagnose((ds.t, ds.u, ds.y))
    print(json.dumps([time.perf_counter() - t0, d.verdict, time.process_time() - c0]), flush=True)
"""


def _previous_worker(ref: str):
    """(worker process, commit): the previous code (``git archive`` of ``ref``) timing diagnose on request."""
    from bench import _baseline
    return _baseline.start_worker(ref, PREVIOUS_WORKER)


def timing(records: int, repeats: int, previous: str | None = "main") -> dict:
    kinds = [None, "delay", "hysteresis", "second_mode", "periodic_disturbance", "leakage"][:records]
    data = [hidden_dataset(k, 1, n=30_000) for k in kinds]
    warm = hidden_dataset(None, 1, n=4000)
    diagnose((warm.t, warm.u, warm.y))      # imports, numba cache (as the previous code's worker does)
    worker, commit = _previous_worker(previous) if previous else (None, None)
    runs, cpu, verdicts, prev_runs, prev_cpu, prev_verdicts, loads = [], [], [], [], [], [], [os.getloadavg()]
    serial_runs, serial_cpu, serial_same = [], [], []
    for _ in range(repeats):   # record by record, this code then the previous one: both see the same load
        for k, ds in zip(kinds, data):
            t0, c0 = time.perf_counter(), time.process_time()
            d = diagnose((ds.t, ds.u, ds.y))
            runs.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            verdicts.append({"hidden": k or "none", "verdict": d.verdict, "seconds": runs[-1], "cpu_seconds": cpu[-1]})
            t0, c0 = time.perf_counter(), time.process_time()
            s = diagnose((ds.t, ds.u, ds.y), workers=1)
            serial_runs.append(time.perf_counter() - t0)
            serial_cpu.append(time.process_time() - c0)
            serial_same.append([(c.effect, c.evidence, c.fit.rss) for c in s.candidates]
                               == [(c.effect, c.evidence, c.fit.rss) for c in d.candidates])
            verdicts[-1].update(serial_seconds=serial_runs[-1], serial_cpu_seconds=serial_cpu[-1])
            if worker is not None:
                worker.stdin.write((k or "none") + "\n")
                worker.stdin.flush()
                sec, verdict, *more = json.loads(worker.stdout.readline())
                prev_runs.append(sec)
                prev_cpu.append(more[0] if more else float("nan"))
                prev_verdicts.append({"hidden": k or "none", "verdict": verdict, "seconds": sec,
                                      "cpu_seconds": prev_cpu[-1]})
            loads.append(os.getloadavg())
    if worker is not None:
        worker.stdin.close()
        worker.wait()
    # ablation: identical fits, every evaluation on the whole record (no exploration window)
    saved = ext.EXPLORE_SAMPLES
    ext.EXPLORE_SAMPLES = 10**9
    try:
        base_runs = []
        for k, ds in zip(kinds[:2], data[:2]):
            t0 = time.perf_counter()
            diagnose((ds.t, ds.u, ds.y))
            base_runs.append(time.perf_counter() - t0)
    finally:
        ext.EXPLORE_SAMPLES = saved
    ours = dist_min(runs)
    base = dist_min(base_runs)
    same = [r for r, v in zip(runs, verdicts) if v["hidden"] in [k or "none" for k in kinds[:2]]]
    out = {"samples": 30_000, "candidates": len(EFFECTS), "workers": default_workers(), "seconds": ours,
           "cpu_seconds": dist_min(cpu),
           "serial": {"seconds": dist_min(serial_runs), "cpu_seconds": dist_min(serial_cpu),
                      "same_candidates_bit_for_bit": all(serial_same)},
           "per_record": verdicts,
           "baseline_full_record_seconds": base,
           "speedup_vs_baseline_p50": base["p50"] / float(np.percentile(same, 50)),
           "goal_s": 3.0, "meets_goal_p50": ours["p50"] <= 3.0, "load_average": loads}
    if worker is not None:
        prev = dist_min(prev_runs)
        out["previous"] = {"commit": commit, "seconds": prev, "cpu_seconds": dist_min(prev_cpu),
                           "per_record": prev_verdicts,
                           "same_verdicts": [v["verdict"] for v in verdicts] == [v["verdict"] for v in prev_verdicts],
                           "speedup_p50": prev["p50"] / ours["p50"],
                           "cpu_speedup_p50": float(np.percentile(prev_cpu, 50) / np.percentile(cpu, 50))}
    return out


def detection(seeds: list[int], n: int) -> dict:
    rows = []
    for effect in (None, *EFFECTS):
        for seed in seeds:
            ds = hidden_dataset(effect, seed, n=n)
            t0 = time.perf_counter()
            d = diagnose((ds.t, ds.u, ds.y))
            el = time.perf_counter() - t0
            names = [c.effect for c in d.candidates]
            name = effect or "none"
            rank = names.index(effect) + 1 if effect in names else None
            top = d.candidates[0] if d.candidates else None
            after = top.fit if (top is not None and effect is not None) else d.base
            rows.append({
                "effect": name, "seed": seed, "verdict": d.verdict, "rank_of_correct": rank if effect else
                (1 if d.verdict == "none" else None),
                "fit_percent_before": d.base.fit_percent, "fit_percent_after": after.fit_percent,
                "residual_over_noise_before": d.base.residual_rms / ds.noise_std,
                "residual_over_noise_after": after.residual_rms / ds.noise_std,
                "evidence_top": top.evidence if top else None, "seconds": el})
    table = {}
    for r in rows:
        e = table.setdefault(r["effect"], {"ranks": [], "correct_verdicts": 0, "runs": 0,
                                           "max_residual_over_noise_after": 0.0})
        e["ranks"].append(r["rank_of_correct"])
        e["runs"] += 1
        e["correct_verdicts"] += int(r["verdict"] == r["effect"])
        e["max_residual_over_noise_after"] = max(e["max_residual_over_noise_after"], r["residual_over_noise_after"])
    ok = all(all(k == 1 for k in v["ranks"]) and v["max_residual_over_noise_after"] <= 1.3 for v in table.values())
    return {"samples": n, "seeds": seeds, "table": table, "rows": rows, "all_pass": ok,
            "seconds": dist_min([r["seconds"] for r in rows])}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=3, help="seeds per effect in the detection table (>= 3)")
    p.add_argument("--samples", type=int, default=4000, help="samples per detection record")
    p.add_argument("--timing-records", type=int, default=4, help="30k-sample records timed")
    p.add_argument("--repeats", type=int, default=1, help="timing repeats over the records")
    p.add_argument("--previous", default="main", help="git ref of the previous code timed in the same run ('' to skip)")
    p.add_argument("--timing-only", action="store_true", help="only the timing table")
    p.add_argument("--quick", action="store_true", help="2 timing records, 1 seed (smoke run)")
    a = p.parse_args()
    if a.quick:
        a.timing_records, a.seeds = 2, 1
    out = {"timing": timing(a.timing_records, a.repeats, a.previous or None)}
    if not a.timing_only:
        out["detection"] = detection(list(range(101, 101 + a.seeds)), a.samples)
    write_report(out)


if __name__ == "__main__":
    main()
