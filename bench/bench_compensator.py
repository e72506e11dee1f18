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
   ``adaptive_no_change_test`` is the adaptive loop with ``OnlineEstimator(detect_changes=False)``.
3. ``random`` (``random_plants``): ``hil_sim.closed_loop.random_drifting_plant(seed)`` (alpha 0.02-0.6,
   fn 100-2000 Hz, zeta 0.02-0.7, b of random sign and magnitude 0.1-10), a 6-level staircase over
   ``--random-duration`` (60 s: 10 s holds, the first left out) with alpha +20 % and b +10 % over it;
   frozen vs adaptive per setting (estimator default or ``detect_changes=False``; the adaptive loop's
   ``online.gate`` on, or off: only ``good`` estimates, the policy before the gate and the baseline measured
   in the same run) and the oracle (true parameters every 10 ms). Reported: the fraction reaching 5x, and the fraction where even the oracle
   reaches 5x against that frozen compensator (a large alpha's drift re-weights the whole history,
   which no frozen-time inverse undoes).
4. ``cost``: ``command()`` alone, as it was before the packed buffer (``command_before_16_args``: the
   baseline), numba's dispatch alone with 16 and with 4 arguments (functions that do nothing), a call that only
   computes for as long as ``command()`` takes at the median (no memory: how often the machine interrupts a call
   of that length), with a model
   change every 0.1 s (the estimator's re-fit period) and every sample, each against an empty call timed in
   the same loop (interleaved: the same machine), thread
   CPU and wall time; calls over the 25 us budget per second of loop time, minus the empty call's
   (noise-corrected); garbage-collector passes marked; the first model's replay of the pass-through
   history; ``command()`` with warm caches and after an 8 MB sweep between calls (``cold_cache``: what a
   call costs when something else ran on the core); ``OnlineEstimator.update()`` in the same run.
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

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from creep_online.model import CreepModel  # noqa: E402
from creep_online.online import OnlineEstimator, warm_kernels  # noqa: E402
from creep_online.online.compensator import CreepCompensator  # noqa: E402
from creep_online.online.compensator import warm_kernels as warm_compensator  # noqa: E402
from creep_online.online import compensator_kernels as CK  # noqa: E402
from creep_online.metrics import creep_error  # noqa: E402
from hil_sim.closed_loop import run_closed_loop, staircase  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402

H = 1e-4
PLANT = CreepModel.from_resonance(0.12, 420.0, 0.08, 2.5)
HOLD_S = 10.0
LEVELS = (0.25, 0.75, 0.5, 1.0, 0.4, 0.8)
BANDWIDTH_HZ = 210.0     # half the plant's natural frequency, as a datasheet would give it


def run_mode(mode: str, t, r, alpha=None, b=None, seed: int = 0, **est_kwargs) -> dict:
    """One closed-loop run of the demo plant (``oracle``: the true parameters every 10 samples)."""
    est = OnlineEstimator(H, **est_kwargs) if mode in ("adaptive", "frozen") else None
    comp = CreepCompensator(H, bandwidth_hz=BANDWIDTH_HZ)
    t0 = time.perf_counter()
    rec = run_closed_loop(t, r, PLANT, mode, alpha=alpha, b=b, estimator=est, compensator=comp, seed=seed)
    ce = creep_error(t, r, rec.y_clean, PLANT.settling_time, skip_before=HOLD_S / 2)
    out = {"max_abs": ce["max_abs"], "rms": ce["rms"], "per_hold_max": [p["max_abs"] for p in ce["per_hold"]],
           "model_changes": len(rec.models), "run_s": time.perf_counter() - t0}
    if est is not None and est.model is not None:
        out["final_estimate"] = est.model.describe()     # (frozen: when it froze; it is not fed after)
    if rec.models:
        out["first_model_t"] = rec.model_t[0]
    return out


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


#: Settings compared on the random drifting plants: (estimator keyword arguments, the adaptive loop's gate).
#: ``gate=False`` is the policy before ``online.gate``: only ``good`` estimates (the baseline, same run).
#: ``closed_loop.drifting_comparison`` feeds its estimator with ``input_gate=0`` (the compensator's own commands);
#: ``input_gate=20`` is the estimator's default glitch gate, as before.
SETTINGS = {"gate": ({}, True), "gate_no_change_test": ({"detect_changes": False}, True),
            "gate_input_gate_20": ({"input_gate": 20.0}, True), "before": ({"input_gate": 20.0}, False),
            "before_no_change_test": ({"input_gate": 20.0, "detect_changes": False}, False)}


def _random_one(seed: int, duration: float, settings: tuple = tuple(SETTINGS)) -> dict:
    """One random drifting plant: frozen (once per estimator setting: the gate does not change it) and
    adaptive per setting, and the oracle."""
    from hil_sim.closed_loop import drifting_comparison
    t0 = time.perf_counter()
    res = drifting_comparison(seed, duration, modes=("oracle",))
    res["seed"] = seed
    frozen: dict = {}
    for name in settings:
        kwargs, gate = SETTINGS[name]
        key = json.dumps(kwargs, sort_keys=True)
        if key not in frozen:
            frozen[key] = drifting_comparison(seed, duration, kwargs, modes=("frozen",))["frozen"]
        adaptive = drifting_comparison(seed, duration, kwargs, modes=("adaptive",), gate=gate)["adaptive"]
        res[name] = {"frozen": frozen[key], "adaptive": adaptive, "ratio": frozen[key] / adaptive,
                     "oracle_ratio": frozen[key] / res["oracle"]}
    res["run_s"] = time.perf_counter() - t0
    print(f"random plant {seed}: " + ", ".join(f"{k} {res[k]['ratio']:.1f}x (oracle {res[k]['oracle_ratio']:.1f}x)"
                                                for k in settings), file=sys.stderr)
    return res


def random_case(seeds: list[int], duration: float, jobs: int = 1, settings: tuple = tuple(SETTINGS)) -> dict:
    """Adaptive vs frozen on random drifting plants (``hil_sim.closed_loop.random_drifting_plant``): per
    setting the fraction reaching 5x, and the fraction where even the oracle (true parameters every
    10 ms) reaches 5x against that frozen compensator (the frozen-time inverse's limit)."""
    if jobs > 1:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(jobs) as pool:
            runs = list(pool.map(_random_one, seeds, [duration] * len(seeds), [settings] * len(seeds)))
    else:
        runs = [_random_one(s, duration, settings) for s in seeds]
    out = {"seeds": list(seeds), "duration_s": duration, "drift": "alpha +20 %, b +10 % over the run",
           "settings": {name: {"estimator": SETTINGS[name][0], "gate": SETTINGS[name][1]} for name in settings},
           "load_average": list(os.getloadavg()), "runs": runs}
    for name in settings:
        ratio = np.array([x[name]["ratio"] for x in runs])
        oracle = np.array([x[name]["oracle_ratio"] for x in runs])
        near = np.array([x[name]["adaptive"] <= 1.25 * x["oracle"] for x in runs])
        out[name] = {"pass_fraction_5x": float(np.mean(ratio >= 5)), "oracle_pass_fraction_5x": float(np.mean(oracle >= 5)),
                     "pass_fraction_where_oracle_passes": float(np.mean(ratio[oracle >= 5] >= 5)) if np.any(oracle >= 5) else None,
                     "adaptive_within_1.25x_of_oracle": float(np.mean(near)),
                     "ratio_min": float(ratio.min()), "ratio_median": float(np.median(ratio)),
                     "seeds_below_5x": [s for s, r in zip(seeds, ratio) if r < 5]}
    return out


#: A call slower than this (us) misses the per-sample budget (the 25 us of ``update()``).
BUDGET_US = 25.0
#: The estimator re-fits every 0.1 s: in the adaptive loop the compensator's model changes at most that often.
CHANGE_EVERY = 1000


class _GcCount:
    """Counts the garbage collector's passes (``gc.callbacks``): a timed call that spans one is marked."""

    def __init__(self) -> None:
        self.passes = 0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self.passes += 1


def time_interleaved(calls: dict, n: int) -> tuple[dict, float]:
    """Time every call of ``calls`` (name -> f(k)) at each k = 0..n-1, in turn, with both clocks.

    Interleaving puts every call under the same machine (other processes, interrupts, frequency):
    the empty call's outliers are the machine's, and what a real call has beyond them is its own.
    Each call is marked when a garbage-collector pass or a context switch of the thread (getrusage,
    outside the timed interval) fell inside it.
    Returns ({name: (cpu_ns, wall_ns, gc_marked, switch_marked)}, loop seconds).
    """
    import gc
    import resource
    names, fns = list(calls), list(calls.values())
    cpu, wall = np.empty((len(fns), n)), np.empty((len(fns), n))
    marked = np.zeros((len(fns), n), dtype=bool)
    switched = np.zeros((len(fns), n), dtype=bool)
    counter = _GcCount()
    gc.callbacks.append(counter)
    who = resource.RUSAGE_THREAD
    try:
        t0 = time.perf_counter()
        for k in range(n):
            for j, f in enumerate(fns):
                g0 = counter.passes
                s0 = resource.getrusage(who)
                c0, w0 = time.thread_time_ns(), time.perf_counter_ns()
                f(k)
                cpu[j, k], wall[j, k] = time.thread_time_ns() - c0, time.perf_counter_ns() - w0
                s1 = resource.getrusage(who)
                marked[j, k] = counter.passes != g0
                switched[j, k] = s1.ru_nivcsw + s1.ru_nvcsw != s0.ru_nivcsw + s0.ru_nvcsw
        loop_s = time.perf_counter() - t0
    finally:
        gc.callbacks.remove(counter)
    return {name: (cpu[j], wall[j], marked[j], switched[j]) for j, name in enumerate(names)}, loop_s


def cost_summary(cpu: np.ndarray, wall: np.ndarray, marked: np.ndarray, switched: np.ndarray, loop_s: float,
                 empty: dict | None) -> dict:
    """p50/p99/max per clock, calls over the budget per second of loop time, and the same minus the empty
    call's (noise-corrected: what remains is the call's own work); how many of the slow calls spanned a
    garbage-collector pass or a context switch."""
    out = {"cpu_us": dist(cpu / 1e3), "wall_us": dist(wall / 1e3), "calls": int(cpu.size)}
    for clock, x in (("cpu", cpu), ("wall", wall)):
        over = x > BUDGET_US * 1e3
        out[f"over_budget_{clock}"] = int(over.sum())
        out[f"over_budget_per_s_{clock}"] = float(over.sum() / loop_s)
        out[f"over_budget_{clock}_during_gc"] = int((over & marked).sum())
        out[f"over_budget_{clock}_with_context_switch"] = int((over & switched).sum())
        if empty is not None:
            out[f"over_budget_per_s_{clock}_corrected"] = \
                out[f"over_budget_per_s_{clock}"] - empty[f"over_budget_per_s_{clock}"]
    out["calls_over_budget_cpu"] = [round(float(v) / 1e3, 1) for v in np.sort(cpu[cpu > BUDGET_US * 1e3])[-10:]]
    return out


def first_model_cost(passes: tuple = (1000, 10_000, 100_000)) -> dict:
    """The first model after n pass-through samples, per n: ``set_model``'s CPU time (us), and the calls
    that replay the n remembered commands (``REPLAY_CHUNK`` per call): how many, their p50 and max CPU (us)."""
    r = np.where(np.arange(max(passes)) > 10, 0.5, 0.0).tolist()
    out = {}
    for n in passes:
        comp = CreepCompensator(H, bandwidth_hz=BANDWIDTH_HZ)
        for v in r[:n]:
            comp.command(v)
        c0 = time.thread_time_ns()
        comp.set_model(PLANT)
        set_us = (time.thread_time_ns() - c0) / 1e3
        cpu = []
        while comp.replaying:
            c0 = time.thread_time_ns()
            comp.command(0.5)
            cpu.append((time.thread_time_ns() - c0) / 1e3)
        out[str(n)] = {"set_model_cpu_us": set_us, "replay_calls": len(cpu),
                       "replay_call_cpu_us_p50": float(np.median(cpu)), "replay_call_cpu_us_max": float(max(cpu))}
    return out


def command_16_args(c: CreepCompensator, r: float) -> float:
    """``command()`` as it was before the packed buffer (the baseline, same run): the same checks, then the
    kernel called with its sixteen arguments and the clip counted in Python."""
    r = float(r)
    if not math.isfinite(r):
        raise ValueError(r)
    c.samples += 1
    if c._base is not None and c._applied:
        c._replay_some()
    if c._base is None or c._applied:
        return c._pass(r)
    u = CK.command_step(c._st, c._e, c._M, c._m, c._phi, c._gam, c._Wz, c._Ux, c._ur, r - c._offset, c._lo, c._hi,
                        c.anti_windup, c._hy, c._hy_on, c._out)
    c._clipped += int(c._out[1])
    return u


def _dispatch_controls(c: CreepCompensator):
    """Two numba functions that do nothing, called with command_step's 16 arguments and command_packed's 4:
    what numba's dispatch (a type check per argument) costs, without the kernel's work."""
    from numba import njit

    @njit(cache=False)
    def nothing16(st, e, M, m, phi, gam, Wz, Ux, ur, r, lo, hi, aw, hy, hy_on, out):
        return r

    @njit(cache=False)
    def nothing4(buf, hy, r, out):
        return r

    def d16(r: float) -> float:
        return nothing16(c._st, c._e, c._M, c._m, c._phi, c._gam, c._Wz, c._Ux, c._ur, r, c._lo, c._hi,
                         c.anti_windup, c._hy, c._hy_on, c._out)

    def d4(r: float) -> float:
        return nothing4(c._pack, c._hy, r, c._out)
    d16(0.0), d4(0.0)
    return d16, d4


def _compute_control(target_us: float):
    """A numba call with one argument that only computes (no memory) for about ``target_us`` at the median:
    how often the machine interrupts a call of that length (the share of a tail that is duration, not code)."""
    from numba import njit

    @njit(cache=False)
    def spin(k: int) -> float:
        s = 1.0
        for _ in range(k):
            s = s * 0.999999 + 1e-9
        return s

    def median_us(k: int) -> float:
        x = np.empty(5000)
        for i in range(x.size):
            c0 = time.thread_time_ns()
            spin(k)
            x[i] = time.thread_time_ns() - c0
        return float(np.median(x)) / 1e3
    k = 10
    while median_us(k) < target_us and k < 10**6:
        k = int(k * 1.2) + 1
    return lambda r: spin(k)


def cold_cache_case(n: int = 20_000) -> dict:
    """``command()`` (and the previous 16-argument path) with warm caches and after an 8 MB sweep between calls
    (outside the timed interval), which evicts what the call touches as another process on the core would:
    CPU p50/p90/p99 (us) and the fraction over the budget."""
    r = staircase(np.arange(n) * H, LEVELS, 0.5, t_start=0.01).tolist()
    big = np.ones(1 << 20)
    command_16_args(CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ), 0.5)
    out = {}
    for name, call in (("command", CreepCompensator.command), ("command_before_16_args", command_16_args)):
        for evict in (False, True):
            comp = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
            x = np.empty(n)
            for k in range(n):
                if evict:
                    big *= 1.0000001
                c0 = time.thread_time_ns()
                call(comp, r[k])
                x[k] = time.thread_time_ns() - c0
            x /= 1e3
            out[f"{name}_{'evicted' if evict else 'warm'}"] = {
                "p50": float(np.percentile(x, 50)), "p90": float(np.percentile(x, 90)),
                "p99": float(np.percentile(x, 99)), "over_budget_fraction": float(np.mean(x > BUDGET_US))}
    return out


