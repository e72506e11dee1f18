"""Compensation of hysteresis and creep together, from a model fitted in batch: scans on random plants.

For each seed, a random plant of ``hil_sim.hysteresis_plants`` (Prandtl-Ishlinskii loop 2-20 % of the stroke,
alpha 0.01-0.3, fn 100-1500 Hz, 10 kHz) is identified on a calibration record (a random staircase over the
stroke: its steps excite the resonance and its reversals open the operators) with ``fit_extended(data, ("hysteresis",))``. Its model then drives
``CreepCompensator`` open loop on scans the plant did not see: sine and triangle references over the stroke at
1, 3 and 10 Hz, three periods (at least 1 s). The plant (the true loop, resting centred at 0) answers, noise-free.

Three commands for the same reference r (the output wanted, in output units):

* ``uncompensated``: r divided by the calibration record's static gain (least squares of y on u, with an
  offset: what a user without a model of either effect would apply);
* ``creep_only``: ``CreepCompensator`` with the extended fit's creep and resonance, its loop left out (what
  hysteresis compensation adds);
* ``both``: ``CreepCompensator`` with the extended model (the analytic PI inverse, then creep and resonance).

The error of each is the rms of the output minus the compensator's shaped reference (``shaped_reference``: the
reference through the compensator's filter, the output it can deliver) over the scan's second half, in % of the
output's stroke; ``ratio`` = uncompensated error / compensated error (the issue's goal: >= 10).

Usage: ``python -m bench.bench_hysteresis_compensation [--plants 20] [--first-seed 0]``; JSON in
``bench/results/hysteresis_compensation.json``.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import time

import creep_online  # noqa: F401  (before numpy: one BLAS thread)
import numpy as np

from creep_online.diagnostics.extended import fit_base, fit_extended, prepare
from creep_online.effects.forward import simulate_with_effects
from creep_online.online.compensator import CreepCompensator
from hil_sim.hysteresis_plants import hysteresis_record
from bench.harness import dist, results_path, write_report

#: Scan frequencies (Hz) and shapes.
FREQUENCIES = (1.0, 3.0, 10.0)
SHAPES = ("sine", "triangle")
#: The compensation goal: the uncompensated error over the compensated one.
GOAL_RATIO = 10.0


def scan(shape: str, f: float, h: float, stroke: float) -> np.ndarray:
    """The input-side shape over the stroke (0 .. stroke), three periods or at least 1 s, starting at 0."""
    n = int(round(max(3.0 / f, 1.0) / h))
    phase = f * np.arange(n) * h
    if shape == "sine":
        return 0.5 * stroke * (1.0 - np.cos(2.0 * math.pi * phase))
    return stroke * (1.0 - np.abs(2.0 * (phase % 1.0) - 1.0))


def drive(model, h: float, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(commands, shaped reference) of ``CreepCompensator`` with ``model``, sample by sample."""
    comp = CreepCompensator(h, model)
    u = np.empty_like(r)
    shaped = np.empty_like(r)
    for i, x in enumerate(r.tolist()):
        u[i] = comp.command(x)
        shaped[i] = comp.shaped_reference
    return u, shaped


def plant_output(rec, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The true plant's noise-free output, from rest with its operators centred at 0."""
    loop = {**rec.params, "initial": "centred"}
    return simulate_with_effects(rec.model, t, u, {"hysteresis": loop}, u_pre=0.0)


def one_plant(seed: int, n_calibration: int) -> dict:
    rec = hysteresis_record("random_staircase", seed, n=n_calibration)
    data = prepare(rec.t, rec.u, rec.y, u_pre=rec.u_pre)
    # (the scans start from rest at 0, so the output's offset is 0: the calibration record's offset is its own)
    both = dataclasses.replace(fit_extended(data, ("hysteresis",), fit_base(data)).fitted_model().model, offset=0.0)
    creep = both.base
    gain = float(np.linalg.lstsq(np.column_stack([rec.u, np.ones_like(rec.u)]), rec.y, rcond=None)[0][0])
    stroke = float(np.max(rec.u))
    h = float(rec.t[1] - rec.t[0])
    out = {"seed": seed, "loop_width_rel": rec.notes["loop_width_rel"], "plant": rec.model.params(),
           "static_gain": gain, "scans": []}
    for shape in SHAPES:
        for f in FREQUENCIES:
            shape_u = scan(shape, f, h, stroke)
            t = np.arange(shape_u.size) * h
            r = gain * shape_u
            half = slice(shape_u.size // 2, None)
            errors = {}
            u_both, shaped = drive(both, h, r)
            u_creep, shaped_creep = drive(creep, h, r)
            y = {"uncompensated": plant_output(rec, t, r / gain), "creep_only": plant_output(rec, t, u_creep),
                 "both": plant_output(rec, t, u_both)}
            target = {"uncompensated": shaped, "creep_only": shaped_creep, "both": shaped}
            span = float(np.ptp(shaped[half])) or 1.0
            for name, yy in y.items():
                errors[name] = 100.0 * float(np.sqrt(np.mean((yy[half] - target[name][half]) ** 2))) / span
            out["scans"].append({"shape": shape, "f_hz": f, "error_pct_of_stroke": errors,
                                 "ratio": errors["uncompensated"] / max(errors["both"], 1e-300),
                                 "ratio_creep_only": errors["uncompensated"] / max(errors["creep_only"], 1e-300)})
    return out


def summary(rows: list[dict]) -> dict:
    scans = [s for r in rows for s in r["scans"]]
    by = {}
    for shape in SHAPES:
        for f in FREQUENCIES:
            sel = [s for s in scans if s["shape"] == shape and s["f_hz"] == f]
            by[f"{shape}_{f:g}hz"] = {
                "scans": len(sel), "ratio": dist([s["ratio"] for s in sel]),
                "at_goal": sum(s["ratio"] >= GOAL_RATIO for s in sel) / max(len(sel), 1),
                **{f"error_pct_{k}": dist([s["error_pct_of_stroke"][k] for s in sel])
                   for k in ("uncompensated", "creep_only", "both")}}
    return {"scans": len(scans), "at_goal": sum(s["ratio"] >= GOAL_RATIO for s in scans) / max(len(scans), 1),
            "ratio": dist([s["ratio"] for s in scans]),
            "error_pct_uncompensated": dist([s["error_pct_of_stroke"]["uncompensated"] for s in scans]),
            "error_pct_creep_only": dist([s["error_pct_of_stroke"]["creep_only"] for s in scans]),
            "error_pct_both": dist([s["error_pct_of_stroke"]["both"] for s in scans]), "by_scan": by}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--calibration-samples", type=int, default=20_000, help="calibration record length (10 kHz)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    start = time.perf_counter()
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.plants):
        rows.append(one_plant(seed, args.calibration_samples))
        worst = min(s["ratio"] for s in rows[-1]["scans"])
        print(f"seed {seed}: loop {100 * rows[-1]['loop_width_rel']:.1f} % worst ratio {worst:.1f}", flush=True)
    doc = {"plants": args.plants, "first_seed": args.first_seed, "frequencies_hz": FREQUENCIES, "shapes": SHAPES,
           "goal_ratio": GOAL_RATIO, "summary": summary(rows), "rows": rows,
           "elapsed_s": time.perf_counter() - start}
    write_report(doc, args.out or results_path("hysteresis_compensation"))
    return doc


if __name__ == "__main__":
    main()
