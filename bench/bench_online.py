"""Online estimator benchmark (issue 3): latency, throughput, memory, accuracy, baseline, Remark 3.

Prints one JSON document. Run: ``PYTHONPATH=. python bench/bench_online.py [--quick]``
(--quick: 3.6 M instead of 36 M samples for the memory run, shorter latency run).
Timings are from a shared 2-core machine: read distributions, not single numbers.
"""
from __future__ import annotations

import argparse
import gc
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from creep_online.identification import identify  # noqa: E402
from creep_online.kernels import zoh_integral_weights  # noqa: E402
from creep_online.model import CreepModel  # noqa: E402
from creep_online.online import OnlineEstimator  # noqa: E402
from creep_online.online import kernels as K  # noqa: E402
from creep_online.online.plant import PlantStream, simulate_varying  # noqa: E402
from creep_online.online.soe import SoeBasis  # noqa: E402
from creep_online.simulate import simulate  # noqa: E402


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def dist(x_us: np.ndarray) -> dict:
    return {"p50": float(np.percentile(x_us, 50)), "p99": float(np.percentile(x_us, 99)),
            "max": float(np.max(x_us)), "mean": float(np.mean(x_us)),
            "over_1ms": int(np.count_nonzero(x_us > 1000.0)), "n": int(x_us.size)}


def noisy(y: np.ndarray, active: np.ndarray, seed: int, snr_db: float = 40.0) -> np.ndarray:
    sig = math.sqrt(np.mean(y[active] ** 2))
    return y + np.random.default_rng(seed).normal(0.0, sig * 10 ** (-snr_db / 20), y.size)


def staircase(t: np.ndarray, t0: float, hold: float, levels=(10.0, 6.0, 12.0, 4.0)) -> np.ndarray:
    k = np.floor((t - t0) / hold).astype(int)
    u = np.asarray(levels)[np.mod(k, len(levels))]
    return np.where(t >= t0, u, 0.0)


# --------------------------------------------------------------------------- latency
def latency_run(samples: int) -> dict:
    """Per-sample update() over a 10 kHz nanopositioner stream (staircase, steps every 20 s)."""
    h = 1e-4
    model = CreepModel.from_resonance(0.02, 300.0, 0.05, 0.15)
    t = np.arange(samples) * h
    u = staircase(t, 0.01, 20.0)
    y = noisy(simulate(model, t, u), t >= 0.01, 1)
    est = OnlineEstimator(h)
    ul, yl = u.tolist(), y.tolist()
    ns = np.empty(samples, dtype=np.int64)
    upd = np.zeros(samples, dtype=bool)
    clock = time.perf_counter_ns
    gc.collect()
    last = 0
    for k in range(samples):
        t0 = clock()
        est.update(ul[k], yl[k])
        ns[k] = clock() - t0
        if est.alpha_updates != last:
            upd[k] = True
            last = est.alpha_updates
    us = ns / 1e3
    e = est.estimate
    return {"samples": samples, "fs_hz": 1 / h, "update_us": dist(us),
            "alpha_update_samples_us": dist(us[upd]) if upd.any() else None,
            "alpha_updates": est.alpha_updates, "t_c": e.t_c, "final": {"alpha": e.alpha, "b": e.b, "fn_hz": e.fn_hz},
            "truth": {"alpha": 0.02, "b": 0.15, "fn_hz": 300.0}, "goal": {"p50": 10, "p99": 100}}


