"""Online estimator robustness (issue 14): single outliers, frozen and clipped sensors.

Usage (from the repository root, with the package installed or ``PYTHONPATH=.``)::

    python -m bench.bench_online_robustness [--plants 9] [--variants 9] [--single 20]
        [--faults 4] [--out bench/results/online_robustness.json]

Plants: ``--plants`` seeds (0..plants-1) of each stationary family of
``hil_sim.scenarios`` (strong_creep, controller, mid_operation). Everything
below is drawn from fixed seeds, so every run sees the same cases.

1. Outliers (block mode). Per plant the clean record is fed once with
   ``update_block`` (whole record) as the reference; then ``--variants``
   copies with one corrupted sample each: at a uniformly random time in
   [3 s, end - 1 s] (every fifth case at a sample where u changes), in u
   (every other case) or y, of size 10^U(1, 300) times the rms of the
   corrupted signal (u or y), random sign, added to the sample (clipped to
   1e307 so that it stays finite). A case passes if the final alpha, b, a1, a2
   are within 2 / 3 / 5 / 5 % of the clean run's (goal: >= 99 %). Recorded per
   case: family, seed, where, size, time, at_step, pass, relative
   differences, outlier counters, the final quality of both runs. A failing
   case is re-run with the same sample moved by one noise std instead (no
   outlier, a different noise draw): if that control fails too, the clean
   estimate itself is not determined to the tolerances (the estimator then
   says quality "provisional"), and the outlier is not what moved it.
2. Outliers (single mode): the first ``--single`` cases again with
   ``update()`` per sample, against a clean ``update()`` run of the same plant.
3. Frozen / clipped sensor (``--faults`` cases per plant, alternating): at a
   uniformly random time t_f in [3 s, end - 2 s] the output freezes at its
   current value, or is clipped at it (y = min(y, y(t_f))) while the input
   keeps moving. The record is fed with ``update_block`` up to t_f - 0.2 s and
   then with ``update()`` per sample; every 10 samples the estimate is
   checked for ``"frozen" in reason``. Detection time = first flag minus the
   onset: t_f for frozen; for clipped the start of the first stretch of at
   least 50 ms at the rail (the underlying output >= the level); clipped cases
   without such a stretch before end - 0.5 s are counted as "never at the
   rail" and not judged. Pass: detection <= 0.5 s (goal: >= 99 %). A flag
   between t_f - 0.2 s and t_f is a false alarm. Observability is recorded:
   whether the input changes within 0.5 s of the onset and how far the clean
   (noisy) output moves in that time, in noise standard deviations.

Prints one JSON document (summary, failures with their parameters, all
cases) and writes it to ``--out``. About 5-6 minutes on one core with the
defaults (strong_creep seeds 0 and 2 take ~5 s per run, the rest < 1 s).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")   # one core: the machine is shared

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

from creep_online.online.estimator import OnlineEstimator, warm_kernels  # noqa: E402
from hil_sim import scenarios  # noqa: E402
from bench.harness import results_path, write_report  # noqa: E402

FAMILIES = ("strong_creep", "controller", "mid_operation")
PARAMS = ("alpha", "b", "a1", "a2")
#: Largest relative difference from the clean run's final estimate.
TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
#: Detection limit (s) of a frozen or clipped output.
DETECT_S = 0.5
#: Outliers: earliest time (s) and distance from the end (s).
OUT_T0, OUT_END = 3.0, 1.0
#: Faults: earliest time (s), distance from the end (s), lead-in fed per sample (s).
FAULT_T0, FAULT_END, LEAD_S = 3.0, 2.0, 0.2
#: Shortest stretch (s) at the rail that counts as "at the rail" (a clipped output).
RAIL_MIN_S = 0.05
#: Observation after the onset (s) of a fault before giving up.
OBSERVE_S = 1.5
CHECK_EVERY = 10
SEED = 14
BIG = 1e307


# --------------------------------------------------------------------------- helpers
def final(est: OnlineEstimator) -> dict:
    e = est.estimate
    return {"alpha": e.alpha, "b": e.b, "a1": e.a1, "a2": e.a2, "quality": e.quality, "reason": e.reason,
            "phase": e.phase, "outliers": e.outliers, "input_outliers": e.input_outliers,
            "shifts": e.shifts, "skipped": e.skipped}


def run(h: float, u: np.ndarray, y: np.ndarray, mode: str) -> dict:
    """Final estimate after feeding the whole record (block: one update_block; single: update() per sample)."""
    t0 = time.perf_counter()
    try:
        est = OnlineEstimator(h)
        if mode == "block":
            est.update_block(u, y)
        else:
            upd = est.update
            for a, b in zip(u.tolist(), y.tolist()):
                upd(a, b)
        out = final(est)
        out["error"] = None
    except Exception as exc:  # a crash is a failure, recorded with its message
        out = {"error": f"{type(exc).__name__}: {exc}"}
    out["seconds"] = round(time.perf_counter() - t0, 3)
    return out


def rel_diffs(ref: dict, res: dict) -> dict:
    if ref.get("error") or res.get("error"):
        return {k: math.inf for k in PARAMS}
    out = {}
    for k in PARAMS:
        d = abs(res[k] - ref[k]) / max(abs(ref[k]), 1e-300)
        out[k] = d if math.isfinite(d) else math.inf
    return out


def passed(diffs: dict) -> bool:
    return all(diffs[k] <= TOL[k] for k in PARAMS)


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def jnum(x):
    """JSON-safe float (inf as a string)."""
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def jsafe(obj):
    if isinstance(obj, dict):
        return {k: jsafe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsafe(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    return jnum(obj)


def quantiles(x: list[float]) -> dict:
    if not x:
        return {"n": 0}
    a = np.asarray(x, dtype=float)
    return {"n": int(a.size), "p50": float(np.percentile(a, 50)), "p90": float(np.percentile(a, 90)),
            "max": float(a.max())}


# --------------------------------------------------------------------------- outliers
def outlier_cases(sc, fam_index: int, n_var: int, counter: int) -> list[dict]:
    """The corruptions of one plant (deterministic); ``counter`` numbers cases across plants."""
    rng = np.random.default_rng([SEED, 1, fam_index, sc.seed])
    h, n = sc.h, sc.u.size
    lo, hi = int(math.ceil(OUT_T0 / h)), int((n * h - OUT_END) / h)
    steps = np.flatnonzero(np.diff(sc.u[lo - 1:hi]) != 0.0) + lo
    cases = []
    for j in range(n_var):
        i = counter + j
        where = "u" if i % 2 == 0 else "y"
        at_step = (i % 5 == 4) and steps.size > 0
        k = int(rng.choice(steps)) if at_step else int(rng.integers(lo, hi))
        size = float(10.0 ** rng.uniform(1.0, 300.0))
        sign = float(rng.choice([-1.0, 1.0]))
        sig = sc.u if where == "u" else sc.y
        amp = min(size * rms(sig), BIG)
        cases.append({"family": sc.family, "seed": sc.seed, "where": where, "k": k, "t": round(k * h, 5),
                      "at_step": bool(at_step), "size": size, "sign": sign, "value_added": sign * amp,
                      "original": float(sig[k])})
    return cases


def corrupt(sc, case: dict) -> tuple[np.ndarray, np.ndarray]:
    u, y = sc.u, sc.y
    if case["where"] == "u":
        u = u.copy()
        u[case["k"]] += case["value_added"]
    else:
        y = y.copy()
        y[case["k"]] += case["value_added"]
    return u, y


# --------------------------------------------------------------------------- frozen / clipped
def rail_start(above: np.ndarray, start: int, need: int) -> int | None:
    """First index >= start of a run of at least ``need`` True samples in ``above``."""
    a = above[start:].astype(np.int8)
    if a.size < need:
        return None
    edges = np.diff(np.concatenate(([0], a, [0])))
    begins = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    ok = np.flatnonzero(ends - begins >= need)
    return None if ok.size == 0 else int(begins[ok[0]]) + start


def fault_case(sc, kind: str, rng: np.random.Generator) -> dict:
    h, n = sc.h, sc.u.size
    kf = int(rng.integers(int(FAULT_T0 / h), int((n * h - FAULT_END) / h)))
    level = float(sc.y[kf])
    y = sc.y.copy()
    if kind == "frozen":
        y[kf:] = level
        k_on = kf
    else:
        y[kf:] = np.minimum(y[kf:], level)
        k_on = rail_start(sc.y >= level, kf, max(1, int(round(RAIL_MIN_S / h))))
        if k_on is not None and k_on + int(DETECT_S / h) > n:
            k_on = None
    w = slice(kf if k_on is None else k_on, min(n, (kf if k_on is None else k_on) + int(DETECT_S / h)))
    k0 = w.start
    case = {"family": sc.family, "seed": sc.seed, "kind": kind, "t_fault": round(kf * h, 5),
            "level": level, "noise_std": float(sc.params.get("noise_std", float("nan"))),
            "input_changes_in_0.5s": bool(np.any(sc.u[w] != sc.u[k0])),
            "output_move_in_0.5s_over_noise": float(np.max(np.abs(sc.y[w] - sc.y[k0]))
                                                    / max(sc.params.get("noise_std", 1e-300), 1e-300)),
            "t_onset": None if k_on is None else round(k_on * h, 5)}
    if k_on is None:
        case.update(never_at_rail=True, t_detect=None, passed=None, false_alarm=False)
        return case
    case["never_at_rail"] = False
    k_lead = max(0, kf - int(round(LEAD_S / h)))
    k_stop = min(n, k_on + int(round(OBSERVE_S / h)))
    t0 = time.perf_counter()
    detect = None
    false_alarm = False
    try:
        est = OnlineEstimator(h)
        est.update_block(sc.u[:k_lead], y[:k_lead])
        upd = est.update
        uu, yy = sc.u.tolist(), y.tolist()
        for k in range(k_lead, k_stop):
            upd(uu[k], yy[k])
            if (k - k_lead) % CHECK_EVERY == CHECK_EVERY - 1 or k == k_stop - 1:
                e = est.estimate
                if "frozen" in e.reason:
                    if k < kf:
                        false_alarm = True
                    elif k >= k_on:
                        detect = k
                        break
        e = est.estimate
        case.update(error=None, quality=e.quality, reason=e.reason, phase=e.phase)
    except Exception as exc:
        case["error"] = f"{type(exc).__name__}: {exc}"
    case["seconds"] = round(time.perf_counter() - t0, 3)
    case["false_alarm"] = false_alarm
    case["t_detect"] = None if detect is None else round((detect - k_on + 1) * h, 5)
    case["t_detect_from_fault"] = None if detect is None else round((detect - kf + 1) * h, 5)
    case["passed"] = detect is not None and (detect - k_on + 1) * h <= DETECT_S + 1e-12
    return case


# --------------------------------------------------------------------------- main
def summarize_outliers(cases: list[dict]) -> dict:
    n = len(cases)
    ok = sum(c["passed"] for c in cases)
    out = {"cases": n, "passed": ok, "fraction": ok / n if n else None}
    for key, vals in (("where", ("u", "y")), ("at_step", (True, False))):
        for v in vals:
            sub = [c for c in cases if c[key] == v]
            if sub:
                out[f"fraction_{key}_{v}"] = sum(c["passed"] for c in sub) / len(sub)
    good = [c for c in cases if c["clean_quality"] == "good"]
    if good:
        out["fraction_clean_good"] = sum(c["passed"] for c in good) / len(good)
        out["cases_clean_good"] = len(good)
    fails = [c for c in cases if not c["passed"]]
    out["failures_also_failing_the_1sigma_control"] = sum(bool(c.get("control_1sigma_passed") is False)
                                                          for c in fails)
    for lo, hi in ((1, 10), (10, 100), (100, 300)):
        sub = [c for c in cases if lo <= math.log10(c["size"]) < hi + (hi == 300)]
        if sub:
            out[f"fraction_size_1e{lo}_1e{hi}"] = sum(c["passed"] for c in sub) / len(sub)
    for k in PARAMS:
        d = [c["diff"][k] for c in cases]
        out[f"diff_{k}_p50_p99_max"] = [float(np.percentile(d, 50)), float(np.percentile(d, 99)), float(max(d))]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--plants", type=int, default=9, help="seeds per family")
    ap.add_argument("--variants", type=int, default=9, help="outlier cases per plant")
    ap.add_argument("--single", type=int, default=20, help="outlier cases repeated with update() per sample")
    ap.add_argument("--faults", type=int, default=4, help="frozen/clipped cases per plant")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--out", default=str(results_path("online_robustness")))
    args = ap.parse_args()
    start = time.perf_counter()
    warm_kernels()

    plants = [(fi, fam, s) for fi, fam in enumerate(args.families.split(",")) for s in range(args.plants)]
    out_cases: list[dict] = []
    single_cases: list[dict] = []
    fault_cases: list[dict] = []
    clean_runs: list[dict] = []
    counter = 0
    single_refs: dict = {}
    for fi, fam, seed in plants:
        sc = scenarios.make(fam, seed)
        ref = run(sc.h, sc.u, sc.y, "block")
        clean_runs.append({"family": fam, "seed": seed, "fs_hz": 1.0 / sc.h, "duration_s": sc.u.size * sc.h,
                           "input": sc.params.get("input"), "truth": sc.final_truth, **ref})
        cases = outlier_cases(sc, fi, args.variants, counter)
        counter += len(cases)
        for c in cases:
            u, y = corrupt(sc, c)
            res = run(sc.h, u, y, "block")
            c["diff"] = rel_diffs(ref, res)
            c["passed"] = passed(c["diff"])
            if not c["passed"]:
                # control: the same sample moved by one noise std (a different noise draw, no outlier);
                # if that also fails, the clean estimate is not determined well enough to compare to
                yc = sc.y.copy()
                yc[c["k"]] += float(sc.params.get("noise_std", 0.0))
                c["control_1sigma_diff"] = rel_diffs(ref, run(sc.h, sc.u, yc, "block"))
                c["control_1sigma_passed"] = passed(c["control_1sigma_diff"])
            c["estimate"] = {k: res.get(k) for k in PARAMS}
            c["clean_estimate"] = {k: ref.get(k) for k in PARAMS}
            c.update(clean_quality=ref.get("quality"), quality=res.get("quality"), reason=res.get("reason"),
                     outliers=res.get("outliers"), input_outliers=res.get("input_outliers"),
                     shifts=res.get("shifts"), clean_outliers=ref.get("outliers"),
                     clean_input_outliers=ref.get("input_outliers"), error=res.get("error"),
                     seconds=res["seconds"])
            out_cases.append(c)
            # single mode: the first cases of the plants with a fast clean run, two per plant
            if (len(single_cases) < args.single and ref["seconds"] < 2.0
                    and sum(s["family"] == fam and s["seed"] == seed for s in single_cases) < 2):
                key = (fam, seed)
                if key not in single_refs:
                    single_refs[key] = run(sc.h, sc.u, sc.y, "single")
                sref = single_refs[key]
                sres = run(sc.h, u, y, "single")
                sd = rel_diffs(sref, sres)
                single_cases.append({k: c[k] for k in ("family", "seed", "where", "k", "t", "at_step", "size",
                                                       "value_added")}
                                    | {"diff": sd, "passed": passed(sd), "block_passed": c["passed"],
                                       "clean_quality": sref.get("quality"), "quality": sres.get("quality"),
                                       "outliers": sres.get("outliers"),
                                       "input_outliers": sres.get("input_outliers"),
                                       "single_vs_block_clean": rel_diffs(ref, sref), "error": sres.get("error")})
        frng = np.random.default_rng([SEED, 2, fi, seed])
        for j in range(args.faults):
            fault_cases.append(fault_case(sc, "frozen" if j % 2 == 0 else "clipped", frng))
        print(f"{fam} {seed}: clean {ref['seconds']:.2f} s, outliers "
              f"{sum(c['passed'] for c in cases)}/{len(cases)}, faults "
              f"{[c['t_detect'] for c in fault_cases[-args.faults:]]}  ({time.perf_counter() - start:.0f} s)",
              file=sys.stderr)

    judged = [c for c in fault_cases if not c["never_at_rail"]]
    fsum = {"cases": len(fault_cases), "judged": len(judged),
            "never_at_rail": sum(c["never_at_rail"] for c in fault_cases),
            "passed": sum(bool(c["passed"]) for c in judged),
            "fraction": sum(bool(c["passed"]) for c in judged) / len(judged) if judged else None,
            "false_alarms": sum(c["false_alarm"] for c in fault_cases)}
    for kind in ("frozen", "clipped"):
        sub = [c for c in judged if c["kind"] == kind]
        fsum[kind] = {"judged": len(sub), "fraction": sum(bool(c["passed"]) for c in sub) / len(sub) if sub else None,
                      "t_detect_s": quantiles([c["t_detect"] for c in sub if c["t_detect"] is not None]),
                      "undetected": sum(c["t_detect"] is None for c in sub)}
    fsum["t_detect_s"] = quantiles([c["t_detect"] for c in judged if c["t_detect"] is not None])
    for name, flag in (("input_changes_in_0.5s", True), ("input_held_0.5s", False)):
        sub = [c for c in judged if c["input_changes_in_0.5s"] == flag]
        fsum[f"when_{name}"] = {"judged": len(sub), "fraction": (sum(bool(c["passed"]) for c in sub) / len(sub))
                                if sub else None}

    doc = {
        "bench": "online_robustness",
        "goals": {"outliers": "final estimate within alpha 2 %, b 3 %, a1 5 %, a2 5 % of the clean run's in >= 99 %",
                  "frozen": f"a frozen or clipped output flagged within {DETECT_S} s in >= 99 %"},
        "settings": {"plants_per_family": args.plants, "families": args.families.split(","),
                     "variants": args.variants, "single": args.single, "faults_per_plant": args.faults,
                     "seed": SEED, "tol": TOL},
        "outliers_block": summarize_outliers(out_cases),
        "outliers_single": summarize_outliers(single_cases) if single_cases else None,
        "faults": fsum,
        "failures": {
            "outliers_block": [c for c in out_cases if not c["passed"]],
            "outliers_single": [c for c in single_cases if not c["passed"]],
            "faults": [c for c in judged if not c["passed"]],
            "false_alarms": [c for c in fault_cases if c["false_alarm"]],
        },
        "clean_runs": clean_runs,
        "cases": {"outliers_block": out_cases, "outliers_single": single_cases, "faults": fault_cases},
        "seconds": round(time.perf_counter() - start, 1),
    }
    doc = jsafe(doc)
    write_report(doc, args.out)


if __name__ == "__main__":
    main()
