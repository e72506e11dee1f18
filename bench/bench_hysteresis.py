"""Hysteresis fits that are models: weights, simulate against the fit, fit percent, determined thresholds, inverse.

For every input family of ``hil_sim.hysteresis_plants`` (a step, the plain step
at the first sample, staircases with few levels, sines, triangles, random
staircases) and ``--records`` seeds: a random plant with a random
Prandtl-Ishlinskii loop (loop width 2-20 % of the stroke, alpha 0.01-0.3,
10 kHz), fitted with ``fit_extended(data, ("hysteresis",))``. Per record:

* ``w_max``: the largest |weight| reported; ``flattest_branch``: the flattest
  branch's slope over the mean (``hysteresis.flattest_branch``; <= 0: the loop
  cannot be inverted); ``opened`` / ``determined``: operators the
  record opens and weight combinations the data determine;
* ``simulate_over_noise``: RMS of ``ExtendedFit.simulate(t, u)`` minus the
  fit's ``y_hat``, over the noise; it *reproduces* the fit when below
  ``REPRODUCES`` (rounding: the two sum the same responses in another order);
* ``fit_percent`` and ``residual_over_noise`` of the reported model, of the
  search's unconstrained solution at the same plant parameters (``search_*``: what
  the fit reported before its weights were solved as a model) and, with
  ``--previous REF`` (default main), of the previous code on the same record
  (its own weights and simulate, in its own interpreter);
* ``invertible``: every partial slope of the fitted loop positive (``flattest_branch`` > 0);
* ``errors``: the creep and resonance parameters' relative errors (alpha, b, a1, a2; ``b_with_loop``: b against
  the true b times the true loop's gain relative to the fitted loop on the record's input, ``loop_gain``, the
  product the output determines) and ``within``: all inside the scenario bench's tolerances (``TOL``: alpha
  2 %, b 3 % judged as ``b_with_loop``, a1 5 %, a2 5 %);
* ``uncertainty_rel``, ``error_over_sigma``, ``honest``: the fit's reported 1-sigma of alpha, a1 and a2
  (``ExtendedFit.uncertainty``, relative), the error over it, and whether the error is inside the tolerance or
  within ``HONEST_SIGMAS`` of it (a parameter reported poorly determined has an unbounded one);
* ``inverse_error``: max |invert(forward(u)) - u| over the stroke, fitted weights;
* ``loop_error``: the fitted loop against the true one on another input
  (``other_input``: a full-stroke cycle that wipes the operators' memory, then
  decaying minor loops and a random walk), once its memory is wiped: RMS of
  ``v_true - (c v_fit + d)`` (c, d by least squares: gain and offset belong
  to the linear path) over the true loop's opening (sum w_i 2 r_i); the same for
  the previous code's weights (``previous.loop_error``);
* ``cpu_seconds``: the fit's CPU time (its process'), this code's and the previous code's (``previous.cpu_seconds``,
  its worker fitting the same record while this process waits).

The summary gives each fraction per input family, over all records, and per band of the true loop width
(``WIDTH_BANDS``). Prints one JSON document and writes it to ``bench/results/`` (``--out``).
Usage: ``python -m bench.bench_hysteresis [--records 20] [--families sine,few_levels] [--previous main]``
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time


import creep_online  # noqa: E402,F401  (before numpy: one BLAS thread)
import numpy as np  # noqa: E402

from creep_online.diagnostics.extended import Design, fit_base, fit_extended, prepare  # noqa: E402
from creep_online.effects import hysteresis_input, invert_hysteresis  # noqa: E402
from creep_online.effects.forward import transformed_input  # noqa: E402
from creep_online.effects.hysteresis import Hysteresis, flattest_branch  # noqa: E402
from creep_online.identification import POORLY_DETERMINED  # noqa: E402
from creep_online.metrics import fit_percent, rms  # noqa: E402
from hil_sim.hysteresis_plants import INPUT_FAMILIES, hysteresis_record  # noqa: E402
from bench.harness import dist, results_path, write_report  # noqa: E402

#: simulate reproduces the fit when the RMS of their difference is below this fraction of the noise.
REPRODUCES = 1e-6
#: Relative error tolerances of the creep and resonance parameters (those of ``bench_online_scenarios``).
TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
#: The parameters whose 1-sigma the extended fit reports (``ExtendedFit.uncertainty``): per record their relative
#: 1-sigma, the error over it (``error_over_sigma``), ``flagged`` (reported poorly determined: 1-sigma over identify's
#: POORLY_DETERMINED, inf included) and ``honest``: inside ``TOL`` or within HONEST_SIGMAS of the reported 1-sigma.
UNCERTAIN = ("alpha", "a1", "a2")
HONEST_SIGMAS = 3.0
#: b is judged as the data determine it: with the loop's gain on the record's input (``loop_gain``); the raw
#: ratio is reported too (``errors["b"]``).
GAIN_JUDGED = {"b": "b_with_loop"}
#: Bands of the true loop width over the stroke (the plants draw 2-20 %, log-uniformly).
WIDTH_BANDS = ((0.02, 0.05), (0.05, 0.1), (0.1, 0.2001))

#: The previous code's worker: fits the record in each .npz named on stdin, prints its weights and simulate's miss.
PREVIOUS_WORKER = """
import json, sys, time
import numpy as np
from creep_online.diagnostics.extended import fit_base, fit_extended, prepare
print("ready", flush=True)
for line in sys.stdin:
    z = np.load(line.strip())
    u_pre = None if np.isnan(z["u_pre"]) else float(z["u_pre"])
    data = prepare(z["t"], z["u"], z["y"], u_pre=u_pre)
    c0 = time.process_time()
    fit = fit_extended(data, ("hysteresis",), fit_base(data))
    cpu = time.process_time() - c0
    w = np.asarray(fit.effect_params["hysteresis"]["w"])
    sim = fit.simulate(z["t"], z["u"])
    hp = fit.effect_params["hysteresis"]
    print(json.dumps({"cpu_seconds": cpu, "r": list(hp["r"]), "w": w.tolist(), "initial": hp.get("initial", "centred"),
                      "fit_percent": fit.fit_percent, "residual_rms": fit.residual_rms,
                      "w_max": float(np.max(np.abs(w))), "simulate_rms": float(np.sqrt(np.mean((sim - fit.y_hat) ** 2))),
                      "flattest_branch": float(np.min(s := np.concatenate(([1.0], 1 + np.cumsum(w)))) / np.mean(s))}),
          flush=True)