def cost_case(n: int = 200_000) -> dict:
    """command() alone, with a model change every 0.1 s (the adaptive loop) and every sample (the worst
    case), against an empty call timed in the same loop; OnlineEstimator.update() in the same run."""
    warm_compensator()
    warm_kernels()
    t = np.arange(n) * H
    r = staircase(t, LEVELS, 0.5, t_start=0.01).tolist()
    other = CreepModel(0.125, PLANT.a1, PLANT.a2, 2.55)
    fixed = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
    before = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
    command_16_args(CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ), 0.5)   # (compile/load its dispatch)
    d16, d4 = _dispatch_controls(CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0))
    probe = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
    x = np.empty(5000)
    for i in range(x.size):
        c0 = time.thread_time_ns()
        probe.command(r[i])
        x[i] = time.thread_time_ns() - c0
    spin = _compute_control(float(np.median(x)) / 1e3)
    loop = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
    every = CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ, u_min=-1.0, u_max=1.0)
    models = (PLANT, other)

    def empty(k: int) -> float:
        return r[k]

    def adaptive(k: int) -> float:
        loop.set_model(models[(k // CHANGE_EVERY) % 2])
        return loop.command(r[k])

    def worst(k: int) -> float:
        every.set_model(models[k % 2])
        return every.command(r[k])

    calls = {"empty": empty, "command": lambda k: fixed.command(r[k]),
             "command_before_16_args": lambda k: command_16_args(before, r[k]),
             "dispatch_only_16_args": lambda k: d16(r[k]), "dispatch_only_4_args": lambda k: d4(r[k]),
             "compute_only_same_p50": lambda k: spin(r[k]),
             "set_model_every_0.1s_and_command": adaptive, "set_model_every_sample_and_command": worst}
    timed, loop_s = time_interleaved(calls, n)
    empty_summary = cost_summary(*timed["empty"], loop_s, None)
    out = {"samples": n, "loop_s": loop_s, "budget_us": BUDGET_US, "load_average": list(os.getloadavg()),
           "empty_call": empty_summary}
    for name in list(calls)[1:]:
        out[name] = cost_summary(*timed[name], loop_s, empty_summary)
    out["first_set_model_after_pass_through_cpu_us"] = first_model_cost()
    out["cold_cache"] = cold_cache_case()
    from creep_online.simulate import simulate
    u = np.clip(np.asarray(r), 0, 1) / 2.0
    y = simulate(PLANT, t, u) + 2e-4 * np.random.default_rng(0).standard_normal(n)
    est = OnlineEstimator(H)
    ecpu = np.empty(n)
    for k in range(n):
        c0 = time.thread_time_ns()
        est.update(u[k], y[k])
        ecpu[k] = time.thread_time_ns() - c0
    out["estimator_update_cpu_us_same_run"] = dist(ecpu / 1e3)
    out["ratio_command_to_update_p50"] = out["command"]["cpu_us"]["p50"] / out["estimator_update_cpu_us_same_run"]["p50"]
    t0 = time.perf_counter()
    CreepCompensator(H, PLANT, bandwidth_hz=BANDWIDTH_HZ).command_block(np.asarray(r))
    out["command_block_us_per_sample"] = (time.perf_counter() - t0) / n * 1e6
    out["load_average_after"] = list(os.getloadavg())
    return out


CASES = ("staircase", "drift", "random", "cost")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=5, help="drift runs (seed 0: the staircase levels)")
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--cases", default=",".join(CASES), help=f"comma-separated subset of {', '.join(CASES)}")
    p.add_argument("--random-seeds", default="0-19", help="random drifting plants: seeds as a-b or a,b,c")
    p.add_argument("--random-duration", type=float, default=60.0)
    p.add_argument("--jobs", type=int, default=1, help="processes for the random plants")
    p.add_argument("--random-key", default="random_plants", help="JSON key of the random case (e.g. a fresh seed set)")
    p.add_argument("--settings", default=",".join(SETTINGS), help=f"random case: comma-separated subset of "
                                                                  f"{', '.join(SETTINGS)}")
    p.add_argument("--out", default=None, help="JSON file; the cases run replace theirs, the others are kept")
    args = p.parse_args()
    cases = args.cases.split(",")
    warm_kernels()
    warm_compensator()
    t = np.arange(int(round(args.duration / H))) * H
    started = time.perf_counter()
    out = {}
    if args.out and os.path.exists(args.out):
        with open(args.out) as fh:
            out = json.load(fh)
    out.update({"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "node": platform.node()},
                "plant": PLANT.describe(), "dt": H, "hold_s": HOLD_S, "bandwidth_hz": BANDWIDTH_HZ,
                "settle_s": PLANT.settling_time})
    out.setdefault("commands", {})
    for case in cases:
        out["commands"][case] = " ".join(sys.argv)
    if "staircase" in cases:
        out["staircase"] = staircase_case(t)
        print(f"staircase: uncompensated {out['staircase']['uncompensated']['max_abs']:.4f} "
              f"adaptive {out['staircase']['adaptive']['max_abs']:.2e}", file=sys.stderr)
    if "drift" in cases:
        out["drift"] = drift_case(t, range(args.seeds))
    if "random" in cases:
        out[args.random_key] = random_case(parse_seeds(args.random_seeds), args.random_duration, args.jobs,
                                           tuple(args.settings.split(",")))
    if "cost" in cases:
        out["cost"] = cost_case()
    out["elapsed_s"] = time.perf_counter() - started
    write_report(out, args.out)


def parse_seeds(text: str) -> list[int]:
    """'0-19' or '3,5,8' -> the seeds."""
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",")]


if __name__ == "__main__":
    main()
