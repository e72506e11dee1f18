"""Benchmark of ``creep-online batch``: records per second on Dask with 1 and 2 workers, per-record cost.

A seeded fleet (``hil_sim.fleet``: one actuator type, 2 s at 5 kHz = 10,000
samples per record, a staircase with a reversal, 40 dB; every 50th unit
faulty) is written as CSV files, then run through the same code as the CLI
(``fleet.runner.dask_client`` + ``run_on_dask``) with:

* ``serial``: the baseline, ``run_record`` in a plain loop in this process (no Dask);
* ``processes_1`` / ``processes_2``: the CLI's local cluster, 1 and 2 single-threaded worker processes;
* ``threads_2``: one worker process with 2 threads (why the CLI does not use threads).

Each configuration reports its start-up (cluster up, workers warm), the
records per second after start-up, and the per-record wall and thread-CPU
time (p50/p99/max, measured on the worker). The load average is recorded
before and after: this is a shared 2-core machine. ``plan_10000`` puts the
numbers on paper for a 10,000-actuator run. ``outlier_rule`` measures how
often the rule (fleet/summary.py) flags a unit of a normal fleet that is not
faulty, for fleets of 10 to 1,000.

The configurations run in ``--rounds`` interleaved rounds (they see the same
machine load); rates and start-ups are the medians over the rounds, the
per-record distributions pool all rounds.

Usage: ``python -m bench.bench_batch [--records 200] [--rounds 2] [--out bench/results/batch.json]``
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np


from creep_online.fleet import summarize  # noqa: E402
from creep_online.fleet.job import run_record, warm_up  # noqa: E402
from creep_online.fleet.runner import dask_client, run_on_dask  # noqa: E402
from creep_online.fleet.summary import Z_THRESHOLD, robust_z  # noqa: E402
from creep_online.io.fleet_records import find_records  # noqa: E402
from hil_sim.fleet import make_fleet, write_fleet  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402


def measure(name: str, jobs, run, workers: int) -> dict:
    """Run one configuration: ``run(jobs)`` gives (startup_s, rows iterator, close).

    Besides the rate: ``busy`` = (sum of the records' wall times) / (workers x
    elapsed), the fraction of the time Dask kept the workers on a record (1 =
    no scheduling gaps); ``contention`` = median of wall / CPU time per record,
    how much the record waited for a core (1 on an idle machine). The rate is
    workers x busy / (CPU per record x contention).
    """
    load0 = os.getloadavg()[0]
    t_start = time.perf_counter()
    startup, rows_iter, close = run(jobs)
    t0 = time.perf_counter()
    rows = list(rows_iter)
    elapsed = time.perf_counter() - t0
    close()
    summary = summarize(rows)
    out = {"records": len(rows), "identified": summary["identified"], "startup_s": startup,
           "elapsed_s": elapsed, "records_per_s": len(rows) / elapsed,
           "total_s": time.perf_counter() - t_start,
           "record_wall_s": dist([r["seconds"] for r in rows]),
           "record_cpu_s": dist([r["cpu_seconds"] for r in rows]),
           "wall_samples": [r["seconds"] for r in rows], "cpu_samples": [r["cpu_seconds"] for r in rows],
           "busy": sum(r["seconds"] for r in rows) / (workers * elapsed),
           "contention": float(np.median([r["seconds"] / r["cpu_seconds"] for r in rows])),
           "outliers": sorted(o["id"] for o in summary["outliers"]),
           "load_before": load0, "load_after": os.getloadavg()[0]}
    print(f"{name}: {out['records_per_s']:.2f} records/s, start-up {startup:.1f} s, record CPU p50 "
          f"{out['record_cpu_s']['p50'] * 1e3:.0f} ms, busy {out['busy']:.2f}, contention {out['contention']:.1f}, "
          f"load {load0:.1f} -> {out['load_after']:.1f}", file=sys.stderr)
    return out, rows


def serial(jobs):
    t0 = time.perf_counter()
    warm_up()
    return time.perf_counter() - t0, (run_record(j) for j in jobs), lambda: None


def local_processes(workers: int):
    def run(jobs):
        t0 = time.perf_counter()
        ctx = dask_client(workers=workers)
        client = ctx.__enter__()
        return time.perf_counter() - t0, run_on_dask(jobs, client), lambda: ctx.__exit__(None, None, None)
    return run


def local_threads(threads: int):
    def run(jobs):
        from dask.distributed import Client, LocalCluster
        from creep_online.fleet.runner import warm_up_workers
        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=1, threads_per_worker=threads, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0", silence_logs=40)
        client = Client(cluster)
        warm_up_workers(client, "the threads cluster")

        def close():
            client.close()
            cluster.close()
        return time.perf_counter() - t0, run_on_dask(jobs, client), close
    return run


def outlier_rule(trials: int = 400) -> dict:
    """Fraction of units of a normal fleet (no faults) flagged, per unit and per parameter."""
    rng = np.random.default_rng(0)
    out = {}
    for n in (10, 20, 50, 200, 1000):
        flagged = [np.mean(np.abs(robust_z(rng.normal(size=n))) > Z_THRESHOLD) for _ in range(trials)]
        out[str(n)] = float(np.mean(flagged))
    # for normal data MAD -> 0.6745 sigma, so |z| > 3.5 means |x - mean| > 3.5 sigma
    return {"threshold": Z_THRESHOLD, "false_flag_rate_per_unit_and_parameter": out,
            "normal_theory_large_fleet": math.erfc(Z_THRESHOLD / math.sqrt(2))}


def plan(results: dict, records: int = 10_000) -> dict:
    """A 10,000-actuator run on paper: wall = start-up + N c / (W busy) on W idle cores.

    c: mean thread-CPU seconds per record on the workers; busy: the fraction of
    the time Dask kept the workers on a record (both measured here with 2
    worker processes). On a shared machine divide the rate by the contention
    (wall / CPU per record); ``hours_here`` is what the measured rate gives.
    """
    p2 = results["processes_2"]
    cpu, busy, startup = p2["record_cpu_s"]["mean"], p2["busy"], p2["startup_s"]
    return {
        "records": records,
        "cpu_s_per_record_mean": cpu,
        "core_hours": records * cpu / 3600,
        "busy_2_workers": busy,
        "startup_s_2_workers": startup,
        "minutes_on_idle_cores": {str(w): (startup + records * cpu / (w * busy)) / 60 for w in (1, 2, 8, 32)},
        "hours_here_at_the_measured_2_worker_rate": (startup + records / p2["records_per_s"]) / 3600,
        "formula": "wall = start-up + N x c / (W x busy)   (x contention on a shared machine)",
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=200)
    ap.add_argument("--out", default=None)
    ap.add_argument("--configs", default="serial,processes_1,processes_2,threads_2")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    units = make_fleet(args.records, seed=1, faults={k: ("loose", "depoled")[(k // 50) % 2]
                                                     for k in range(25, args.records, 50)}, duration=2.0)
    faulty = sorted(u.id for u in units if u.fault)
    configs = {"serial": (serial, 1), "processes_1": (local_processes(1), 1),
               "processes_2": (local_processes(2), 2), "threads_2": (local_threads(2), 2)}
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as folder:
        write_fleet(units, folder)
        jobs = find_records(folder)
        reference = None
        for round_ in range(args.rounds):   # rounds interleave the configurations: they share the load
            for name in args.configs.split(","):
                one, rows = measure(f"round {round_ + 1} {name}", jobs, *configs[name])
                params = {r["id"]: (r["alpha"], r["a1"], r["a2"], r["b"]) for r in rows}
                reference = reference or params
                one["same_parameters_as_first"] = all(np.allclose(params[k], reference[k], rtol=1e-7)
                                                      for k in reference)
                one["faulty_units_flagged"] = sorted(set(faulty) & set(one["outliers"]))
                one["others_flagged"] = sorted(set(one["outliers"]) - set(faulty))
                results.setdefault(name, {"rounds": []})["rounds"].append(one)
    for name, res in results.items():
        for key in ("records_per_s", "startup_s", "busy", "contention"):
            res[key] = float(np.median([r[key] for r in res["rounds"]]))
        res["record_cpu_s"] = dist([x for r in res["rounds"] for x in r.pop("cpu_samples")])
        res["record_wall_s"] = dist([x for r in res["rounds"] for x in r.pop("wall_samples")])
    doc = {"records": args.records, "samples_per_record": int(units[0].t.size), "faulty_units": faulty,
           "cpus": os.cpu_count(), "rounds": args.rounds, "configs": results}
    if "serial" in results and "processes_1" in results:
        doc["dask_1_worker_vs_serial"] = results["processes_1"]["records_per_s"] / results["serial"]["records_per_s"]
    if "processes_1" in results and "processes_2" in results:
        doc["speedup_1_to_2_workers"] = results["processes_2"]["records_per_s"] / results["processes_1"]["records_per_s"]
        doc["speedup_1_to_2_workers_on_idle_cores_predicted"] = \
            2 * results["processes_2"]["busy"] / results["processes_1"]["busy"]
        doc["plan_10000"] = plan(results)
    if "threads_2" in results and "processes_2" in results:
        doc["threads_2_vs_processes_2"] = results["threads_2"]["records_per_s"] / results["processes_2"]["records_per_s"]
    doc["outlier_rule"] = outlier_rule()
    write_report(doc, args.out, indent=2)


if __name__ == "__main__":
    main()