"""


def other_input(stroke: float, n: int = 4000, seed: int = 0) -> tuple[np.ndarray, int]:
    """(u, start): 0 -> stroke -> 0 (every operator below half the stroke then has a state set by u alone), then
    minor loops decaying from the full stroke and a bounded random walk; ``start``: the first sample after the wipe."""
    rng = np.random.default_rng(seed)
    wipe = np.concatenate([np.linspace(0.0, stroke, n // 8), np.linspace(stroke, 0.0, n // 8)])
    k = np.arange(n // 2)
    amp = stroke * (1.0 - k / k.size)
    minor = amp * (1.0 - np.abs(2.0 * ((k / 250.0) % 1.0) - 1.0))
    walk = np.clip(np.cumsum(rng.normal(0.0, 0.02 * stroke, n - wipe.size - minor.size)) + 0.5 * stroke, 0.0, stroke)
    return np.concatenate([wipe, minor, walk]), wipe.size


def loop_error(true: dict, fitted: dict, stroke: float) -> float:
    """RMS of the true loop's output minus the best affine map of the fitted one on ``other_input``, over the true
    loop's opening (sum_i w_i 2 r_i, the units of v)."""
    u, start = other_input(stroke)
    v_true = hysteresis_input(u, true["r"], true["w"], "centred")[start:]
    v_fit = hysteresis_input(u, fitted["r"], fitted["w"], "centred")[start:]
    a = np.column_stack([v_fit, np.ones_like(v_fit)])
    miss = v_true - a @ np.linalg.lstsq(a, v_true, rcond=None)[0]
    r, w = np.asarray(true["r"]), np.asarray(true["w"])
    return float(rms(miss) / np.sum(w * 2.0 * np.minimum(r, stroke / 2.0)))


def loop_gain(rec, fitted: dict) -> float:
    """c of the best affine map v_true ~ c v_fit + d on the record's own input: the true loop's gain relative to the
    fitted one there. Only b times the loop's gain reaches the output (y = b G[v], v = u + sum w_i p_i[u]), so where
    the record opens fewer operators than the plant has (a step opens none) the fitted b carries the loop's gain on
    that input: b_fit = c b_true is the fit being right."""
    def seen(params: dict) -> np.ndarray:   # v as the linear path sees it, the level before the record first
        v, v_pre = transformed_input({"hysteresis": params}, rec.u, rec.u_pre)
        return v if v_pre is None else np.concatenate([[v_pre], v])
    v_true, v_fit = seen(rec.params), seen(fitted)
    if np.ptp(v_fit) == 0.0:
        return 1.0
    a = np.column_stack([v_fit, np.ones_like(v_fit)])
    return float(np.linalg.lstsq(a, v_true, rcond=None)[0][0])


def dist_finite(x: list[float]) -> dict:
    """The harness summary of the finite values, with the smallest."""
    a = [v for v in x if v is not None and np.isfinite(v)]
    return {**dist(a), "min": float(min(a)) if a else None}


