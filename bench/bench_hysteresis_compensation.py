"""Compensation of hysteresis and creep together, from a batch fit and from the live (online) estimate.

For each seed, a random plant of ``hil_sim.hysteresis_plants`` (Prandtl-Ishlinskii loop 2-20 % of the stroke,
alpha 0.01-0.3, fn 100-1500 Hz, 10 kHz) is identified on a calibration record (a random staircase over the
stroke: its steps excite the resonance and its reversals open the operators) twice: ``batch``, with
``fit_extended(data, ("hysteresis",))``; ``live``, with ``OnlineEstimator(dt, effects=("hysteresis",))`` fed the same
record in blocks of 100 samples, the model the compensator would hold at its end (``ModelGate``: the creep part with
the estimate's own loop). Each model then drives ``CreepCompensator`` open loop on scans the plant did not see: sine
and triangle references over the stroke at 1, 3 and 10 Hz, three periods (at least 1 s). The plant (the true
loop, resting centred at 0) answers, noise-free.

Three commands for the same reference r (the output wanted, in output units):

* ``uncompensated``: r divided by the calibration record's static gain (least squares of y on u, with an
  offset: what a user without a model of either effect would apply);
* ``creep_only``: ``CreepCompensator`` with the model's creep and resonance, its loop left out (what
  hysteresis compensation adds);
* ``both``: ``CreepCompensator`` with the extended model (the analytic PI inverse, then creep and resonance).

The error of each is the rms of the output minus the compensator's shaped reference (``shaped_reference``: the
reference through the compensator's filter, the output it can deliver) over the scan's second half, in % of the
output's stroke; ``ratio`` = uncompensated error / compensated error (the issue's goal: >= 10).

``drift``: a random plant whose loop width grows 30 % over 60 s (``hil_sim.play_stage.width_scale``) in the
closed loop (``hil_sim.closed_loop.run_closed_loop``, the estimator fed the commands, sensor noise 0.25 % of the
output's stroke): a staircase over the stroke for 6 s (0.3 s holds), then a 2 Hz triangle scan. ``adaptive`` takes
the gate's model at every block of 100 samples; ``frozen`` keeps the model it holds at 10 s. The error is the rms of
the output minus the shaped reference over the last 20 s; goal: adaptive at least 3x smaller than frozen. Both use
the estimator's default window unless ``--drift-window-s`` sets another (``rule``: per plant, the window
docs/online.md's rule gives for its loop width and drift, ``rule_window_s``). Per mode fed the estimator,
``update_block_ms``: p50/p99/max of each ``update_block`` call's own CPU time (ms), what the loop waits for each block.

``--attribute`` (with both sources): two mixed models on the same scans, ``live_creep+batch_loop`` (the live
estimate's creep and resonance with the batch fit's loop) and ``batch_creep+live_loop``: which half of the live
model the compensation error comes from.

Usage: ``python -m bench.bench_hysteresis_compensation [--plants 20] [--first-seed 0] [--drift-plants 4]
[--drift-modes adaptive,frozen] [--drift-references stairs] [--drift-window-s 4|rule] [--attribute]``; JSON in ``bench/results/hysteresis_compensation.json``.
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
from creep_online.model import ExtendedModel
from creep_online.online import ModelGate, OnlineEstimator
from creep_online.online.compensator import CreepCompensator
from hil_sim.closed_loop import run_closed_loop
from hil_sim.hysteresis_plants import random_loop, random_plant, hysteresis_record
from hil_sim.play_stage import width_scale
from bench.bench_online_scenarios import estimator_window_s
from bench.harness import dist, results_path, write_report

#: Model sources compared on the same plants.
SOURCES = ("batch", "live")

#: The mixed models of ``--attribute``: (name, the creep part's source, the loop's source).
MIXED = (("live_creep+batch_loop", "live", "batch"), ("batch_creep+live_loop", "batch", "live"))

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


def live_model(rec) -> tuple[ExtendedModel | None, dict]:
    """The model ``ModelGate`` gives last while the online estimator is fed the record (blocks of 100), and facts."""
    est, gate = OnlineEstimator(float(rec.t[1] - rec.t[0]), effects=("hysteresis",)), ModelGate()
    model, first, updates = None, None, 0
    t0 = time.thread_time()
    for k0 in range(0, rec.t.size, 100):
        est.update_block(rec.u[k0:k0 + 100], rec.y[k0:k0 + 100])
        m = gate.model(est.estimate)
        if m is not None and m != model:
            model, updates = m, updates + 1
            first = est.estimate.t if first is None else first
    e = est.estimate
    return model, {"first_model_t": first, "model_updates": updates, "final_quality": e.quality,
                   "cpu_s": time.thread_time() - t0, "b_rel_error": None if model is None else
                   model.base.b / rec.model.b - 1.0, "alpha_abs_error": None if model is None else
                   model.base.alpha - rec.model.alpha}


def mixed_models(models: dict) -> dict:
    """``MIXED``: the creep part of one source's model with the other's loop (None where either has no model)."""
    out = {}
    for name, creep_from, loop_from in MIXED:
        creep, loop = models.get(creep_from), models.get(loop_from)
        out[name] = None if creep is None or loop is None else ExtendedModel(creep.base, loop.effects)
    return out


def one_plant(seed: int, n_calibration: int, sources: tuple = SOURCES, attribute: bool = False) -> dict:
    rec = hysteresis_record("random_staircase", seed, n=n_calibration)
    models, facts = {}, {}
    if "batch" in sources:
        data = prepare(rec.t, rec.u, rec.y, u_pre=rec.u_pre)
        # (the scans start from rest at 0, so the output's offset is 0: the calibration record's offset is its own)
        models["batch"] = dataclasses.replace(fit_extended(data, ("hysteresis",), fit_base(data)).fitted_model().model,
                                              offset=0.0)
    if "live" in sources:
        models["live"], facts["live"] = live_model(rec)
        if models["live"] is not None:              # (as the batch fit's: the calibration record's offset is its own)
            models["live"] = dataclasses.replace(models["live"], offset=0.0)
    if attribute:
        models.update(mixed_models(models))
    gain = float(np.linalg.lstsq(np.column_stack([rec.u, np.ones_like(rec.u)]), rec.y, rcond=None)[0][0])
    stroke = float(np.max(rec.u))
    h = float(rec.t[1] - rec.t[0])
    out = {"seed": seed, "loop_width_rel": rec.notes["loop_width_rel"], "plant": rec.model.params(),
           "static_gain": gain, "facts": facts, "scans": []}
    for source, both in models.items():
        for shape in SHAPES:
            for f in FREQUENCIES:
                out["scans"].append({"source": source, "shape": shape, "f_hz": f,
                                     **one_scan(rec, both, gain, scan(shape, f, h, stroke), h)})
    return out


def one_scan(rec, both, gain: float, shape_u: np.ndarray, h: float) -> dict:
    """Errors of the three commands on one scan (``both`` None: the source gave no model, the ratio is 0)."""
    t = np.arange(shape_u.size) * h
    r = gain * shape_u
    half = slice(shape_u.size // 2, None)
    if both is None:
        return {"error_pct_of_stroke": None, "ratio": 0.0, "ratio_creep_only": 0.0}
    u_both, shaped = drive(both, h, r)
    u_creep, shaped_creep = drive(both.base, h, r)
    y = {"uncompensated": plant_output(rec, t, r / gain), "creep_only": plant_output(rec, t, u_creep),
         "both": plant_output(rec, t, u_both)}
    target = {"uncompensated": shaped, "creep_only": shaped_creep, "both": shaped}
    span = float(np.ptp(shaped[half])) or 1.0
    errors = {name: 100.0 * float(np.sqrt(np.mean((yy[half] - target[name][half]) ** 2))) / span
              for name, yy in y.items()}
    return {"error_pct_of_stroke": errors, "ratio": errors["uncompensated"] / max(errors["both"], 1e-300),
            "ratio_creep_only": errors["uncompensated"] / max(errors["creep_only"], 1e-300)}


#: Drift comparison: references (``stairs``: a random staircase over the stroke, 0.3 s holds, throughout; ``scan``:
#: that staircase for 6 s, then a 2 Hz triangle) and modes (``run_closed_loop``; ``known`` is the true initial loop
#: frozen, ``oracle`` the true current loop at every block: the limit of adaptation).
DRIFT_REFERENCES = ("stairs", "scan")
DRIFT_MODES = ("adaptive", "frozen", "known", "oracle")
#: The estimator's own default window (s): what a user who sets nothing gets.
ESTIMATOR_WINDOW_S = estimator_window_s()


class TimedBlocks:
    """An estimator whose ``update_block`` calls' own CPU times (s) are kept in ``seconds``: what a control loop
    that feeds it a block at a time waits for (the loop's blocks are 10 ms of samples)."""

    def __init__(self, estimator: OnlineEstimator) -> None:
        self._estimator = estimator
        self.seconds: list[float] = []

    def update_block(self, u: np.ndarray, y: np.ndarray):
        t0 = time.thread_time()
        out = self._estimator.update_block(u, y)
        self.seconds.append(time.thread_time() - t0)
        return out

    def __getattr__(self, name: str):
        return getattr(self._estimator, name)


#: The drift comparison's sensor noise, over the output's stroke.
DRIFT_NOISE_REL = 2.5e-3


def rule_window_s(loop_width_rel: float, growth: float, duration: float) -> float:
    """The window docs/online.md tells a user to choose for a loop that drifts ("A plant that drifts faster than
    the window"): window_s < noise / (A r), A the loop's width and r its relative drift rate per second; at most
    the estimator's default window (a slow drift needs no shorter one)."""
    rate = abs(growth) / duration
    if loop_width_rel <= 0.0 or rate == 0.0:
        return ESTIMATOR_WINDOW_S
    return min(ESTIMATOR_WINDOW_S, DRIFT_NOISE_REL / (loop_width_rel * rate))


def drift_plant(seed: int, reference: str, duration: float = 60.0, growth: float = 0.3, h: float = 1e-4,
                modes: tuple = DRIFT_MODES, window_s: float | str | None = ESTIMATOR_WINDOW_S) -> dict:
    """Adaptive vs frozen on a plant whose loop width grows by ``growth`` over ``duration`` (module docstring);
    ``modes``: the closed loops run (the ratios of those present); ``window_s``: the estimator's, or ``"rule"``:
    the window the docs' rule gives for this plant's loop and drift (``rule_window_s``)."""
    from creep_online.effects import loop_width
    from creep_online.online import warm_kernels
    warm_kernels()          # (as a control loop does before it starts: no block pays for loading a kernel)
    rng = np.random.default_rng([seed, 41])
    plant = random_plant(rng)
    stroke = 1.0
    loop = {**random_loop(rng, stroke), "initial": "centred"}
    n = int(round(duration / h))
    t = np.arange(n) * h
    amp = abs(plant.b) * stroke * (1.0 + float(np.sum(loop["w"])))     # (the output's stroke)
    levels = rng.uniform(0.0, 1.0, int(duration / 0.3) + 1)
    stairs = levels[(t / 0.3).astype(int)]
    shape = stairs if reference == "stairs" else np.where(t < 6.0, stairs, 1.0 - np.abs(2.0 * ((2.0 * t) % 1.0) - 1.0))
    r = shape * amp * np.sign(plant.b)
    scale = width_scale(loop, stroke, growth, n)
    width_rel = loop_width(loop["r"], loop["w"], stroke) / stroke
    if window_s == "rule":
        window_s = rule_window_s(width_rel, growth, duration)
    bandwidth = plant.fn / 2
    f = CreepCompensator(h, plant, bandwidth_hz=bandwidth)
    shaped = np.array([(f.command(x), f.shaped_reference)[1] for x in r])
    late = t >= duration - 20.0
    out = {"seed": seed, "reference": reference, "window_s": window_s, "plant": plant.params(),
           "loop_width_rel": width_rel, "growth": growth, "modes": {}}
    for mode in modes:
        t0 = time.thread_time()
        est = (TimedBlocks(OnlineEstimator(h, window_s=window_s, input_gate=0.0, effects=("hysteresis",)))
               if mode in ("adaptive", "frozen") else None)
        rec = run_closed_loop(t, r, plant, mode, estimator=est, compensator=CreepCompensator(h, bandwidth_hz=bandwidth),
                              hysteresis=loop, loop_scale=scale, noise=DRIFT_NOISE_REL * amp, block=100, seed=seed)
        err = rec.y_clean - shaped
        out["modes"][mode] = {"rms_late_rel": float(np.sqrt(np.mean(err[late] ** 2))) / amp,
                              "model_updates": len(rec.models), "cpu_s": time.thread_time() - t0,
                              "last_model_t": rec.model_t[-1] if rec.model_t else None,
                              **({"update_block_ms": dist(est.seconds, 1e-3)} if est is not None else {})}
    m = out["modes"]
    for name, (over, under) in (("ratio_frozen_over_adaptive", ("frozen", "adaptive")),
                                ("ratio_known_over_oracle", ("known", "oracle"))):
        if over in m and under in m:
            out[name] = m[over]["rms_late_rel"] / max(m[under]["rms_late_rel"], 1e-300)
    return out


def summary(rows: list[dict], source: str) -> dict:
    scans = [s for r in rows for s in r["scans"] if s["source"] == source]
    ok = [s for s in scans if s["error_pct_of_stroke"] is not None]

    def errs(sel: list, k: str) -> dict:
        return dist([s["error_pct_of_stroke"][k] for s in sel if s["error_pct_of_stroke"] is not None])
    by = {}
    for shape in SHAPES:
        for f in FREQUENCIES:
            sel = [s for s in scans if s["shape"] == shape and s["f_hz"] == f]
            by[f"{shape}_{f:g}hz"] = {
                "scans": len(sel), "ratio": dist([s["ratio"] for s in sel]),
                "at_goal": sum(s["ratio"] >= GOAL_RATIO for s in sel) / max(len(sel), 1),
                **{f"error_pct_{k}": errs(sel, k) for k in ("uncompensated", "creep_only", "both")}}
    return {"scans": len(scans), "without_model": len(scans) - len(ok),
            "at_goal": sum(s["ratio"] >= GOAL_RATIO for s in scans) / max(len(scans), 1),
            "plants_all_at_goal": sum(all(s["ratio"] >= GOAL_RATIO for s in r["scans"] if s["source"] == source)
                                      for r in rows) / max(len(rows), 1),
            "ratio": dist([s["ratio"] for s in scans]),
            "ratio_creep_only": dist([s["ratio_creep_only"] for s in scans]),
            "error_pct_uncompensated": errs(ok, "uncompensated"), "error_pct_creep_only": errs(ok, "creep_only"),
            "error_pct_both": errs(ok, "both"), "by_scan": by}


def drift_summary(rows: list[dict]) -> dict:
    out = {}
    for reference in DRIFT_REFERENCES:
        sel = [r for r in rows if r["reference"] == reference and "ratio_frozen_over_adaptive" in r]
        if not sel:
            continue
        ratios = [r["ratio_frozen_over_adaptive"] for r in sel]
        modes = [m for m in DRIFT_MODES if all(m in r["modes"] for r in sel)]
        oracle = [r["ratio_known_over_oracle"] for r in sel if "ratio_known_over_oracle" in r]
        out[reference] = {"plants": len(sel), "ratio_frozen_over_adaptive": dist(ratios),
                          "at_goal": sum(x >= DRIFT_GOAL for x in ratios) / max(len(sel), 1),
                          "ratio_known_over_oracle": dist(oracle) if oracle else None,
                          **{f"rms_late_rel_{m}": dist([r["modes"][m]["rms_late_rel"] for r in sel]) for m in modes}}
    return out


#: The drift goal: the frozen model's error over the adaptive one's.
DRIFT_GOAL = 3.0


def _window_arg(text: str) -> float | str:
    return text if text == "rule" else float(text)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--calibration-samples", type=int, default=40_000, help="calibration record length (10 kHz)")
    ap.add_argument("--sources", default=",".join(SOURCES), help="batch, live or both (comma-separated)")
    ap.add_argument("--drift-plants", type=int, default=4, help="plants of the drifting-loop comparison (0: none)")
    ap.add_argument("--drift-modes", default=",".join(DRIFT_MODES),
                    help="closed loops of the drift comparison (comma-separated; adaptive,frozen for the ratio)")
    ap.add_argument("--drift-references", default=",".join(DRIFT_REFERENCES),
                    help="references of the drift comparison: stairs, scan or both (comma-separated)")
    ap.add_argument("--drift-window-s", type=_window_arg, default=ESTIMATOR_WINDOW_S,
                    help=f"the estimator's window_s in the drift comparison (default {ESTIMATOR_WINDOW_S:g}: "
                         "OnlineEstimator's), or 'rule': per plant, the window the docs' rule gives for its loop "
                         "and drift")
    ap.add_argument("--attribute", action="store_true", help="also the mixed models (live creep with the batch loop "
                    "and the reverse; needs both sources)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    sources = tuple(x for x in args.sources.split(",") if x)
    if args.attribute and set(SOURCES) - set(sources):
        ap.error("--attribute needs both sources (batch,live)")
    summarised = sources + tuple(m[0] for m in MIXED) if args.attribute else sources
    start = time.perf_counter()
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.plants):
        rows.append(one_plant(seed, args.calibration_samples, sources, args.attribute))
        worst = {src: min((s["ratio"] for s in rows[-1]["scans"] if s["source"] == src), default=None)
                 for src in summarised}
        print(f"seed {seed}: loop {100 * rows[-1]['loop_width_rel']:.1f} % worst ratio "
              + ", ".join(f"{k} {v:.1f}" for k, v in worst.items()), flush=True)
    drift = []
    for seed in range(args.first_seed, args.first_seed + args.drift_plants):
        for reference in [x for x in args.drift_references.split(",") if x]:
            drift.append(drift_plant(seed, reference, modes=tuple(x for x in args.drift_modes.split(",") if x),
                                     window_s=args.drift_window_s))
            m = drift[-1]["modes"]
            print(f"drift seed {seed} {reference}: loop {100 * drift[-1]['loop_width_rel']:.1f} % "
                  + " ".join(f"{k} {v['rms_late_rel']:.2e}" for k, v in m.items())
                  + "".join(f" ({k}: update_block max {v['update_block_ms']['max']:.3g} ms)" for k, v in m.items()
                            if "update_block_ms" in v), flush=True)
    doc = {"plants": args.plants, "first_seed": args.first_seed, "calibration_samples": args.calibration_samples,
           "frequencies_hz": FREQUENCIES, "shapes": SHAPES, "goal_ratio": GOAL_RATIO,
           "summary": {src: summary(rows, src) for src in summarised}, "rows": rows,
           "drift_goal": DRIFT_GOAL, "drift_summary": drift_summary(drift) if drift else None, "drift": drift,
           "elapsed_s": time.perf_counter() - start}
    write_report(doc, args.out or results_path("hysteresis_compensation"))
    return doc


if __name__ == "__main__":
    main()
