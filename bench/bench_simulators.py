"""Accuracy and speed of the simulators (issue 2). Prints one JSON document.

* convergence: max error relative to the peak output against the exact
  references in tests/data/oracle, for h, 2h, 4h, ... and the fitted order.
* truncation: error of short memory L against full memory for a unit step
  (the dropped tail ((N h)^alpha - (L h)^alpha) / Gamma(1+alpha)) and for the
  whole model, for several alpha and N/L.
* speed: each simulator on 12,000 and 100,000 samples, p50/p99/max over repeats.

Usage: python -m bench.bench_simulators [--quick]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from creep_online import CreepModel, simulate  # noqa: E402
from creep_online.simulate import fractional_integral  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402

ORACLE = ROOT / "tests" / "data" / "oracle"


def convergence() -> list[dict]:
    rows = []
    for ref in json.loads((ORACLE / "exact_refs.json").read_text()):
        data = np.loadtxt(ORACLE / f"{ref['name']}.csv", delimiter=",", skiprows=1)
        m = CreepModel(ref["alpha"], ref["a1"], ref["a2"], ref["b"])
        peak = float(np.max(np.abs(data[:, 2])))
        entry = {"reference": ref["name"], "h_s": [], "error": {"exact": [], "split": [], "paper": []}}
        for stride in (32, 16, 8, 4, 2, 1):
            sub = data[::stride]
            coarse = stride * ref["h"]
            on_grid = all(abs(ts / coarse - round(ts / coarse)) < 1e-9 for ts in ref["step_times"])
            if not on_grid or (sub.shape[0] > 20001 and stride < 2):
                continue  # an input change between coarse samples would be a different input
            entry["h_s"].append(float(sub[1, 0] - sub[0, 0]))
            for method, errs in entry["error"].items():
                if method == "paper" and sub.shape[0] > 20001:
                    errs.append(None)
                    continue
                y = simulate(m, sub[:, 0], sub[:, 1], method=method)
                errs.append(float(np.max(np.abs(y - sub[:, 2])) / peak))
        entry["order"] = {}
        for method, errs in entry["error"].items():
            pts = [(h, e) for h, e in zip(entry["h_s"], errs) if e is not None and e > 1e-12]
            if len(pts) >= 3:
                hs, es = zip(*pts)
                entry["order"][method] = float(np.polyfit(np.log(hs), np.log(es), 1)[0])
        rows.append(entry)
    return rows


def truncation() -> list[dict]:
    rows = []
    h, n = 1e-3, 20000
    t = np.arange(n) * h
    for alpha in (0.0133, 0.05, 0.2, 0.5, 0.8):
        z_full = fractional_integral(np.ones(n), h, alpha)
        m = CreepModel.from_resonance(alpha, 20.0, 0.2)
        y_full = simulate(m, t, np.ones(n), method="split")
        for ratio in (2, 5, 10, 100):
            memory = n // ratio
            z = fractional_integral(np.ones(n), h, alpha, memory=memory)
            y = simulate(m, t, np.ones(n), method="split", memory=memory)
            tail = ((n - 1) * h) ** alpha - (memory * h) ** alpha
            rows.append({"alpha": alpha, "N_over_L": ratio, "L": memory,
                         "step_integral_rel_error_at_end": float((z_full[-1] - z[-1]) / z_full[-1]),
                         "predicted_tail_rel": float(tail / math.gamma(1 + alpha) / z_full[-1]),
                         "model_output_rel_error_at_end": float(abs(y_full[-1] - y[-1]) / abs(y_full[-1]))})
    return rows


def speed(repeats: int) -> list[dict]:
    rows = []
    m = CreepModel.from_resonance(0.05, 100.0, 0.1)
    for n, h in ((12000, 5e-3), (100000, 1e-4)):
        t = np.arange(n) * h
        u = np.where(t > t[n // 2], 0.5, 1.0)
        for method in ("exact", "split", "paper"):
            reps = repeats if (method != "paper" or n <= 12000) else 1
            simulate(m, t[:100], u[:100], method=method)
            times = []
            for _ in range(reps):
                t0 = time.perf_counter()
                simulate(m, t, u, method=method)
                times.append(time.perf_counter() - t0)
            rows.append({"samples": n, "method": method, "elapsed_s": dist(times)})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    out = {"bench": "simulators", "convergence": convergence(), "truncation": truncation(),
           "speed": speed(3 if args.quick else 15)}
    write_report(out, indent=2)


if __name__ == "__main__":
    main()
