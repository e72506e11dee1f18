"""Hold physics against the hidden effect (issue 9 item 2): leakage, second creep and drift per strength band.

The records are those of ``bench_diagnose_bands.py`` (same generator, seeds and
bands). Each is diagnosed (``workers=1``); per record: the BIC verdict, the hold
physics check's verdict (``diagnostics/holds.py``), which evidence decided
(``verdict_basis``), and the BIC lead of the verdict over the effect the holds
point to. Per cell: the fractions where the check agrees with the hidden
effect, is inconclusive (or ``none``), or names another effect; and what an
alternative rule -- the hold check overturns the BIC verdict when the BIC lead
is below 10 and the check is decisive -- would have done. Clean records: the
check's verdicts.

    python -m bench.bench_diagnose_physics --records 30 [--first-seed 0] [--out F]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter


from bench.bench_diagnose_bands import BANDS, emit, make_record  # noqa: E402
from creep_online.diagnostics import diagnose  # noqa: E402
from creep_online.diagnostics.holds import EFFECTS  # noqa: E402

#: The alternative rule's threshold: overturn only a BIC lead below this.
OVERTURN_LEAD = 10.0


def run_one(effect: str | None, band: tuple[float, float], seed: int) -> dict:
    """One record: the BIC verdict, the hold check, the basis and what the alternative rule would say."""
    rec = make_record(effect, band, seed)
    t0 = time.perf_counter()
    d = diagnose((rec["t"], rec["u"], rec["y"]), workers=1)
    ph, basis = d.physics, d.verdict_basis
    ev = {c.effect: c.evidence for c in d.candidates}
    pv = ph.get("verdict")
    lead = ev.get(d.verdict, float("nan")) - ev.get(pv, float("nan")) if pv in EFFECTS else None
    overturn = pv in EFFECTS and d.verdict in EFFECTS and pv != d.verdict and lead is not None and lead < OVERTURN_LEAD
    return {"seed": seed, "ratio": rec["ratio"], "plant": rec["plant"], "verdict": d.verdict,
            "physics": pv, "physics_reason": ph.get("reason"), "physics_evidence": ph.get("evidence"),
            "physics_margin": ph.get("margin"), "effective_blocks": ph.get("effective_blocks"),
            "holds": ph.get("holds"), "decided_by": basis["decided_by"], "bic_lead_over_physics": lead,
            "alternative_verdict": pv if overturn else d.verdict, "seconds": time.perf_counter() - t0}


def cell(rows: list[dict], effect: str | None) -> dict:
    """Fractions of agreement with the hidden effect, inconclusive and disagreement; both rules' verdicts."""
    n = len(rows)
    truth = effect or "none"
    agree = sum(r["physics"] == truth for r in rows) if effect else 0
    unsure = sum(r["physics"] in ("inconclusive", "none") for r in rows) if effect else 0
    return {"records": n, "physics_agrees": agree / n, "physics_inconclusive": unsure / n,
            "physics_disagrees": (n - agree - unsure) / n if effect else None,
            "physics_verdicts": dict(Counter(r["physics"] for r in rows).most_common()),
            "bic_named_first": sum(r["verdict"] == truth for r in rows) / n,
            "alternative_rule_named_first": sum(r["alternative_verdict"] == truth for r in rows) / n,
            "decided_by": dict(Counter(r["decided_by"] for r in rows).most_common())}


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--records", type=int, default=30)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    seeds = range(args.first_seed, args.first_seed + args.records)
    started = time.perf_counter()
    rows = {"none|clean": [run_one(None, (1.0, 1.0), s) for s in seeds]}
    table = {"none": cell(rows["none|clean"], None)}
    for effect in EFFECTS:
        for band, limits in BANDS.items():
            rows[f"{effect}|{band}"] = r = [run_one(effect, limits, s) for s in seeds]
            table.setdefault(effect, {})[band] = c = cell(r, effect)
            print(f"[physics] {effect} {band}: agree {c['physics_agrees']:.2f}, inconclusive "
                  f"{c['physics_inconclusive']:.2f}, disagree {c['physics_disagrees']:.2f}", file=sys.stderr, flush=True)
    doc = {"bench": "diagnose_physics", "records_per_cell": args.records, "first_seed": args.first_seed,
           "bands": BANDS, "overturn_lead": OVERTURN_LEAD, "table": table, "load_average": list(os.getloadavg()),
           "elapsed_s": time.perf_counter() - started, "rows": rows}
    return emit(doc, args.out)


if __name__ == "__main__":
    main()
