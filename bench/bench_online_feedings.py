"""Does the online estimator's result depend on how a record is fed? Sample by sample, in chunks, in one block.

Usage (from the repository root)::

    python -m bench.bench_online_feedings [--seeds 1003,1004,1005] [--families triangle,sine] [--n 20000]

Each hil_sim hysteresis record (``hysteresis_plants.hysteresis_record``, fixed seeds) runs through
``OnlineEstimator(h)`` and ``OnlineEstimator(h, effects=("hysteresis",))`` fed: one block; 200-sample chunks;
random chunks (seeded); sample by sample with the default work budget; and with ``work_units=4`` in one block and
sample by sample. Per feeding it reports alpha, b, the hysteresis weights, the largest relative difference from the
one-block estimate with the same work budget (alpha, b, the weights over the largest weight), the sample at which the tracker went live and the replays swapped in
(``Replayer.relinearize_job``); per estimator kind, over the records with an estimate, the fraction whose feedings all
give the one block's estimate exactly (``==``).
"""
from __future__ import annotations

import argparse

import numpy as np

from bench.harness import dist, results_path, write_report
from creep_online.online import OnlineEstimator
from hil_sim.hysteresis_plants import hysteresis_record

#: Samples per chunk of the fixed-chunk feeding (the issue's reproduction).
CHUNK = 200
#: Random cuts of the random-chunk feeding.
CUTS = 40


def feed(rec, effects: tuple, how: str) -> dict:
    """One feeding of ``rec``: its estimate, weights, the sample where the tracker went live, replays swapped."""
    h = float(rec.t[1] - rec.t[0])
    est = OnlineEstimator(h, effects=effects, work_units=4 if how.endswith("_units4") else None)
    live = None
    if how.startswith("sample"):
        for k, (a, b) in enumerate(zip(rec.u.tolist(), rec.y.tolist())):
            est.update(a, b)
            if live is None and est._live is not None:
                live = k + 1
    else:
        n = rec.u.size
        cuts = {"block": [], "block_units4": [], "chunks": np.arange(0, n, CHUNK),
                "random": np.random.default_rng(7).integers(0, n, CUTS)}[how]
        pieces = np.unique(np.concatenate(([0, n], cuts))).astype(int)
        for a, b in zip(pieces[:-1], pieces[1:]):
            est.update_block(rec.u[a:b], rec.y[a:b])
            if live is None and est._live is not None:
                live = int(b)
    e = est.estimate
    tr = est._live
    return {"alpha": e.alpha, "b": e.b, "w": e.hysteresis["w"] if e.hysteresis else None, "live_at": live,
            "replays": getattr(tr, "relinearizations", None)}


def compare(runs: dict) -> dict:
    """Each feeding's largest relative difference from the one-block run with the same work budget (alpha, b,
    weights over max |w|)."""
    out = {}
    for how, r in runs.items():
        ref = runs["block_units4" if how.endswith("_units4") else "block"]
        if r["alpha"] is None or ref["alpha"] is None:      # (no estimate: equal only if neither has one)
            out[how] = 0.0 if r["alpha"] is ref["alpha"] else float("inf")
            continue
        d = max(abs(r["alpha"] / ref["alpha"] - 1.0), abs(r["b"] / ref["b"] - 1.0))
        if r["w"] is not None and ref["w"] is not None:
            w, w0 = np.asarray(r["w"]), np.asarray(ref["w"])
            d = max(d, float(np.max(np.abs(w - w0)) / max(np.max(np.abs(w0)), 1e-300)))
        out[how] = d
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", default="1003,1004,1005")
    p.add_argument("--families", default="triangle,random_staircase")
    p.add_argument("--n", type=int, default=20_000)
    args = p.parse_args(argv)
    feedings = ("block", "chunks", "random", "sample", "block_units4", "sample_units4")
    doc: dict = {"records": [], "summary": {}}
    for kind, effects in (("plain", ()), ("hysteresis", ("hysteresis",))):
        same, diffs = [], {how: [] for how in feedings}
        for family in args.families.split(","):
            for seed in (int(s) for s in args.seeds.split(",")):
                rec = hysteresis_record(family, seed, n=args.n)
                runs = {how: feed(rec, effects, how) for how in feedings}
                if runs["block"]["alpha"] is None:     # (no estimate in one block: nothing to compare)
                    doc["records"].append({"kind": kind, "family": family, "seed": seed, "runs": runs})
                    continue
                rel = compare(runs)
                for how in feedings:
                    diffs[how].append(rel[how])
                same.append(all(v == 0.0 for v in rel.values()))
                doc["records"].append({"kind": kind, "family": family, "seed": seed, "runs": runs, "rel_diff": rel})
        doc["summary"][kind] = {"identical_fraction": float(np.mean(same)),
                                "rel_diff_vs_block": {how: dist(diffs[how]) for how in feedings}}
    write_report(doc, results_path("online_feedings"), argv=argv)


if __name__ == "__main__":
    main()
