"""Cold start of the ``creep-online`` program: fresh processes, this code against the previous code.

For ``--help``, ``--version``, ``identify --help`` and ``identify FILE`` (12,000 samples: the load-cell
experiment, 60 s at 200 Hz) each run is a new interpreter (``python -m creep_online``) with the compiled
kernels already in numba's cache and the modules' bytecode written (one warm-up run per command and version
first, so the OS file cache is warm too; an installed package has its bytecode, pip compiles it, so the
children may write it even when ``PYTHONDONTWRITEBYTECODE`` is set here). The two versions alternate run by
run, so load on the machine hits both alike. Wall time and the process's own CPU time (user + sys, from the
child's rusage) are reported: on a shared machine the CPU time is the steadier figure. Targets: ``--help``
<= 0.15 s, ``identify`` <= 0.6 s (best of 5 wall).

``identify_12000_phases_cpu_s`` says where a cold ``identify`` spends its own CPU (minimum over the repeats
of each phase, both versions): the interpreter and the program's parser, numpy, scipy.linalg (numba's first
dispatch imports it for BLAS), numba, creep_online's modules, numba's first dispatch of a cached kernel (its
target context and runtime), the command (reading the CSV, loading the other kernels, the fit, the JSON) and
the interpreter's shutdown (the child's total CPU minus what it had used when the command returned).

Usage: python -m bench.bench_cold_start [--repeats 5] [--previous REF] [--out FILE]
(prints one JSON document; --out writes it too, e.g. bench/results/cold_start.json)
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from bench import _baseline
from bench.harness import write_report
from hil_sim.experiments import LOAD_CELL

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

TARGETS_S = {"help": 0.15, "identify_12000": 0.6}


def record_file(directory: str) -> str:
    """The 12,000-sample load-cell record as a t,u,y CSV."""
    t, u, y, _ = LOAD_CELL.run(40.0, seed=1)
    path = os.path.join(directory, "load_cell_12000.csv")
    np.savetxt(path, np.column_stack((t, u, y)), delimiter=",", header="t,u,y", comments="")
    return path


def run_once(code_dir: str, args: list[str], cwd: str, env: dict[str, str]) -> tuple[float, float]:
    """(wall s, user+sys CPU s) of one fresh ``python -m creep_online ARGS`` with ``code_dir`` first on the path."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "creep_online", *args], check=True, capture_output=True, cwd=cwd,
                   env=dict(env, PYTHONPATH=code_dir))
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


#: Run in a fresh interpreter: ``creep-online identify PATH --json`` as the program runs it (``console``, its
#: shutdown included), with the heavy imports and numba's first dispatch taken one by one before it. Prints
#: the process's own CPU at each mark as one ``PHASES`` line on stderr.
_PHASE_PROBE = """
import json, resource, sys
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
marks = []
def mark(name):
    marks.append((name, cpu()))
mark("interpreter")
import creep_online.cli
mark("program")
import numpy
mark("numpy")
import scipy.linalg
mark("scipy.linalg")
import numba
mark("numba")
import creep_online.identification, creep_online.io.csvfile
mark("creep_online modules")
from creep_online import kernels
kernels.second_differences(numpy.zeros(3))
mark("numba first dispatch")
sys.argv = ["creep-online", "identify", PATH, "--json"]
try:
    creep_online.cli.console()
except SystemExit as stop:
    code = stop.code
mark("identify command")
print("PHASES " + json.dumps(marks), file=sys.stderr)
raise SystemExit(code)
"""


