"""Creep compensation (issue 12): creep error with and without the compensator, adaptive vs frozen on a
drifting plant, and the per-sample cost. Prints JSON; ``--out`` writes it (bench/results/compensator.json).

1. ``staircase``: the demo plant (alpha 0.12, 420 Hz, zeta 0.08, b 2.5), 10 kHz, noise 2e-4, a staircase
   reference with 10 s holds (6 levels). Creep error = output (noise-free) minus reference, from the end
   of the resonance transient (the model's settling time, 33 ms) after each step to the end of its hold,
   first hold left out (the estimator starts there). Uncompensated: u = r / g with the plant's static
   gain 1 s after a step, g = b / Gamma(1 + alpha) (the usual open-loop calibration). ``known``: the
   compensator with the true model; ``adaptive``: with the live estimate (OnlineEstimator on the same loop).
2. ``drift``: the same, alpha +20 % and b +10 % over the 60 s (hil_sim/varying_plant.py), per seed
   (noise and reference levels); ``frozen`` takes the estimator's first good model only, ``oracle`` the
   true current parameters every millisecond (the limit of the frozen-time inverse);
   ``adaptive_no_change_test`` is the adaptive loop with ``OnlineEstimator(detect_changes=False)`` (a plant
   known to drift, not jump: the default change test can fire falsely in a compensated hold).
3. ``cost``: ``command()`` and ``set_model() + command()`` per sample at 10 kHz, thread CPU time and
   wall time (ns clocks), against ``OnlineEstimator.update()`` measured in the same run.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from creep_online.model import CreepModel  # noqa: E402
from creep_online.online import OnlineEstimator, warm_kernels  # noqa: E402
from creep_online.online.compensator import CreepCompensator  # noqa: E402
from creep_online.online.compensator import warm_kernels as warm_compensator  # noqa: E402
from creep_online.metrics import creep_error  # noqa: E402
from hil_sim.closed_loop import run_closed_loop, staircase  # noqa: E402

H = 1e-4
PLANT = CreepModel.from_resonance(0.12, 420.0, 0.08, 2.5)
HOLD_S = 10.0
LEVELS = (0.25, 0.75, 0.5, 1.0, 0.4, 0.8)
BANDWIDTH_HZ = 210.0     # half the plant's natural frequency, as a datasheet would give it


def dist(x: np.ndarray) -> dict:
    return {"p50": float(np.percentile(x, 50)), "p99": float(np.percentile(x, 99)), "max": float(np.max(x)),
            "mean": float(np.mean(x))}


def run_mode(mode: str, t, r, alpha=None, b=None, seed: int = 0, **est_kwargs) -> dict:
    est = OnlineEstimator(H, **est_kwargs) if mode in ("adaptive", "frozen") else None
    comp = CreepCompensator(H, bandwidth_hz=BANDWIDTH_HZ)
    t0 = time.perf_counter()
    if mode == "oracle":
        rec = _oracle(t, r, alpha, b, comp)
    else:
        rec = run_closed_loop(t, r, PLANT, mode, alpha=alpha, b=b, estimator=est, compensator=comp, seed=seed)
    ce = creep_error(t, r, rec.y_clean, PLANT.settling_time, skip_before=HOLD_S / 2)
    out = {"max_abs": ce["max_abs"], "rms": ce["rms"], "per_hold_max": [p["max_abs"] for p in ce["per_hold"]],
           "model_changes": len(rec.models), "run_s": time.perf_counter() - t0}
    if est is not None and est.model is not None:
        out["final_estimate"] = est.model.describe()
    if rec.models:
        out["first_model_t"] = rec.model_t[0]
    return out


def _oracle(t, r, alpha, b, comp):
    from hil_sim.closed_loop import LoopRecord
    from hil_sim.varying_plant import PlantStream
    stream = PlantStream(H, PLANT.alpha, PLANT.a1, PLANT.a2, PLANT.b)
    u, y = np.empty_like(t), np.empty_like(t)
    for k0 in range(0, t.size, 10):
        k1 = k0 + 10
        comp.set_model(CreepModel(alpha[k0], PLANT.a1, PLANT.a2, b[k0]))
        u[k0:k1] = comp.command_block(r[k0:k1])
        y[k0:k1] = stream.step_block(u[k0:k1], alpha[k0:k1], b[k0:k1])
    return LoopRecord(t, r, u, y, y, [], [])


def staircase_case(t) -> dict:
    r = staircase(t, LEVELS, HOLD_S, t_start=0.05)
    res = {m: run_mode(m, t, r) for m in ("uncompensated", "known", "adaptive")}
    for m in ("known", "adaptive"):
        res[m]["ratio_max"] = res["uncompensated"]["max_abs"] / res[m]["max_abs"]
        res[m]["ratio_rms"] = res["uncompensated"]["rms"] / res[m]["rms"]
    return res


def drift_case(t, seeds) -> dict:
    duration = t[-1] + H
    alpha = PLANT.alpha * (1 + 0.2 * t / duration)
    b = PLANT.b * (1 + 0.1 * t / duration)
    runs = []
    for seed in seeds:
        levels = LEVELS if seed == 0 else tuple(np.random.default_rng(seed).uniform(0.2, 1.0, len(LEVELS)))
        r = staircase(t, levels, HOLD_S, t_start=0.05)
        res = {m: run_mode(m, t, r, alpha, b, seed) for m in ("frozen", "adaptive", "oracle")}
        res["adaptive_no_change_test"] = run_mode("adaptive", t, r, alpha, b, seed, detect_changes=False)
        res["seed"] = seed
        for key, suffix in (("adaptive", ""), ("adaptive_no_change_test", "_no_change_test")):
            res["ratio_max" + suffix] = res["frozen"]["max_abs"] / res[key]["max_abs"]
            res["ratio_rms" + suffix] = res["frozen"]["rms"] / res[key]["rms"]
        runs.append(res)
        print(f"drift seed {seed}: frozen {res['frozen']['max_abs']:.4f} adaptive {res['adaptive']['max_abs']:.4f} "
              f"(no change test {res['adaptive_no_change_test']['max_abs']:.4f}) oracle {res['oracle']['max_abs']:.4f} "
              f"ratio {res['ratio_max']:.1f} / {res['ratio_max_no_change_test']:.1f}", file=sys.stderr)
    out = {"runs": runs}
    for suffix in ("", "_no_change_test"):
        ratios = np.array([x["ratio_max" + suffix] for x in runs])
        out.update({"pass_fraction_5x" + suffix: float(np.mean(ratios >= 5)),
                    "ratio_max_min" + suffix: float(ratios.min()),
                    "ratio_max_median" + suffix: float(np.median(ratios))})
    return out


def cost_case(n: int = 200_000) -> dict:
    warm_compensator()
    warm_kernels()
    t = np.arange(n) * H
    r = staircase(t, LEVELS, 0.5, t_start=0.01)
    comp = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
    other = CreepModel(0.125, PLANT.a1, PLANT.a2, 2.55)
    cpu, wall = np.empty(n), np.empty(n)
    cpu2, wall2 = np.empty(n), np.empty(n)
    for k in range(n):
        c0, w0 = time.thread_time_ns(), time.perf_counter_ns()
        comp.command(r[k])
        cpu[k], wall[k] = time.thread_time_ns() - c0, time.perf_counter_ns() - w0
    for k in range(n):
        m = PLANT if k % 2 else other
        c0, w0 = time.thread_time_ns(), time.perf_counter_ns()
        comp.set_model(m)
        comp.command(r[k])
        cpu2[k], wall2[k] = time.thread_time_ns() - c0, time.perf_counter_ns() - w0
    from creep_online.simulate import simulate
    y = simulate(PLANT, t, np.clip(r, 0, 1) / 2.0) + 2e-4 * np.random.default_rng(0).standard_normal(n)
    est = OnlineEstimator(H)
    ecpu = np.empty(n)
    u = np.clip(r, 0, 1) / 2.0
    for k in range(n):
        c0 = time.thread_time_ns()
        est.update(u[k], y[k])
        ecpu[k] = time.thread_time_ns() - c0
    t0 = time.perf_counter()
    CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ).command_block(r)
    block = (time.perf_counter() - t0) / n
    return {"samples": n, "command_cpu_us": dist(cpu / 1e3), "command_wall_us": dist(wall / 1e3),
            "set_model_and_command_cpu_us": dist(cpu2 / 1e3), "set_model_and_command_wall_us": dist(wall2 / 1e3),
            "estimator_update_cpu_us_same_run": dist(ecpu / 1e3),
            "ratio_command_to_update_p50": float(np.percentile(cpu, 50) / np.percentile(ecpu, 50)),
            "command_block_us_per_sample": block * 1e6, "budget_us": 25.0}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=5, help="drift runs (seed 0: the staircase levels)")
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--out", default=None)
    args = p.parse_args()
    warm_kernels()
    warm_compensator()
    t = np.arange(int(round(args.duration / H))) * H
    started = time.perf_counter()
    out = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "node": platform.node()},
           "command": " ".join(sys.argv), "plant": PLANT.describe(), "dt": H, "hold_s": HOLD_S,
           "bandwidth_hz": BANDWIDTH_HZ, "settle_s": PLANT.settling_time}
    out["staircase"] = staircase_case(t)
    print(f"staircase: uncompensated {out['staircase']['uncompensated']['max_abs']:.4f} "
          f"adaptive {out['staircase']['adaptive']['max_abs']:.2e}", file=sys.stderr)
    out["drift"] = drift_case(t, range(args.seeds))
    out["cost"] = cost_case()
    out["elapsed_s"] = time.perf_counter() - started
    text = json.dumps(out, indent=1)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
