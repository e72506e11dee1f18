"""Where a long diagnosis' memory and CPU go, stage by stage: the 150 V piezo record (50,001 samples).

Runs in fresh interpreters (the record's numbers are that process' alone) and prints one JSON document
(and writes ``bench/results/diagnose_phases.json``):

* ``imports``: resident memory (MB) and seconds each import adds, in the order ``diagnose`` needs them
  (numpy, scipy's parts, numba, the package's kernels and diagnostics);
* ``kernels``: each compiled kernel ``diagnose`` calls, loaded from numba's cache one after the other:
  resident memory it adds (the first load also starts numba's code generator) and seconds;
* ``stages``: per stage of ``diagnose`` (its ``progress`` messages; each candidate fit on the whole record
  and each pair fit of the search apart): resident memory at its end and its peak within it (Linux
  ``VmHWM``, reset at each stage start), CPU seconds of the process in it; and with ``--traced`` (slower,
  a second run) the live Python and numpy memory (``tracemalloc``) at its end and its peak within it.

``workers=1`` by default (every stage in the calling thread, so the stages' CPU and peaks are their own).

Usage: ``python -m bench.bench_diagnose_phases [--workers N] [--traced]``
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from bench.harness import ROOT, results_path, write_report

RECORD = "tests/data/real/piezo-hyst-150V-1Hz/piezo_150V_1Hz.csv"

#: Imports, one after the other, as diagnose loads them.
IMPORTS = ["numpy", "creep_online", "scipy.linalg", "scipy.fft", "scipy.optimize", "scipy.interpolate",
           "scipy.special", "scipy.ndimage", "numba", "creep_online.kernels", "creep_online.diagnostics.explain"]

_COMMON = r"""
import json, os, sys, time
def status(field):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field):
                return int(line.split()[1]) / 1024.0
def reset_peak():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass
"""

IMPORT_WORKER = _COMMON + r"""
import importlib
out, last = [], status("VmRSS")
for name in sys.argv[1].split(","):
    t = time.perf_counter()
    importlib.import_module(name)
    now = status("VmRSS")
    out.append({"module": name, "added_mb": now - last, "rss_mb": now, "seconds": time.perf_counter() - t})
    last = now
print(json.dumps(out))
"""

KERNEL_WORKER = _COMMON + r"""
import gc, importlib, pickle
from numba.core.registry import CPUDispatcher
if sys.argv[1] == "record":      # which kernels a (short) diagnosis calls, with their signatures
    from creep_online.diagnostics import diagnose
    from hil_sim.hidden_effects import hidden_dataset
    ds = hidden_dataset("hysteresis", 1, n=3000)
    diagnose((ds.t, ds.u, ds.y), workers=1)
    used = {o.py_func.__module__ + ":" + o.py_func.__name__: list(o.signatures) for o in gc.get_objects()
            if isinstance(o, CPUDispatcher) and o.overloads and o.py_func.__module__.startswith("creep_online")}
    sys.stdout.buffer.write(pickle.dumps(used))
else:
    import scipy.optimize, scipy.ndimage, creep_online.kernels, creep_online.diagnostics.explain
    used = pickle.loads(sys.stdin.buffer.read())
    out, last = [], status("VmRSS")
    for key, sigs in used.items():
        module, name = key.split(":")
        dispatcher = getattr(importlib.import_module(module), name)
        t = time.perf_counter()
        for sig in sigs:
            dispatcher.compile(sig)
        now = status("VmRSS")
        out.append({"kernel": key, "added_mb": now - last, "seconds": time.perf_counter() - t,
                    "from_cache": all(dispatcher.stats.cache_hits.get(s, 0) for s in sigs)})
        last = now
    print(json.dumps(out))
"""

STAGE_WORKER = _COMMON + r"""
traced = sys.argv[2] == "1"
if traced:
    import tracemalloc
    tracemalloc.start(1)
from pathlib import Path
import creep_online
from creep_online.diagnostics import diagnose
from creep_online.diagnostics import extended as ext
from creep_online.diagnostics.loading import load_for_diagnosis
inp = load_for_diagnosis(Path(sys.argv[1]))
stages, current = [], {"name": "imports and the record", "cpu": 0.0}
def close(next_name):
    row = {"stage": current["name"], "rss_mb": status("VmRSS"), "peak_rss_mb": status("VmHWM"),
           "cpu_seconds": time.process_time() - current["cpu"]}
    if traced:
        live, peak = tracemalloc.get_traced_memory()
        row.update(live_mb=live / 2**20, peak_live_mb=peak / 2**20)
        tracemalloc.reset_peak()
    stages.append(row)
    current.update(name=next_name, cpu=time.process_time())
    reset_peak()
close("start")
fit_extended = ext.fit_extended
def each_fit(data, effects, *a, **k):     # a fit on the whole record, or one of the pair search: a stage of its own
    close(f"fit {'+'.join(effects)} ({data.n} samples)")
    try:
        return fit_extended(data, effects, *a, **k)
    finally:
        close("between fits")
ext.fit_extended = each_fit
c0 = time.process_time()
d = diagnose(inp.record, u_pre=inp.u_pre, t_pre=inp.t_pre, workers=int(sys.argv[3]), progress=close)
close("end")
print(json.dumps({"stages": [s for s in stages if s["stage"] != "between fits" or s["cpu_seconds"] > 0.05],
                  "peak_rss_mb": max(s["peak_rss_mb"] for s in stages),
                  "scipy_signal_or_stats": sorted(m for m in sys.modules if m.startswith(("scipy.signal", "scipy.stats"))),
                  "cpu_seconds": time.process_time() - c0, "verdict": d.verdict,
                  "candidates": [c.effect for c in d.candidates],
                  "combination": None if d.combination is None else d.combination.effect}))
"""


def run(code: str, *args: str, stdin: bytes | None = None) -> bytes:
    """``code`` in a fresh interpreter with this checkout first on sys.path; its stdout."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True, input=stdin,
                          env=env, cwd=ROOT).stdout


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", default="1", help="diagnose's workers (1: every stage in the calling thread)")
    p.add_argument("--traced", action="store_true", help="also the live Python/numpy memory (tracemalloc)")
    p.add_argument("--out", default=str(results_path("diagnose_phases")))
    a = p.parse_args()
    doc = {"record": RECORD, "workers": a.workers, "load_average": [os.getloadavg()]}
    doc["imports"] = json.loads(run(IMPORT_WORKER, ",".join(IMPORTS)))
    doc["kernels"] = json.loads(run(KERNEL_WORKER, "load", stdin=run(KERNEL_WORKER, "record")))
    doc["run"] = json.loads(run(STAGE_WORKER, str(ROOT / RECORD), "0", a.workers))
    if a.traced:
        doc["traced_run"] = json.loads(run(STAGE_WORKER, str(ROOT / RECORD), "1", a.workers))
    doc["load_average"].append(os.getloadavg())
    write_report(doc, a.out)


if __name__ == "__main__":
    main()