def run_phases(code_dir: str, path: str, cwd: str, env: dict[str, str]) -> dict[str, float]:
    """Own CPU s of each phase of one cold ``identify`` (see the module notes), ``shutdown`` and ``total``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([sys.executable, "-c", _PHASE_PROBE.replace("PATH", repr(path))], check=True,
                         capture_output=True, text=True, cwd=cwd, env=dict(env, PYTHONPATH=code_dir))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    total = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    line = next(x for x in out.stderr.splitlines() if x.startswith("PHASES "))
    marks = json.loads(line[len("PHASES "):])
    phases, previous = {}, 0.0
    for name, at in marks:
        phases[name], previous = at - previous, at
    phases["shutdown"] = total - previous
    phases["total"] = total
    return phases


def summary(values: list[float]) -> dict[str, float]:
    return {"best": min(values), "median": statistics.median(values), "max": max(values), "n": len(values)}


def modules_loaded(code_dir: str, args: list[str], cwd: str, env: dict[str, str]) -> list[str]:
    """Which of numpy, scipy, numba, rich, pandas a command imports (``-X importtime`` of one run)."""
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "creep_online", *args], capture_output=True,
                         text=True, cwd=cwd, env=dict(env, PYTHONPATH=code_dir))
    names = {line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines() if line.startswith("import time:")}
    return sorted(n for n in ("numpy", "scipy", "scipy.optimize", "scipy.special", "numba", "rich", "pandas")
                  if n in names)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--previous", default="main", help="git ref of the previous code (the baseline)")
    ap.add_argument("--out", default=None, help="also write the JSON document to this file")
    opts = ap.parse_args()

    previous_dir, previous_commit = _baseline.extract(opts.previous)
    work = tempfile.mkdtemp(prefix="creep_cold_")   # neutral cwd: `python -m` puts the cwd first on sys.path
    path = record_file(work)
    commands = {"help": ["--help"], "version": ["--version"], "identify_help": ["identify", "--help"],
                "identify_12000": ["identify", path, "--json"]}
    installed = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}   # bytecode kept
    versions = {"this_code": (ROOT, installed),
                "previous": (previous_dir, dict(installed, NUMBA_CACHE_DIR=os.path.join(previous_dir, ".numba")))}
    for code_dir, env in versions.values():
        for args in commands.values():
            run_once(code_dir, args, work, env)   # numba cache compiled, files in the OS cache
    load_start = os.getloadavg()
    samples = {v: {c: {"wall": [], "cpu": []} for c in commands} for v in versions}
    for _ in range(opts.repeats):
        for label, args in commands.items():
            for version, (code_dir, env) in versions.items():
                wall, cpu = run_once(code_dir, args, work, env)
                samples[version][label]["wall"].append(wall)
                samples[version][label]["cpu"].append(cpu)
    phase_runs = {v: [] for v in versions}
    for _ in range(opts.repeats):
        for version, (code_dir, env) in versions.items():
            phase_runs[version].append(run_phases(code_dir, path, work, env))
    phases = {v: {name: min(run[name] for run in runs) for name in runs[0]} for v, runs in phase_runs.items()}
    results = {v: {c: {"wall_s": summary(s["wall"]), "cpu_s": summary(s["cpu"]),
                       "imports": modules_loaded(versions[v][0], commands[c], work, versions[v][1])}
                   for c, s in by_cmd.items()} for v, by_cmd in samples.items()}
    ratios = {c: {"wall_best": results["previous"][c]["wall_s"]["best"] / results["this_code"][c]["wall_s"]["best"],
                  "cpu_best": results["previous"][c]["cpu_s"]["best"] / results["this_code"][c]["cpu_s"]["best"]}
              for c in commands}
    targets = {c: {"target_wall_s": lim, "best_wall_s": results["this_code"][c]["wall_s"]["best"],
                   "met": results["this_code"][c]["wall_s"]["best"] <= lim} for c, lim in TARGETS_S.items()}
    shutil.rmtree(previous_dir, ignore_errors=True)
    shutil.rmtree(work, ignore_errors=True)
    write_report({"bench": "cold_start", "repeats": opts.repeats, "samples": 12000,
                      "previous_commit": previous_commit, "python": platform.python_version(),
                      "cpus": os.cpu_count(), "load_average_start": load_start, "load_average_end": os.getloadavg(),
                      "bytecode": "written by the warm-up runs (PYTHONDONTWRITEBYTECODE unset in the children)",
                      "results": results, "ratio_previous_over_this": ratios, "targets": targets,
                      "identify_12000_phases_cpu_s": {"statistic": f"minimum of each phase over {opts.repeats} runs",
                                                      **phases}}, opts.out, indent=2)


if __name__ == "__main__":
    main()