# --------------------------------------------------------------------------- throughput + memory
def memory_run(samples: int, chunk: int = 1_000_000) -> dict:
    """Block mode over a long stream generated chunk by chunk: samples/s and RSS at start and end."""
    h = 1e-4
    model = CreepModel.from_resonance(0.02, 300.0, 0.05, 0.15)
    plant = PlantStream(h, model.alpha, model.a1, model.a2, model.b)
    est = OnlineEstimator(h)
    rng = np.random.default_rng(7)
    done = 0
    rss = []
    busy = 0.0
    while done < samples:
        n = min(chunk, samples - done)
        t = (done + np.arange(n)) * h
        u = staircase(t, 0.01, 20.0)
        y = plant.step_block(u) + rng.normal(0, 0.0015, n)
        t0 = time.perf_counter()
        est.update_block(u, y)
        busy += time.perf_counter() - t0
        done += n
        rss.append(rss_mb())
    e = est.estimate
    return {"samples": samples, "hours_at_10khz": samples * h / 3600, "rss_mb_start": rss[0], "rss_mb_end": rss[-1],
            "rss_mb_max": max(rss), "block_samples_per_s": samples / busy, "goal_samples_per_s": 200_000,
            "final": {"alpha": e.alpha, "b": e.b, "quality": e.quality, "divergences": est.divergences}}


# --------------------------------------------------------------------------- accuracy
PLANTS = {
    "nanopositioner_100hz": dict(alpha=0.02, fn=100.0, zeta=0.05, b=0.15, h=1e-4, seconds=10.0, amp=10.0, t0=0.01),
    "nanopositioner_300hz": dict(alpha=0.02, fn=300.0, zeta=0.05, b=0.15, h=1e-4, seconds=10.0, amp=10.0, t0=0.01),
    "nanopositioner_700hz": dict(alpha=0.02, fn=700.0, zeta=0.05, b=0.15, h=1e-4, seconds=10.0, amp=10.0, t0=0.01),
    "load_cell": dict(alpha=0.06, fn=6.0, zeta=0.1, b=0.02, h=5e-3, seconds=30.0, amp=50.0, t0=0.1),
}


def accuracy_run(name: str, p: dict, seed: int = 0) -> dict:
    model = CreepModel.from_resonance(p["alpha"], p["fn"], p["zeta"], p["b"])
    h = p["h"]
    t = np.arange(int(round(p["seconds"] / h))) * h
    u = np.where(t >= p["t0"], p["amp"], 0.0)
    y = noisy(simulate(model, t, u), t >= p["t0"], seed)
    out: dict = {"truth": model.describe()}
    modes = {"recompute": {}, "carry_on": {"remark3": "carry_on"}, "layer1_from_t_c": {"layer1_from": "t_c"}}
    for mode, kw in modes.items():
        est = OnlineEstimator(h, **kw)
        at = None
        k = 0
        step = max(1, int(0.01 / h))
        t_start = time.perf_counter()
        while k < t.size:
            est.update_block(u[k:k + step], y[k:k + step])
            k += step
            e = est.estimate
            if at is None and e.phase == "tracking" and t[k - 1] >= p["t0"] + e.t_c + 5.0:
                at = {"t": float(t[k - 1]), "alpha_rel_err": e.alpha / model.alpha - 1, "b_rel_err": e.b / model.b - 1,
                      "quality": e.quality}
        elapsed = time.perf_counter() - t_start
        e = est.estimate
        out[mode] = {"at_tc_plus_5s": at, "final": {k2: getattr(e, k2) for k2 in ("alpha", "a1", "a2", "b", "fn_hz", "zeta", "t_c")},
                     "final_rel_err": {k2: getattr(e, k2) / getattr(model, k2) - 1 for k2 in ("alpha", "a1", "a2", "b")},
                     "block_samples_per_s": t.size / elapsed}
    t0 = time.perf_counter()
    batch = identify(t, u, y)
    out["batch"] = {**{k2: getattr(batch.model, k2) for k2 in ("alpha", "a1", "a2", "b")}, "elapsed_s": time.perf_counter() - t0}
    out["online_vs_batch_rel"] = {k2: out["recompute"]["final"][k2] / getattr(batch.model, k2) - 1
                                  for k2 in ("alpha", "a1", "a2", "b")}
    return out


