"""Benchmark of ``diagnose`` on the real records of ``tests/data/real``: time, memory and the verdicts, against
the previous code in the same run.

Each record is diagnosed in a fresh interpreter (so that the peak resident
memory is that record's alone), by this code and by the previous one
(``--previous``, default main: ``git archive`` into a temporary directory,
its own numba cache), alternating record by record so that both see the same
load. Prints one JSON document (and writes ``bench/results/diagnose_real.json``):

* per record and code: wall seconds, CPU seconds of the process (every
  thread: the candidate fits run on threads) and of the main thread, peak
  resident memory (MB, ``ru_maxrss`` of the process or of any child it waited for, whichever is larger),
  the verdict, the base fit %, each
  candidate's fit % and evidence, the combination's;
* ``same``: per record, whether the verdict is the same and the largest
  difference of any fit % (base, candidates, combination) between the two;
* the goal (issue: a 50,000-sample record in at most 15 s and 300 MB) for the
  150 V piezo record, and the load average at the start and after each record;
* with ``--repeats N``: each record N times per code (alternating), the first
  run's verdict and fits, and ``runs``: p50/p99/max of the wall, CPU and peak
  memory over the N runs (the goal is judged on the p50).

Records: the real ones below, or ``hidden:EFFECT:SEED:N`` (``hil_sim.hidden_effects.hidden_dataset``, EFFECT
``none`` for a clean one), a long simulated record whose verdict and fits the two codes must share.

Usage: ``python -m bench.bench_diagnose_real [--records piezo_150V,...] [--previous REF] [--workers N] [--repeats N]``
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from bench.harness import ROOT, dist, results_path, write_report

#: The records: name -> how the worker loads it (a CSV path under tests/data/real, or the mirror's virtual SISO).
RECORDS = {
    "piezo_150V": "piezo-hyst-150V-1Hz/piezo_150V_1Hz.csv",
    "micromanipulator": "piezo-micromanipulator-1Hz/micromanipulator_1Hz.csv",
    "pe_creep": "pe-melt-creep-reptate/pe_cm3_creep_10Pa.csv",
    "pe_recovery": "pe-melt-creep-reptate/pe_cm3_recovery_10Pa.csv",
    "fsm_100mV": "fsm:100",
    "fsm_300mV": "fsm:300",
}
#: The issue's goal for a 50,000-sample record.
GOAL_SECONDS = 15.0
GOAL_MB = 300.0

#: Runs in a fresh interpreter with the code under test first on sys.path: diagnoses one record, prints JSON.
WORKER = r"""
import json, resource, sys, time
from pathlib import Path
import creep_online  # before numpy, as the command line: its one BLAS thread applies only if set before BLAS loads
import numpy as np
from creep_online.diagnostics import diagnose
from creep_online.diagnostics.loading import load_for_diagnosis
from creep_online.diagnostics.mimo import virtual_siso
real, what, workers = Path(sys.argv[1]), sys.argv[2], (int(sys.argv[3]) if sys.argv[3] else None)
if what.startswith("hidden:"):
    from hil_sim.hidden_effects import hidden_dataset
    _, effect, seed, n = what.split(":")
    ds = hidden_dataset(None if effect == "none" else effect, int(seed), n=int(n))
    args, kw = ((ds.t, ds.u, ds.y),), {}
elif what.startswith("fsm:"):
    ins, outs = [], []
    for r in range(3):
        a = np.loadtxt(real / "fsm-cubespec-multisine" / f"fsm_{what[4:]}mV_test_r{r}.csv.gz", delimiter=",",
                       skiprows=1)
        ins.append(a[:, [1, 3, 4]])
        outs.append(a[:, 2])
    args, kw = ((virtual_siso(ins, outs, fs=6400.0, period=8192, channel=0, periods=2)),), {}
else:
    inp = load_for_diagnosis(real / what)
    args, kw = (inp.record,), {"u_pre": inp.u_pre, "t_pre": inp.t_pre}
t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
d = diagnose(*args, workers=workers, **kw)
wall, cpu, main = time.perf_counter() - t0, time.process_time() - c0, time.thread_time() - m0
c = d.combination
print(json.dumps({
    "samples": int(d.data.n), "seconds": wall, "cpu_seconds": cpu, "main_thread_cpu_seconds": main,
    "peak_rss_mb": max(resource.getrusage(w).ru_maxrss for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)) / 1024.0,
    "verdict": d.verdict, "fit_percent_base": d.base.fit_percent,
    "candidates": [[x.effect, x.fit.fit_percent, x.evidence] for x in d.candidates],
    "combination": None if c is None else [c.effect, c.fit.fit_percent, c.evidence, bool(c.significant)]}))
