"""Benchmark of batch identification (issue 2). Prints one JSON document.

* recovery: the four reference experiments at 40 dB SNR, several seeds: worst
  relative error per parameter, fit% against the noise floor.
* remark4: the paper's Remark 4 -- layer-1 elapsed time and alpha for coarse
  steps 0.005 ... 0.04 s on a 60 s record, ours and FOMCON-style (eq. 13 full
  memory simulated at the coarse step, finite-difference TRF), same data.
* speed: whole two-layer identification warm, p50/p99/max over repeats, for
  12,000 samples (60 s at 200 Hz) and 100,000 samples (10 s at 10 kHz); the
  FOMCON-style baseline (full-memory eq. 13 + finite-difference TRF on all four
  parameters, from the same starting point) run once in the same process.

* --speed-only: warm p50/p99/max of this code and of --previous (default main; ``git
  archive`` into a temp dir, run in its own interpreter) alternating in three rounds,
  ratio of the p50s previous / ours, load average at the start and after each round; the ms per
  identify spent in the Van Loan exponentials (discretize.taylor_moments[_sensitivity]) in both;
  and the wall time of fresh ``creep-online --help`` and ``creep-online identify``
  (12,000 samples) processes.

Usage: python -m bench.bench_identify [--quick] [--speed-only [--previous REF]]   (--quick: fewer repeats; the 100,000-sample
baseline is then estimated from one eq. 13 simulation instead of run, which takes minutes)
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np
from scipy.optimize import least_squares


from creep_online import CreepModel  # noqa: E402
from creep_online.identification import identify, layer1_alpha  # noqa: E402
from creep_online.kernels import gl_paper  # noqa: E402
from creep_online.metrics import noise_floor_fit  # noqa: E402
from hil_sim.experiments import LOAD_CELL, NANOPOSITIONER, RECOVERY_CASES  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402


def distribution(samples: list[float]) -> dict[str, float]:
    """The harness summary with the fastest run."""
    return {"min": float(np.min(samples)), **dist(samples)}


def recovery(seeds: int) -> list[dict]:
    rows = []
    for case in RECOVERY_CASES:
        worst = dict.fromkeys(("alpha", "a1", "a2", "b"), 0.0)
        gap = []
        for seed in range(seeds):
            t, u, y, std = case.run(40.0, seed)
            res = identify(t, u, y)
            for k in worst:
                worst[k] = max(worst[k], abs(getattr(res.model, k) / getattr(case.model, k) - 1) * 100)
            gap.append(noise_floor_fit(y, std) - res.fit_percent)
        rows.append({"case": case.name, "samples": int(t.size), "truth": case.model.describe(),
                     "worst_error_percent": worst, "seeds": seeds,
                     "fit_below_noise_floor_points_max": float(max(gap))})
    return rows


# ----------------------------------------------------------------------------- FOMCON-style baselines
def fomcon_layer1(t, u, y, step, a1, a2, alpha0):
    """Layer 1 the FOMCON way: data subsampled at ``step``, eq. 13 simulated (full memory) at that
    step for every residual, alpha and gain as free parameters, finite-difference TRF."""
    h = t[1] - t[0]
    k = max(1, int(round(step / h)))
    ts, us, ys = t[::k], u[::k], y[::k]
    hs = ts[1] - ts[0]

    def residual(p):
        return ys - p[1] * gl_paper(us, hs, p[0], a1, a2, -1)

    t0 = time.perf_counter()
    sol = least_squares(residual, [alpha0, 1.0], bounds=([1e-4, -np.inf], [0.999, np.inf]), method="trf")
    return float(sol.x[0]), time.perf_counter() - t0, int(sol.nfev)


def fomcon_full(t, u, y, start: CreepModel):
    """Whole identification the FOMCON way: eq. 13 full memory + finite-difference TRF on all four."""
    h = t[1] - t[0]

    def residual(p):
        return y - p[3] * gl_paper(u, h, p[0], math.exp(p[1]), math.exp(p[2]), -1)

    p0 = [start.alpha, math.log(start.a1), math.log(start.a2), start.b]
    t0 = time.perf_counter()
    sol = least_squares(residual, p0, method="trf",
                        bounds=([1e-4, -np.inf, -np.inf, -np.inf], [0.999, np.inf, np.inf, np.inf]))
    return sol, time.perf_counter() - t0


def remark4() -> dict:
    case = LOAD_CELL
    t, u, y, _ = case.run(40.0, seed=0)
    ref = identify(t, u, y)
    m = ref.model
    rows = []
    for step in (0.005, 0.01, 0.02, 0.03, 0.04):
        ours = []
        for _ in range(20):
            t0 = time.perf_counter()
            alpha, _, info = layer1_alpha(t, u, y, ref.t_c, a1=m.a1, a2=m.a2, step=step)
            ours.append(time.perf_counter() - t0)
        f_alpha, f_el, f_nfev = fomcon_layer1(t, u, y, step, m.a1, m.a2, 0.1)
        rows.append({"step_s": step, "ours": {"alpha": alpha, "elapsed_s": distribution(ours),
                                               "points": info["points"]},
                     "fomcon_style": {"alpha": f_alpha, "elapsed_s": f_el, "nfev": f_nfev},
                     "paper_fomcon_s": {0.005: 29, 0.01: 7, 0.02: 2, 0.03: 1, 0.04: "<1"}[step]})
    return {"record": f"{case.name}, 60 s at 200 Hz, 40 dB", "true_alpha": case.model.alpha, "t_c": ref.t_c,
            "rows": rows}


def speed(repeats: int, full_baseline: bool) -> dict:
    out = {}
    for case in (LOAD_CELL, NANOPOSITIONER):
        t, u, y, _ = case.run(40.0, seed=1)
        identify(t, u, y)  # warm (numba cache, imports)
        times = []
        for _ in range(repeats):
            res = identify(t, u, y)
            times.append(res.elapsed_s)
        entry = {"samples": int(t.size), "elapsed_s": distribution(times)}
        start = CreepModel(res.stages["start"]["alpha"], 1.0, 1.0).from_resonance(
            res.stages["start"]["alpha"], res.stages["start"]["fn_hz"], res.stages["start"]["zeta"], 1.0)
        if t.size <= 20000 or full_baseline:
            sol, el = fomcon_full(t, u, y, start)
            entry["baseline_fomcon_style"] = {
                "elapsed_s": el, "nfev": int(sol.nfev), "alpha": float(sol.x[0]),
                "a1": math.exp(sol.x[1]), "a2": math.exp(sol.x[2]), "b": float(sol.x[3])}
            entry["speedup_vs_baseline_p50"] = el / entry["elapsed_s"]["p50"]
        else:
            # one full-memory eq. 13 simulation is O(N^2): time it once; the baseline needs dozens
            t0 = time.perf_counter()
            gl_paper(u, t[1] - t[0], start.alpha, start.a1, start.a2, -1)
            one = time.perf_counter() - t0
            entry["baseline_one_eq13_simulation_s"] = one
            entry["speedup_lower_bound_vs_one_simulation"] = one / entry["elapsed_s"]["p50"]
        out[case.name] = entry
    return out


#: Runs in the previous code's interpreter: warm times of identify on the speed records (one round).
PREVIOUS_CODE = """
import json, sys, time
import numpy as np
from creep_online.identification import identify
try:
    from hil_sim.experiments import LOAD_CELL, NANOPOSITIONER