# --------------------------------------------------------------------------- naive baseline
def baseline_run(repeats: int = 5) -> dict:
    """Naive online: batch identify() on the window at every alpha update, vs this estimator, same stream."""
    p = PLANTS["nanopositioner_300hz"]
    model = CreepModel.from_resonance(p["alpha"], p["fn"], p["zeta"], p["b"])
    h = p["h"]
    t = np.arange(int(round(10.0 / h))) * h
    u = np.where(t >= p["t0"], p["amp"], 0.0)
    y = noisy(simulate(model, t, u), t >= p["t0"], 3)
    est = OnlineEstimator(h)
    t0 = time.perf_counter()
    est.update_block(u, y)
    online_s = time.perf_counter() - t0
    updates_per_s = 1.0 / (est.update_every * h)
    window = int(round(est.window_s / h)) if est.window_s else t.size
    costs = []
    for r in range(repeats):
        stop = t.size - r * int(0.5 / h)
        start = max(0, stop - window)
        a = time.perf_counter()
        identify(t[start:stop] - t[start], u[start:stop], y[start:stop], polish=False)
        costs.append(time.perf_counter() - a)
    per_identify = float(np.median(costs))
    naive_per_sample = per_identify * updates_per_s * h
    online_per_sample = online_s / t.size
    return {"window_s": est.window_s, "alpha_updates_per_s": updates_per_s,
            "batch_identify_s": {"median": per_identify, "max": float(np.max(costs)), "n": repeats},
            "naive_us_per_sample": naive_per_sample * 1e6, "online_us_per_sample": online_per_sample * 1e6,
            "ratio_naive_over_online": naive_per_sample / online_per_sample,
            "naive_real_time_factor": naive_per_sample / h}


# --------------------------------------------------------------------------- memory kernels
def memory_kernels() -> dict:
    """Fractional integral of a unit step at 10 kHz: SOE (full memory) vs truncated GL (ring buffer of L)."""
    h = 1e-4
    out: dict = {}
    for alpha in (0.0133, 0.02, 0.06, 0.3):
        row: dict = {}
        t_end = 100.0
        exact = t_end**alpha / math.gamma(1 + alpha)
        for length in (1_000, 10_000, 100_000):
            trunc = (length * h) ** alpha / math.gamma(1 + alpha)   # z(t) of a step after L samples: flat
            row[f"truncated_L{length}_rel_err_at_100s"] = trunc / exact - 1
        basis = SoeBasis.build(h, horizon_s=3600.0, top=3000.0)
        tt = np.geomspace(h, 3600.0, 2000)
        soe = basis.step_response(alpha, tt)
        row["soe_max_rel_err_1e-4_to_3600s"] = float(np.max(np.abs(soe / (tt**alpha / math.gamma(1 + alpha)) - 1)))
        row["soe_states"] = basis.size
        out[f"alpha_{alpha}"] = row
    # cost per sample
    n = 200_000
    u = np.random.default_rng(0).normal(size=n)
    cost = {}
    for length in (1_000, 10_000):
        c = zoh_integral_weights(0.02, h, math.gamma(1.02), length + 1)
        z = np.empty(n)
        ring = np.zeros(length)
        K.truncated_gl_block(u[:100], ring, np.zeros(1, dtype=np.int64), c, z[:100])
        a = time.perf_counter()
        K.truncated_gl_block(u, ring, np.zeros(1, dtype=np.int64), c, z)
        cost[f"truncated_L{length}_us_per_sample"] = (time.perf_counter() - a) / n * 1e6
    basis = SoeBasis.build(h, top=3000.0)
    hist = np.empty((n, basis.size))
    zeta = np.zeros(basis.size)
    a = time.perf_counter()
    K.node_history(u, basis.decay, basis.gain, zeta, hist)
    cost["soe_nodes_us_per_sample_incl_history_store"] = (time.perf_counter() - a) / n * 1e6
    out["cost"] = cost
    out["reference_to_beat"] = "fracmem (PyPI): 9-14 us/sample, ~5e-4 error (DESIGN.md section 2)"
    return out