"""

WARM_UP = r"""
from creep_online.diagnostics import diagnose
from hil_sim.hidden_effects import hidden_dataset
ds = hidden_dataset("hysteresis", 1, n=3000)
diagnose((ds.t, ds.u, ds.y))
"""


def run(path: str, code: str, *args: str) -> str:
    """``code`` in a fresh interpreter with ``path`` first on sys.path and its own numba cache; its stdout."""
    env = dict(os.environ, PYTHONPATH=path)
    if path != str(ROOT):
        env["NUMBA_CACHE_DIR"] = os.path.join(path, ".numba_cache")
    return subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True, text=True,
                          env=env, cwd=path).stdout


def compare(ours: dict, prev: dict) -> dict:
    """Same verdict, and the largest difference of any fit % (base, each candidate by name, the combination)."""
    diffs = [abs(ours["fit_percent_base"] - prev["fit_percent_base"])]
    theirs = {e: f for e, f, _ in prev["candidates"]}
    diffs += [abs(f - theirs[e]) for e, f, _ in ours["candidates"] if e in theirs]
    same_combo = (ours["combination"] or [None])[0] == (prev["combination"] or [None])[0]
    if ours["combination"] and prev["combination"] and same_combo:
        diffs.append(abs(ours["combination"][1] - prev["combination"][1]))
    return {"verdict": ours["verdict"] == prev["verdict"],
            "candidate_order": [e for e, _, _ in ours["candidates"]] == [e for e, _, _ in prev["candidates"]],
            "combination": same_combo, "max_fit_percent_difference": max(diffs)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", default=",".join(RECORDS), help=f"comma-separated, of {', '.join(RECORDS)} or hidden:EFFECT:SEED:N")
    p.add_argument("--previous", default="main", help="git ref of the previous code ('' to skip)")
    p.add_argument("--workers", default="", help="diagnose's workers (default: its own default)")
    p.add_argument("--repeats", type=int, default=1, help="runs of each record per code (p50/max reported)")
    p.add_argument("--out", default=str(results_path("diagnose_real")))
    a = p.parse_args()
    names = [n.strip() for n in a.records.split(",") if n.strip()]
    real = str(ROOT / "tests" / "data" / "real")
    codes = {"this": (str(ROOT), None)}
    if a.previous:
        from bench import _baseline
        path, commit = _baseline.extract(a.previous)
        codes["previous"] = (path, commit)
    for path, _ in codes.values():
        run(path, WARM_UP)                           # compiles (or loads) the numba kernels once
    rows, loads = {}, [os.getloadavg()]
    for i, name in enumerate(names):
        order = list(codes) if i % 2 == 0 else list(codes)[::-1]
        runs: dict[str, list[dict]] = {which: [] for which in codes}
        for _ in range(max(1, a.repeats)):
            for which in order:
                runs[which].append(json.loads(run(codes[which][0], WORKER, real, RECORDS.get(name, name),
                                                  a.workers).strip().splitlines()[-1]))
        row = {which: {**done[0], **({"runs": spread(done)} if len(done) > 1 else {})} for which, done in runs.items()}
        if "previous" in row:
            row["same"] = compare(row["this"], row["previous"])
            row["ratio"] = {k: typical(row["previous"], k) / typical(row["this"], k)
                            for k in ("seconds", "cpu_seconds", "peak_rss_mb")}
        rows[name] = row
        loads.append(os.getloadavg())
        write_report(summary(rows, a.workers, loads, codes), a.out, echo=False)   # each record as it is done
    write_report(summary(rows, a.workers, loads, codes), a.out)


def typical(run: dict, key: str) -> float:
    """A record's ``key`` (wall, CPU, memory): the p50 over repeated runs, else the one run's."""
    return run["runs"][key]["p50"] if "runs" in run else run[key]


def spread(done: list[dict]) -> dict:
    """p50/p99/max of the wall, CPU and peak memory over repeated runs of one record, and whether every run
    gave the first run's verdict and fits."""
    keys = ("seconds", "cpu_seconds", "main_thread_cpu_seconds", "peak_rss_mb")
    same = all((r["verdict"], r["candidates"], r["combination"]) == (done[0]["verdict"], done[0]["candidates"],
                                                                     done[0]["combination"]) for r in done)
    return {**{k: dist(r[k] for r in done) for k in keys}, "all_runs_same": same}


def summary(rows: dict, workers: str, loads: list, codes: dict) -> dict:
    """The JSON document of the records done so far."""
    out = {"records": rows, "workers": workers or "default", "load_average": loads,
           "previous_commit": codes.get("previous", (None, None))[1]}
    if "piezo_150V" in rows:
        r = rows["piezo_150V"]["this"]
        sec, mb = (r["runs"]["seconds"]["p50"], r["runs"]["peak_rss_mb"]["p50"]) if "runs" in r else (
            r["seconds"], r["peak_rss_mb"])
        out["goal"] = {"seconds": GOAL_SECONDS, "peak_rss_mb": GOAL_MB, "seconds_p50": sec, "peak_rss_mb_p50": mb,
                       "meets_seconds": sec <= GOAL_SECONDS, "meets_rss": mb <= GOAL_MB}
    if "previous" in codes:
        out["all_same_verdicts"] = all(r["same"]["verdict"] for r in rows.values())
    return out


if __name__ == "__main__":
    main()