except ImportError:  # a revision before the presets moved out of the library
    from creep_online.plants import LOAD_CELL, NANOPOSITIONER
out = {}
for case in (LOAD_CELL, NANOPOSITIONER):
    t, u, y, _ = case.run(40.0, seed=1)
    identify(t, u, y)
    times = []
    for _ in range(int(sys.argv[1])):
        t0 = time.perf_counter()
        identify(t, u, y)
        times.append(time.perf_counter() - t0)
    out[case.name] = times
print(json.dumps(out))
"""


def speed_vs_previous(repeats: int, ref: str, rounds: int = 3) -> dict:
    """Warm times of this code and of ``ref`` (git archive, own interpreter), alternating in rounds so
    both see the same machine load: p50/p99/max of each, ratio = previous p50 / ours, load averages."""
    from bench import _baseline
    path, commit = _baseline.extract(ref)
    _baseline.run_python(path, PREVIOUS_CODE, "1")           # compile its numba cache once
    ours = {c.name: [] for c in (LOAD_CELL, NANOPOSITIONER)}
    prev = {c.name: [] for c in (LOAD_CELL, NANOPOSITIONER)}
    data = {c.name: c.run(40.0, seed=1) for c in (LOAD_CELL, NANOPOSITIONER)}
    for t, u, y, _ in data.values():
        identify(t, u, y)
    loads = [os.getloadavg()]
    for _ in range(rounds):
        for name, (t, u, y, _) in data.items():
            for _ in range(repeats):
                t0 = time.perf_counter()
                identify(t, u, y)
                ours[name].append(time.perf_counter() - t0)
        for name, times in json.loads(_baseline.run_python(path, PREVIOUS_CODE, str(repeats))).items():
            prev[name] += times
        loads.append(os.getloadavg())
    out = {"previous_commit": commit, "repeats_per_round": repeats, "rounds": rounds,
           "load_average_1_5_15min": loads}
    for name in ours:
        mine, theirs = distribution(ours[name]), distribution(prev[name])
        out[name] = {"samples": int(data[name][0].size), "this_code_s": mine, "previous_s": theirs,
                     "p50_s": mine["p50"], "previous_p50_s": theirs["p50"], "speedup": theirs["p50"] / mine["p50"]}
    return out


#: Runs in either code's interpreter: ms per warm identify spent in the Van Loan exponentials
#: (``discretize.taylor_moments_sensitivity``, and ``taylor_moments`` outside it), and the calls.
PARTS_CODE = """
import json, sys, time
from creep_online import discretize as d
from creep_online import identification as ident
from hil_sim.experiments import LOAD_CELL, NANOPOSITIONER
out = {}
for case in (LOAD_CELL, NANOPOSITIONER):
    t, u, y, _ = case.run(40.0, seed=1)
    ident.identify(t, u, y)
    acc = {"s": 0.0, "calls": 0, "depth": 0}
    def timed(f):
        def wrapper(*a, **k):
            t0 = time.perf_counter(); acc["depth"] += 1
            try:
                return f(*a, **k)
            finally:
                acc["depth"] -= 1
                if acc["depth"] == 0:
                    acc["s"] += time.perf_counter() - t0; acc["calls"] += 1
        return wrapper
    plain, sens = d.taylor_moments, d.taylor_moments_sensitivity
    d.taylor_moments, d.taylor_moments_sensitivity = timed(plain), timed(sens)
    reps = int(sys.argv[1])
    for _ in range(reps):
        ident.identify(t, u, y)
    d.taylor_moments, d.taylor_moments_sensitivity = plain, sens
    out[case.name] = {"exponentials_ms_per_identify": acc["s"] / reps * 1e3, "calls_per_identify": acc["calls"] / reps}