# --------------------------------------------------------------------------- drift
def drift_run() -> dict:
    """alpha +20 %, b +10 % over 60 s; square-wave input; tracking error vs forgetting window and Remark 3 option."""
    h = 2e-3
    t = np.arange(int(75 / h)) * h
    base = CreepModel.from_resonance(0.05, 20.0, 0.2, 1.0)
    u = np.where(t >= 0.1, np.where(((t - 0.1) // 2) % 2 == 0, 1.0, -1.0), 0.0)
    ramp = np.clip((t - 10.0) / 60.0, 0.0, 1.0)
    alpha, b = 0.05 * (1 + 0.2 * ramp), 1.0 + 0.1 * ramp
    y = noisy(simulate_varying(t, u, alpha, base.a1, base.a2, b), t >= 0.1, 0)
    out = {}
    for label, kw in {"window_none": {"window_s": None}, "window_3s": {"window_s": 3.0},
                      "window_5s": {"window_s": 5.0}, "window_10s": {"window_s": 10.0},
                      "window_20s": {"window_s": 20.0},
                      "carry_on_window_5s": {"window_s": 5.0, "remark3": "carry_on"}}.items():
        est = OnlineEstimator(h, t_c=1.0, **kw)
        ea, eb = [], []
        for k0 in range(0, t.size, 500):
            est.update_block(u[k0:k0 + 500], y[k0:k0 + 500])
            k = min(k0 + 500, t.size) - 1
            if t[k] > 20:
                ea.append(abs(est.estimate.alpha / alpha[k] - 1))
                eb.append(abs(est.estimate.b / b[k] - 1))
        out[label] = {"alpha_rel_err_max": max(ea), "alpha_rel_err_mean": float(np.mean(ea)),
                      "b_rel_err_max": max(eb), "b_rel_err_mean": float(np.mean(eb))}
    return out


def stationary_window_run() -> dict:
    """Cost of forgetting on a stationary plant (load cell, 30 s, 4 noise seeds): alpha rms relative error."""
    p = PLANTS["load_cell"]
    model = CreepModel.from_resonance(p["alpha"], p["fn"], p["zeta"], p["b"])
    h = p["h"]
    t = np.arange(int(round(p["seconds"] / h))) * h
    u = np.where(t >= p["t0"], p["amp"], 0.0)
    clean = simulate(model, t, u)
    out = {}
    for w in (None, 5.0, 10.0, 30.0):
        errs = []
        for seed in range(4):
            est = OnlineEstimator(h, window_s=w)
            est.update_block(u, noisy(clean, t >= p["t0"], seed))
            errs.append(est.estimate.alpha / model.alpha - 1)
        out[f"window_{w}"] = {"alpha_rel_err_rms": float(np.sqrt(np.mean(np.square(errs))))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="3.6 M samples for memory, 1 M for latency")
    ap.add_argument("--only", default=None, help="comma list of sections")
    args = ap.parse_args()
    sections = {
        "latency": lambda: latency_run(1_000_000),
        "memory": lambda: memory_run(3_600_000 if args.quick else 36_000_000),
        "accuracy": lambda: {name: accuracy_run(name, p) for name, p in PLANTS.items()},
        "baseline": baseline_run,
        "memory_kernels": memory_kernels,
        "drift": drift_run,
        "stationary_window": stationary_window_run,
    }
    chosen = args.only.split(",") if args.only else list(sections)
    OnlineEstimator(1e-3)   # compile/load kernels before timing
    result = {"machine_note": "2 shared cores; other jobs running", "quick": args.quick}
    for name in chosen:
        t0 = time.perf_counter()
        result[name] = sections[name]()
        result[name + "_wall_s"] = time.perf_counter() - t0
        print(f"[bench_online] {name} done in {result[name + '_wall_s']:.1f} s", file=sys.stderr)
    json.dump(result, sys.stdout, indent=1, default=float)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
