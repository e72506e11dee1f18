"""Saved models reproduce their own fit: ``compare`` on the record a model was fitted on gives its fit percent.

For random records of every class a user makes (from rest with a lead-in, a
plain step at the first sample, a short lead-in, taken in operation with steps
or a dense input, dense from rest, time stamps with jitter, each catalogue
effect hidden in the plant, hil_sim's stationary scenario families, every pair
and triple of catalogue effects hidden at once, 10 s excerpts of the real
micromanipulator record), fixed seeds:

* ``identify``: ``compare(result, record)``, and the model saved and loaded
  again (``save_model``/``load_model``), against the result's fit percent;
  ``result.simulate(t, u)`` against ``result.y_hat``;
* the extended fit (the ``fit`` command's path: the start rule's base fit, then
  ``fit_extended``) with the record's hidden effects (or drift): the same three;
* the command line: ``identify -o`` / ``fit -o`` then ``compare --json``.

A case passes when every fit percent is reproduced within TOLERANCE points.
Prints JSON: the fraction that pass per path and per class, the worst
differences, and the time per case.

A combination class is ``effects:A+B[+C]`` (a random 1 kHz plant from
``hil_sim.hidden_effects``, its staircase, each effect at its ``example_params``
strength, noise 0.2-1 % of the range; the record starts from rest after a
lead-in, with a step at its first sample, or cut out of operation, in turn over the seeds). The real
class ``real:micromanipulator`` is the 10 s excerpt starting at 10 x seed s of
tests/data/real/piezo-micromanipulator-1Hz, fitted with hysteresis and nonlinear gain.

Usage: nice -n 10 python -m bench.bench_model_compare [--seeds 3] [--classes a,b | --set plain|combinations]
       [--no-cli] [--out FILE]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import itertools
import json
import math
import sys
import tempfile
import time
import warnings
import zlib
from pathlib import Path

import numpy as np


from creep_online import CreepModel, compare, load_model, save_model  # noqa: E402
from creep_online.effects import EFFECTS, simulate_with_effects  # noqa: E402
from creep_online.identification import identify  # noqa: E402
from creep_online.io import save_csv  # noqa: E402
from bench.harness import write_report  # noqa: E402

#: Largest difference (fit-percent points) between a fit's own fit percent and compare's on its record.
TOLERANCE = 0.05
#: Record classes without a hidden effect (the catalogue effects are classes ``effect:NAME``).
PLAIN_CLASSES = ("rest_lead_in", "first_sample_step", "short_lead_in", "operation_steps", "operation_dense",
                 "dense_from_rest", "jitter")
#: hil_sim's scenario families whose plant does not change (12-16 s at 1-10 kHz: the slow classes).
SCENARIOS = ("strong_creep", "mid_operation", "quiet_start", "controller")
#: Every pair and triple of catalogue effects hidden at once (the fit gets all of them).
COMBINATIONS = tuple(f"effects:{'+'.join(c)}" for k in (2, 3) for c in itertools.combinations(EFFECTS, k))
#: Real records: (file under tests/data/real, the effects fitted), 10 s excerpts.
REAL = {"real:micromanipulator": ("piezo-micromanipulator-1Hz/micromanipulator_1Hz.csv", "hysteresis,nonlinear_gain")}
REAL_EXCERPT_S = 10.0
CLASSES = (PLAIN_CLASSES + tuple(f"effect:{e}" for e in EFFECTS) + tuple(f"scenario:{s}" for s in SCENARIOS)
           + COMBINATIONS + tuple(REAL))
#: Named sets of classes (``--set``).
SETS = {"plain": PLAIN_CLASSES + tuple(f"effect:{e}" for e in EFFECTS) + tuple(f"scenario:{s}" for s in SCENARIOS),
        "combinations": COMBINATIONS + tuple(REAL)}
#: How a combination record starts, by seed: from rest after a lead-in, a step at the first sample, in operation.
COMBINATION_STARTS = ("rest_lead_in", "first_sample_step", "operation")


def random_plant(rng: np.random.Generator, fs: float) -> CreepModel:
    """alpha 0.02-0.6, fn 0.5-20 % of fs, zeta 0.02-0.5 (log-uniform), b = +-10^U(-1, 1)."""
    def log_uniform(lo: float, hi: float) -> float:
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    return CreepModel.from_resonance(log_uniform(0.02, 0.6), log_uniform(0.005, 0.2) * fs, log_uniform(0.02, 0.5),
                                     float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-1, 1)))


def staircase(n: int, rng: np.random.Generator, start: int, hold: tuple[int, int]) -> np.ndarray:
    """Random levels in [-1, 1] from sample ``start``, each held hold[0]..hold[1] samples (0 before)."""
    u = np.zeros(n)
    i = start
    while i < n:
        u[i:] = rng.uniform(-1.0, 1.0)
        i += int(rng.integers(*hold))
    return u


def dense(n: int, rng: np.random.Generator, start: int) -> np.ndarray:
    """A random staircase with 2-20-sample holds (a controller's or PRBS-like input), 0 before ``start``."""
    return staircase(n, rng, start, (2, 20))


def combination_record(effects: tuple[str, ...], seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, u, y): a random plant with ``effects`` hidden at once, starting as ``COMBINATION_STARTS`` in turn over the
    seeds (from a different place for each combination, so that one seed covers every start)."""
    from hil_sim.hidden_effects import effect_params, random_model, staircase
    key = zlib.crc32("+".join(effects).encode())
    rng = np.random.default_rng([seed, key])
    h = 1e-3
    n = int(rng.integers(3000, 5000))
    start = COMBINATION_STARTS[(seed + key) % len(COMBINATION_STARTS)]
    history = int(rng.integers(n // 4, n // 2)) if start == "operation" else 0
    t, u = staircase(n + history, h, rng)
    model = random_model(rng)
    y_base = simulate_with_effects(model, t, u)
    params = {e: effect_params(e, model, t, u, y_base, rng) for e in effects}
    clean = simulate_with_effects(model, t, u, params)
    if start == "first_sample_step":
        history = int(np.flatnonzero(u)[0])
    clean, u = clean[history:], u[history:]
    y = clean + float(np.ptp(clean)) * rng.uniform(0.002, 0.01) * rng.standard_normal(clean.size)
    return np.arange(clean.size) * h, u, y


def real_excerpt(kind: str, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """(t, u, y, effects) of the 10 s excerpt of a real record starting at 10 x seed s (time from 0)."""
    name, effects = REAL[kind]
    path = Path(__file__).resolve().parent.parent / "tests" / "data" / "real" / name
    t, u, y = np.loadtxt(path, delimiter=",", skiprows=1, unpack=True)
    keep = (t >= REAL_EXCERPT_S * seed) & (t < REAL_EXCERPT_S * (seed + 1))
    if not keep.any():
        raise ValueError(f"{kind}: the record has no excerpt {seed}")
    return t[keep] - t[keep][0], u[keep], y[keep], effects


def make_record(kind: str, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """(t, u, y, effects) of one record of class ``kind`` (deterministic in ``seed``); effects: the hidden ones
    (comma-separated) or ''."""
    if kind in REAL:
        return real_excerpt(kind, seed)
    if kind.startswith("effects:"):
        effects = tuple(kind.split(":", 1)[1].split("+"))
        return (*combination_record(effects, seed), ",".join(effects))
    if kind.startswith("scenario:"):
        from hil_sim.scenarios import make
        sc = make(kind.split(":", 1)[1], seed)
        return sc.t, sc.u, sc.y, ""
    if kind.startswith("effect:"):
        from hil_sim.hidden_effects import hidden_dataset
        effect = kind.split(":", 1)[1]
        ds = hidden_dataset(effect, seed=seed)
        return ds.t, ds.u, ds.y, effect
    rng = np.random.default_rng([seed, CLASSES.index(kind)])
    fs = float(rng.choice([1e3, 2e3, 5e3]))
    h = 1.0 / fs
    n = int(rng.integers(4000, 9000))
    model = random_plant(rng, fs)
    history = 0
    if kind == "rest_lead_in" or kind == "jitter":
        u = staircase(n, rng, int(rng.integers(100, 400)), (n // 8, n // 3))
    elif kind == "first_sample_step":
        u = staircase(n, rng, 0, (n // 6, n // 2))
    elif kind == "short_lead_in":
        u = staircase(n, rng, int(rng.integers(5, 90)), (n // 8, n // 3))
    elif kind == "operation_steps":
        history = int(rng.integers(n // 4, n))
        u = staircase(n + history, rng, 20, (n // 8, n // 3))
    elif kind == "operation_dense":
        history = int(rng.integers(n // 4, n))
        u = dense(n + history, rng, 20)
    else:                                    # dense_from_rest
        u = dense(n, rng, int(rng.integers(50, 300)))
    t = np.arange(u.size) * h
    clean = simulate_with_effects(model, t, u)[history:]
    std = float(np.sqrt(np.mean(clean * clean))) * 10 ** (-40.0 / 20)     # 40 dB
    y = clean + rng.normal(0.0, std, clean.size) + rng.normal(0.0, 0.3 * float(np.std(clean)))
    t = np.arange(clean.size) * h
    if kind == "jitter":
        t = t + rng.uniform(-1e-8, 1e-8, t.size)
    return t, u[history:], y, ""


def extended_fit(t, u, y, effects: str):
    """What ``creep-online fit --effects EFFECTS`` computes: the start rule's base fit, then the extended fit."""
    from creep_online.diagnostics.extended import fit_extended
    from creep_online.diagnostics.start import fit_base_by_rule
    data, base = fit_base_by_rule(t, u, y)
    return fit_extended(data, tuple(effects.split(",")), base)


def _reproduced(result, t, u, y, folder: Path, name: str) -> dict:
    """Fit percents of the result, of compare on it, and of compare on its saved and reloaded model file."""
    path = save_model(result, folder / f"{name}.json")
    out = {"fit": result.fit_percent, "compare": compare(result, (t, u, y)).fit_percent,
           "file": compare(load_model(path), (t, u, y)).fit_percent,
           "simulate": float(np.max(np.abs(result.simulate(t, u) - result.y_hat)) / max(np.ptp(y), 1e-300))}
    return out


def _cli(argv: list[str]) -> dict:
    """``creep-online ARGV --json`` in this process: its JSON output (the exit code must be 0)."""
    from creep_online.cli import main
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(argv + ["--json"])
    if code != 0:
        raise RuntimeError(f"creep-online {' '.join(argv)}: exit {code}")
    return json.loads(buf.getvalue())


def _cli_case(t, u, y, effect: str, folder: Path) -> dict:
    data = folder / "record.csv"
    save_csv(data, t, u, y)
    out = {}
    ident = _cli(["identify", str(data), "-o", str(folder / "id.json")])
    out["identify"] = {"fit": ident["fit_percent"],
                       "compare": _cli(["compare", str(folder / "id.json"), str(data)])["fit_percent"]}
    fit = _cli(["fit", str(data), "--effects", effect or "drift", "-o", str(folder / "fit.json")])
    out["fit"] = {"fit": fit["fit_percent"], "compare": _cli(["compare", str(folder / "fit.json"), str(data)])["fit_percent"]}
    return out


def run_case(kind: str, seed: int, cli: bool) -> dict:
    t, u, y, effect = make_record(kind, seed)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        folder = Path(tmp)
        res = identify(t, u, y)
        case = {"class": kind, "seed": seed, "samples": int(t.size),
                "identify": {**_reproduced(res, t, u, y, folder, "id"),
                             "initial_state": res.initial_response is not None},
                "fit": _reproduced(extended_fit(t, u, y, effect or "drift"), t, u, y, folder, "fit")}
        if cli:
            case["cli"] = _cli_case(t, u, y, effect, folder)
    case["elapsed_s"] = time.perf_counter() - start
    case["worst"] = worst_difference(case)
    case["passed"] = case["worst"] <= TOLERANCE
    return case


def worst_difference(case: dict) -> float:
    """The largest |fit percent - compare's| over the case's paths (Python, model file, CLI)."""
    diffs = [abs(case[p][k] - case[p]["fit"]) for p in ("identify", "fit") for k in ("compare", "file")]
    for p in ("identify", "fit"):
        if "cli" in case:
            diffs.append(abs(case["cli"][p]["compare"] - case["cli"][p]["fit"]))
    return max(diffs)


def summarise(cases: list[dict]) -> dict:
    def fraction(rows: list[dict]) -> float:
        return sum(c["passed"] for c in rows) / len(rows) if rows else float("nan")
    by_class = {k: fraction([c for c in cases if c["class"] == k]) for k in dict.fromkeys(c["class"] for c in cases)}
    worst = {p: float(max(abs(c[p][k] - c[p]["fit"]) for c in cases for k in ("compare", "file")))
             for p in ("identify", "fit")}
    cli = [c for c in cases if "cli" in c]
    if cli:
        worst["cli"] = float(max(abs(c["cli"][p]["compare"] - c["cli"][p]["fit"]) for c in cli for p in ("identify", "fit")))
    elapsed = np.array([c["elapsed_s"] for c in cases])
    groups = {"pairs": [c for c in cases if c["class"].startswith("effects:") and c["class"].count("+") == 1],
              "triples": [c for c in cases if c["class"].startswith("effects:") and c["class"].count("+") == 2],
              "real": [c for c in cases if c["class"] in REAL]}
    return {"cases": len(cases), "passed_fraction": fraction(cases), "tolerance_points": TOLERANCE,
            "combinations": {k: {"cases": len(v), "passed_fraction": fraction(v),
                                 "worst_difference_points": max((c["worst"] for c in v), default=float("nan"))}
                             for k, v in groups.items()},
            "by_class": by_class, "worst_difference_points": worst,
            "initial_state_cases": sum(c["identify"]["initial_state"] for c in cases),
            "simulate_max_rel_error": {p: float(max(c[p]["simulate"] for c in cases)) for p in ("identify", "fit")},
            "elapsed_s": {"p50": float(np.percentile(elapsed, 50)), "p99": float(np.percentile(elapsed, 99)),
                          "max": float(elapsed.max())}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--classes", default=",".join(CLASSES))
    ap.add_argument("--set", choices=tuple(SETS), default=None, help="a named set of classes instead of --classes")
    ap.add_argument("--no-cli", action="store_true", help="skip the command-line path")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    cases = []
    kinds = SETS[args.set] if args.set else args.classes.split(",")
    for kind in kinds:
        for seed in range(args.seeds):
            case = run_case(kind, seed, not args.no_cli)
            cases.append(case)
            print(f"{kind} seed {seed}: worst {case['worst']:.3g} points, {case['elapsed_s']:.1f} s", file=sys.stderr)
    out = {"bench": "model_compare", "command": " ".join(["python", "-m", "bench.bench_model_compare", *sys.argv[1:]]),
           "summary": summarise(cases), "cases": cases}
    write_report(out, args.out, indent=2)


if __name__ == "__main__":
    main()