def _previous_worker(ref: str):
    """(worker process, commit): the previous code (``git archive`` of ``ref``) fitting on request."""
    from bench import _baseline
    return _baseline.start_worker(ref, PREVIOUS_WORKER)


def run_one(family: str, seed: int, n: int, worker=None) -> dict:
    rec = hysteresis_record(family, seed, n=n)
    data = prepare(rec.t, rec.u, rec.y, u_pre=rec.u_pre)
    t0, c0 = time.perf_counter(), time.process_time()
    fit = fit_extended(data, ("hysteresis",), fit_base(data))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    hp = fit.effect_params["hysteresis"]
    w = np.asarray(hp["w"])
    sim = fit.simulate(rec.t, rec.u)
    # the search's own (unconstrained, reduced-basis) solution at the same plant parameters
    design = Design(data, ("hysteresis",), 1, {"hysteresis": hp["initial"]})
    coef, y_search, _ = design.project(fit.theta)
    comps = Hysteresis().components(data, hp["initial"])
    w_search = comps @ (np.asarray(coef[1:1 + comps.shape[1]]) / coef[0])
    u_test = rec.u if np.ptp(rec.u) > 0 else np.linspace(0.0, 1.0, 100)
    back = invert_hysteresis(hysteresis_input(u_test, hp["r"], w, hp["initial"]), hp)
    row = {"family": family, "seed": seed, "loop_width_rel_true": rec.notes["loop_width_rel"],
           "alpha_true": rec.model.alpha, "alpha": fit.model.alpha, "initial_true": rec.params["initial"],
           "initial": hp["initial"], "w_max": float(np.max(np.abs(w))), "flattest_branch": flattest_branch(hp["r"], w),
           "opened": hp["opened"], "determined": hp["determined"], "thresholds": len(w),
           "loop_width_rel": hp["loop_width_rel"],
           "simulate_over_noise": float(rms(sim - fit.y_hat) / rec.noise_std),
           "fit_percent": fit.fit_percent, "residual_over_noise": fit.residual_rms / rec.noise_std,
           "search_fit_percent": fit_percent(rec.y, y_search),
           "search_residual_over_noise": float(rms(rec.y - y_search) / rec.noise_std),
           "search_w_max": float(np.max(np.abs(w_search))),
           "w_min": float(np.min(w)), "loop_error": loop_error(rec.params, hp, 2 * max(rec.params["r"])),
           "inverse_error": float(np.max(np.abs(back - u_test)) / max(np.ptp(u_test), 1e-300)),
           "seconds": seconds, "cpu_seconds": cpu}
    row["reproduces"] = row["simulate_over_noise"] <= REPRODUCES
    row["invertible"] = row["flattest_branch"] > 0.0
    row["errors"] = {p: abs(getattr(fit.model, p) / getattr(rec.model, p) - 1.0) for p in TOL}
    row["loop_gain"] = loop_gain(rec, hp)
    row["errors"]["b_with_loop"] = abs(fit.model.b / (rec.model.b * row["loop_gain"]) - 1.0)
    row["within"] = all(row["errors"][GAIN_JUDGED.get(p, p)] <= TOL[p] for p in TOL)
    row["uncertainty_rel"] = {p: fit.uncertainty.get(p, math.nan) / abs(getattr(fit.model, p)) for p in UNCERTAIN}
    row["error_over_sigma"] = {p: row["errors"][p] / row["uncertainty_rel"][p] if row["uncertainty_rel"][p] > 0
                               else math.nan for p in UNCERTAIN}
    row["honest"] = {p: bool(row["errors"][p] <= TOL[p] or not row["error_over_sigma"][p] > HONEST_SIGMAS)
                     for p in UNCERTAIN}
    if worker is not None:
        with tempfile.NamedTemporaryFile(suffix=".npz", delete=False) as fh:
            np.savez(fh, t=rec.t, u=rec.u, y=rec.y, u_pre=np.nan if rec.u_pre is None else rec.u_pre)
        try:
            worker.stdin.write(fh.name + "\n")
            worker.stdin.flush()
            prev = json.loads(worker.stdout.readline())
        finally:
            os.unlink(fh.name)
        row["previous"] = {"fit_percent": prev["fit_percent"], "residual_over_noise": prev["residual_rms"] / rec.noise_std,
                           "w_max": prev["w_max"], "simulate_over_noise": prev["simulate_rms"] / rec.noise_std,
                           "flattest_branch": prev["flattest_branch"], "w_min": float(np.min(prev["w"])),
                           "loop_error": loop_error(rec.params, prev, 2 * max(rec.params["r"])),
                           "cpu_seconds": prev["cpu_seconds"]}
    return row


