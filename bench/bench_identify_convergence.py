"""Global convergence of ``identify`` on the randomized validation set (issue 9, item 1).

For every record of ``hil_sim.validation`` (seeded; 7 input families) the
fit% of ``identify`` is compared with the fit% of the true model on the same
noisy record (its history included for records taken in operation). A record is
"at the floor" when the fit is within 0.05 points of the truth's. The same
records are identified by the baseline code (``git archive`` of --baseline-ref,
in a subprocess) for a before/after table.

Usage: python -m bench.bench_identify_convergence [--per-family 30] [--baseline-ref main]
           [--no-baseline] [--out bench/results/identify_convergence.json]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np


from creep_online.identification import identify  # noqa: E402
from creep_online.metrics import fit_percent  # noqa: E402
from hil_sim.validation import FAMILIES, validation_set  # noqa: E402

from bench import _baseline  # noqa: E402
from bench.harness import write_report  # noqa: E402

FLOOR_POINTS = 0.05

#: Runs in the baseline's interpreter: identify every record of an npz, print fits as JSON.
BASELINE_CODE = """
import json, sys, time
import numpy as np
from creep_online.identification import identify
from creep_online.metrics import fit_percent
d = np.load(sys.argv[1])
out = []
for k in range(int(d["count"])):
    t, u, y = d[f"t{k}"], d[f"u{k}"], d[f"y{k}"]
    t0 = time.perf_counter()
    try:
        r = identify(t, u, y)
        out.append({"fit": fit_percent(y, r.y_hat), "alpha": r.model.alpha, "a2": r.model.a2,
                    "elapsed_s": time.perf_counter() - t0})
    except Exception as exc:
        out.append({"fit": float("nan"), "error": type(exc).__name__ + ": " + str(exc)[:120]})
print(json.dumps(out))
"""


def run_ours(records) -> list[dict]:
    out = []
    for rec in records:
        t0 = time.perf_counter()
        try:
            r = identify(rec.t, rec.u, rec.y)
            out.append({"fit": fit_percent(rec.y, r.y_hat), "alpha": r.model.alpha, "a2": r.model.a2,
                        "elapsed_s": time.perf_counter() - t0, "warnings": r.warnings})
        except Exception as exc:  # noqa: BLE001 - a failure counts as not at the floor
            out.append({"fit": float("nan"), "error": f"{type(exc).__name__}: {str(exc)[:120]}"})
    return out


def run_baseline(records, ref: str) -> tuple[list[dict], str]:
    path, commit = _baseline.extract(ref)
    arrays = {"count": len(records)}
    for k, rec in enumerate(records):
        arrays.update({f"t{k}": rec.t, f"u{k}": rec.u, f"y{k}": rec.y})
    npz = os.path.join(tempfile.mkdtemp(prefix="creep_conv_"), "records.npz")
    np.savez(npz, **arrays)
    return json.loads(_baseline.run_python(path, BASELINE_CODE, npz)), commit


def table(records, results) -> dict:
    rows = {}
    for fam in FAMILIES:
        ks = [k for k, r in enumerate(records) if r.family == fam]
        if not ks:
            continue
        gaps = [records[k].true_fit - results[k]["fit"] for k in ks]
        at = [g <= FLOOR_POINTS for g in gaps]  # NaN compares False: a failure is not at the floor
        rows[fam] = {"records": len(ks), "at_floor": int(sum(at)), "fraction": sum(at) / len(ks),
                     "worst_gap_points": float(np.nanmax(gaps)) if np.any(np.isfinite(gaps)) else None,
                     "median_elapsed_s": float(np.median([results[k].get("elapsed_s", np.nan) for k in ks])),
                     "misses": [{"seed": records[k].seed, "gap": gaps[k_i], "model": records[k].model.params()}
                                for k_i, k in zip(range(len(ks)), ks) if not at[k_i]][:10]}
    total = sum(r["at_floor"] for r in rows.values())
    return {"per_family": rows, "overall": {"records": len(records), "at_floor": total,
                                            "fraction": total / len(records)}}


def timing_check(count: int) -> dict:
    """Asynchronous sampling (item 3): random staircases whose changes reach the plant between samples,
    and the same plants with every change on a sample; how often identify warns, and alpha's error."""
    from hil_sim.validation import make_async_record
    out = {}
    for label, sync in (("asynchronous", False), ("synchronous_control", True)):
        warned, errs, gaps, silent = 0, [], [], []
        for seed in range(count):
            rec = make_async_record(seed, synchronous=sync)
            r = identify(rec.t, rec.u, rec.y)
            hit = any("asynchronous" in w for w in r.warnings)
            warned += hit
            errs.append(abs(r.model.alpha / rec.model.alpha - 1) * 100)
            gaps.append(fit_percent(rec.y, rec.truth) - r.fit_percent)
            if not hit:                    # what a user would get without a warning
                silent.append({"seed": seed, "alpha_error_percent": errs[-1], "fit_gap_points": gaps[-1]})
        out[label] = {"records": count, "warned": warned, "alpha_error_percent_median": float(np.median(errs)),
                      "alpha_error_percent_max": float(np.max(errs)), "fit_gap_points_median": float(np.median(gaps)),
                      **({} if sync else {"not_warned": silent})}   # (the controls are not meant to warn)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=30)
    ap.add_argument("--baseline-ref", default="main")
    ap.add_argument("--no-baseline", action="store_true")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args()
    records = list(validation_set(args.per_family, tuple(args.families.split(","))))
    for rec in records:
        rec.true_fit = fit_percent(rec.y, rec.truth)
    head = _baseline.subprocess.run(["git", "-C", _baseline.ROOT, "rev-parse", "HEAD"], capture_output=True,
                                    text=True).stdout.strip()
    report = {"bench": "identify_convergence", "floor_points": FLOOR_POINTS, "per_family": args.per_family,
              "after": {"commit": head, **table(records, run_ours(records))},
              "timing": timing_check(args.per_family)}
    if not args.no_baseline:
        base, commit = run_baseline(records, args.baseline_ref)
        report["before"] = {"commit": commit, **table(records, base)}
    write_report(report, args.out, indent=2)


if __name__ == "__main__":
    main()