print(json.dumps(out))
"""


def exponential_parts(repeats: int, ref: str) -> dict:
    """Time per warm identify inside the Van Loan exponentials, this code and ``ref`` (each in its own
    interpreter): the saving where it happens, less exposed to machine load than the whole identify."""
    from bench import _baseline
    path, commit = _baseline.extract(ref)
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return {"previous_commit": commit, "load_average_start": os.getloadavg(),
            "this_code": json.loads(_baseline.run_python(here, PARTS_CODE, str(repeats))),
            "previous": json.loads(_baseline.run_python(path, PARTS_CODE, str(repeats)))}


def cold_cli(repeats: int) -> dict:
    """Wall time of fresh ``creep-online`` processes: --help, and identify of 12,000 samples (numba cache warm)."""
    import subprocess
    import tempfile
    t, u, y, _ = LOAD_CELL.run(40.0, seed=1)
    path = os.path.join(tempfile.mkdtemp(prefix="creep_cli_"), "load_cell.csv")
    np.savetxt(path, np.column_stack((t, u, y)), delimiter=",", header="t,u,y", comments="")
    cmd = [sys.executable, "-m", "creep_online"]
    out = {}
    for label, args in (("help", ["--help"]), ("identify_12000", ["identify", path, "--json"])):
        subprocess.run(cmd + args, check=True, capture_output=True)   # caches (numba, OS) warm
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            subprocess.run(cmd + args, check=True, capture_output=True)
            times.append(time.perf_counter() - t0)
        out[label] = distribution(times)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer seeds and repeats")
    ap.add_argument("--speed-only", action="store_true",
                    help="only the warm speed against --previous and the cold command line")
    ap.add_argument("--previous", default="main", help="git ref of the previous code for the speed ratio")
    args = ap.parse_args()
    if args.speed_only:
        report = {"bench": "identify_speed", "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
                  "warm": speed_vs_previous(5 if args.quick else 15, args.previous),
                  "exponentials": exponential_parts(5 if args.quick else 10, args.previous),
                  "cold_cli": cold_cli(5 if args.quick else 10), "load_average_end": os.getloadavg()}
        write_report(report, indent=2)
        return
    report = {
        "bench": "identify", "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "recovery": recovery(2 if args.quick else 5),
        "speed": speed(5 if args.quick else 30, full_baseline=not args.quick),
        "remark4": remark4(),
    }
    write_report(report, indent=2)


if __name__ == "__main__":
    main()