def summary(rows: list[dict]) -> dict:
    def col(key, sub=None):
        return [(r[sub][key] if sub else r[key]) for r in rows if sub is None or sub in r]
    out = {"records": len(rows), "reproduces": sum(r["reproduces"] for r in rows) / len(rows),
           "invertible": sum(r["invertible"] for r in rows) / len(rows),
           "within_tolerances": sum(r["within"] for r in rows) / len(rows),
           "within_per_parameter": {p: sum(r["errors"][GAIN_JUDGED.get(p, p)] <= TOL[p] for r in rows) / len(rows)
                                    for p in TOL},
           "b_raw_within": sum(r["errors"]["b"] <= TOL["b"] for r in rows) / len(rows),
           "honest": {p: sum(r["honest"][p] for r in rows) / len(rows) for p in UNCERTAIN},
           "flagged": {p: sum(not r["uncertainty_rel"][p] <= POORLY_DETERMINED for r in rows) / len(rows)
                       for p in UNCERTAIN},
           "error_over_sigma": {p: dist_finite([r["error_over_sigma"][p] for r in rows]) for p in UNCERTAIN},
           "relative_errors": {p: dist_finite([r["errors"][p] for r in rows]) for p in (*TOL, "b_with_loop")},
           "w_max": dist_finite(col("w_max")), "w_min": dist_finite(col("w_min")),
           "loop_error": dist_finite(col("loop_error")), "flattest_branch": dist_finite(col("flattest_branch")),
           "simulate_over_noise": dist_finite(col("simulate_over_noise")),
           "residual_over_noise": dist_finite(col("residual_over_noise")),
           "search_residual_over_noise": dist_finite(col("search_residual_over_noise")),
           "fit_percent_minus_search": dist_finite([r["fit_percent"] - r["search_fit_percent"] for r in rows]),
           "search_w_max": dist_finite(col("search_w_max")),
           "opened": dist_finite(col("opened")), "determined": dist_finite(col("determined")),
           "inverse_error": dist_finite(col("inverse_error")), "cpu_seconds": dist_finite(col("cpu_seconds"))}
    prev = [r for r in rows if "previous" in r]
    if prev:
        out["previous"] = {"w_max": dist_finite(col("w_max", "previous")), "w_min": dist_finite(col("w_min", "previous")),
                           "loop_error": dist_finite(col("loop_error", "previous")),
                           "simulate_over_noise": dist_finite(col("simulate_over_noise", "previous")),
                           "reproduces": sum(r["previous"]["simulate_over_noise"] <= REPRODUCES for r in prev) / len(prev),
                           "residual_over_noise": dist_finite(col("residual_over_noise", "previous")),
                           "fit_percent_minus_previous": dist_finite([r["fit_percent"] - r["previous"]["fit_percent"]
                                                               for r in prev]),
                           "flattest_branch": dist_finite(col("flattest_branch", "previous")),
                           "cpu_seconds": dist_finite(col("cpu_seconds", "previous"))}
    return out


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=20, help="seeds per input family")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--samples", type=int, default=10_000, help="samples per record (10 kHz)")
    ap.add_argument("--families", default=",".join(INPUT_FAMILIES), help="comma-separated input families")
    ap.add_argument("--previous", default="main", help="git ref of the previous code fitted on the same records ('' to skip)")
    ap.add_argument("--out", default=None, help="JSON path (default: bench/results/hysteresis_fit_<families>_<seeds>.json)")
    a = ap.parse_args()
    families = [f.strip() for f in a.families.split(",") if f.strip()]
    worker, commit = _previous_worker(a.previous) if a.previous else (None, None)
    t0 = time.time()
    rows = {f: [run_one(f, s, a.samples, worker) for s in range(a.first_seed, a.first_seed + a.records)]
            for f in families}
    if worker is not None:
        worker.stdin.close()
        worker.wait()
    doc = {"samples": a.samples, "h": 1e-4, "first_seed": a.first_seed, "records_per_family": a.records,
           "reproduces_below": REPRODUCES, "previous_commit": commit,
           "tolerances": TOL, "table": {f: summary(r) for f, r in rows.items()},
           "all": summary(every := [r for rs in rows.values() for r in rs]),
           "width_bands": {f"{lo:.2f}-{min(hi, 0.2):.2f}": summary(band) for lo, hi in WIDTH_BANDS
                           if (band := [r for r in every if lo <= r["loop_width_rel_true"] < hi])},
           "rows": rows,
           "elapsed_s": time.time() - t0, "load_average": os.getloadavg()}
    out = a.out or results_path(f"hysteresis_fit_{'all' if len(families) == len(INPUT_FAMILIES) else '-'.join(families)}"
                                f"_{a.first_seed}-{a.first_seed + a.records - 1}")
    write_report(doc, out, echo=False)
    json.dump({k: v for k, v in doc.items() if k != "rows"}, sys.stdout, indent=1, default=float)
    sys.stdout.write("\n")
    return doc


if __name__ == "__main__":
    main()
