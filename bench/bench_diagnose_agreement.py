"""Does ``diagnose`` still give the previous code's answers? The same randomized records through both, compared.

Records: the bands bench's single-effect records (``bench_diagnose_bands.make_record``, 6,000 samples, every
catalogue effect and a clean one), the pairs bench's two-effect records (``bench_diagnose_pairs.make_pair_record``)
and long simulated records (``hil_sim.hidden_effects.hidden_dataset``, where the exploration window and the pair
search's window differ from the record). Each code diagnoses every record in its own interpreter (the previous
one: ``git archive`` of ``--previous``, its own numba cache). Per record: whether the verdict, the candidates'
order, the combination and the significant flags are the same, and the largest difference of a fit percent
(base, each candidate, the combination). Prints one JSON document (``bench/results/diagnose_agreement.json``):
the fraction of records with the same verdict and order, and each record's row.

Usage: ``python -m bench.bench_diagnose_agreement [--seeds 2] [--long hysteresis:1:30000,...] [--previous main]``
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from bench.harness import ROOT, results_path, write_report

#: Diagnoses the records named on the command line, one JSON line each.
WORKER = r"""
import json, sys, time
import creep_online
import numpy as np
from creep_online.diagnostics import diagnose
from creep_online.effects import effect_names
for name in sys.argv[1:]:
    kind, what, seed, more = name.split(":")
    if kind == "single":
        from bench.bench_diagnose_bands import BANDS, make_record
        rec = make_record(None if what == "none" else what, BANDS[more], int(seed))
        t, u, y = rec["t"], rec["u"], rec["y"]
    elif kind == "pair":
        from bench.bench_diagnose_bands import BANDS
        from bench.bench_diagnose_pairs import make_pair_record
        rec = make_pair_record(tuple(what.split("+")), BANDS[more], int(seed))
        t, u, y = rec["t"], rec["u"], rec["y"]
    else:
        from hil_sim.hidden_effects import hidden_dataset
        ds = hidden_dataset(None if what == "none" else what, int(seed), n=int(more))
        t, u, y = ds.t, ds.u, ds.y
    t0 = time.process_time()
    d = diagnose((t, u, y), workers=1)
    c = d.combination
    print(json.dumps({"record": name, "cpu_seconds": time.process_time() - t0, "verdict": d.verdict,
                      "fit_percent_base": d.base.fit_percent,
                      "candidates": [[x.effect, x.fit.fit_percent, bool(x.significant)] for x in d.candidates],
                      "combination": None if c is None else [c.effect, c.fit.fit_percent, bool(c.significant)]}),
          flush=True)
"""


def records(seeds: int, long: list[str]) -> list[str]:
    """The record names: single effects (and none) in two bands, the pairs bench's pairs in one, the long ones."""
    from bench.bench_diagnose_pairs import PAIRS
    from creep_online.effects import effect_names
    names = [f"single:{e}:{s}:{band}" for s in range(seeds) for e in ("none", *effect_names())
             for band in ("3-10x", "10-100x")]
    names += [f"pair:{a}+{b}:{s}:3-10x" for s in range(seeds) for a, b in PAIRS]
    return names + [f"long:{x}" for x in long]


def run(path: str, names: list[str]) -> dict[str, dict]:
    """Each record's diagnosis by the code at ``path`` (a fresh interpreter, its own numba cache unless ROOT)."""
    env = dict(os.environ, PYTHONPATH=path)
    if path != str(ROOT):
        env["NUMBA_CACHE_DIR"] = os.path.join(path, ".numba_cache")
    out = subprocess.run([sys.executable, "-c", WORKER, *names], check=True, capture_output=True, text=True,
                         env=env, cwd=path).stdout
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return {r["record"]: r for r in rows}


def compare(ours: dict, prev: dict) -> dict:
    """Same verdict, order, significance and combination; the largest fit-percent difference."""
    theirs = {e: f for e, f, _ in prev["candidates"]}
    diffs = [abs(ours["fit_percent_base"] - prev["fit_percent_base"])]
    diffs += [abs(f - theirs[e]) for e, f, _ in ours["candidates"] if e in theirs]
    combo = (ours["combination"] or [None])[0] == (prev["combination"] or [None])[0]
    if combo and ours["combination"]:
        diffs.append(abs(ours["combination"][1] - prev["combination"][1]))
    return {"verdict": ours["verdict"] == prev["verdict"],
            "order": [e for e, _, _ in ours["candidates"]] == [e for e, _, _ in prev["candidates"]],
            "significant": [s for _, _, s in ours["candidates"]] == [s for _, _, s in prev["candidates"]],
            "combination": combo, "max_fit_percent_difference": max(diffs),
            "cpu_seconds": {"this": ours["cpu_seconds"], "previous": prev["cpu_seconds"]}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=2, help="seeds per effect, band and pair")
    p.add_argument("--long", default="hysteresis:1:30000,second_creep:2:30000,drift:3:30000,none:4:30000",
                   help="comma-separated EFFECT:SEED:N long simulated records ('' for none)")
    p.add_argument("--previous", default="main", help="git ref of the previous code")
    p.add_argument("--out", default=str(results_path("diagnose_agreement")))
    a = p.parse_args()
    names = records(a.seeds, [x for x in a.long.split(",") if x])
    from bench import _baseline
    path, commit = _baseline.extract(a.previous)
    prev, ours = run(path, names), run(str(ROOT), names)
    rows = {n: compare(ours[n], prev[n]) for n in names}
    same = [n for n, r in rows.items() if r["verdict"] and r["order"] and r["combination"]]
    cpu = {k: sum(r["cpu_seconds"][k] for r in rows.values()) for k in ("this", "previous")}
    write_report({"previous_commit": commit, "records": len(names),
                  "same_verdict": sum(r["verdict"] for r in rows.values()) / len(names),
                  "same_verdict_order_and_combination": len(same) / len(names),
                  "max_fit_percent_difference": max(r["max_fit_percent_difference"] for r in rows.values()),
                  "cpu_seconds_total": cpu, "differing": [n for n in names if n not in same], "rows": rows},
                 a.out)


if __name__ == "__main__":
    main()
