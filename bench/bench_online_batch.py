"""Online against batch on the same records, and the online estimator's live prediction error per window.

Usage (from the repository root, with the package installed or ``PYTHONPATH=.``)::

    python -m bench.bench_online_batch [--plants 20] [--seed-offset 0] [--snr-db 40] [--families payload,drift]
        [--rest-samples 0] [--out bench/results/online_vs_batch_40db.json]
    python -m bench.bench_online_batch --real [--out bench/results/online_divergence_real.json]
    python -m bench.bench_online_batch --merge A.json B.json ... --snr-db 40 [--out bench/results/online_vs_batch_40db.json]
    python -m bench.bench_online_batch --table bench/results/online_vs_batch_40db.json bench/results/online_vs_batch_80db.json

A run writes its results file after every record (a run that is stopped keeps the records it finished); runs of
one family each, in turn, are merged into one file per SNR with ``--merge``.

Scenario records (``hil_sim.scenarios``; ``--rest-samples`` as in ``bench_online_scenarios.py``): each is fed to
``OnlineEstimator`` sample by sample (``update()``), its live prediction error (the output minus
``last_prediction`` after each sample, as ``creep-online fit --online`` shows it) kept; the final estimate and
its 1-sigma are compared with ``identify`` on the same data:

* the record, for the stationary families (mid_operation: ``identify`` reads it in operation);
* the samples after the change (t re-zeroed, the plant then in operation) for payload and stiffness;
* the last window (the estimator's ``window_s``, 10 s) for drift, which ``identify`` reads as taken in operation
  (its initial state estimated): the online estimate is the plant's value now, a batch fit of the whole drifting
  record its average, and one of the last window with the input's history known and the parameters held constant
  over it is biased by the drift (alpha 7-90 % off on drift seeds 6, 8, 14, 18 at 40 dB).

A record counts where it *determines* the plant: ``identify`` fits it at the noise floor (its residual's rms
within ``identification.FLOOR_WARNING`` of its white-noise level: what ``identify`` itself warns about) and
every parameter's 1-sigma from that fit, relative to its value, is within the limits the online estimator calls
"determined" (``creep_online.online.policy.limits.DeterminedLimits``: alpha 1 %, b 1.5 %, a1 and a2 2.5 %, half
the tolerances). A record whose batch fit leaves a parameter wider than that does not say what the parameter is,
so neither estimate can be judged against the other there (the online estimate reads ``provisional`` on such
records); the table counts these records apart. On a determined record the online estimate agrees when, for each
of alpha, b, a1, a2, ``|online - batch|`` is within the looser of the combined 1-sigma
(``sqrt(sd_online^2 + sd_batch^2)``) and the scenario tolerance (alpha 2 %, b 3 %, a1 and a2 5 % of the batch
value).

Divergence: per window of 1 s where the estimator tracks, the rms of the live prediction error over the rms
variation of the output (its standard deviation over the window): a prediction worse than the window's own mean
is a divergence. Where the output holds still within its noise, even the true model's error is the noise and the
ratio is 1 within the noise's own fluctuation, so a window counts as divergent when its ratio exceeds
``1 + 3 / sqrt(n)`` (n predicted samples: three standard deviations of an rms over n samples); the largest ratio of
all is reported beside it. The windows from a plant change to ``CHANGE_ALLOWANCE_S`` after it are reported
apart: until the change shows and is re-searched the live prediction is the old plant's (a gain step in a hold:
the output's level moves while it holds still, and the old model misses it by many times the hold's spread).
Windows with fewer than half their samples predicted are left out. ``--real`` runs every record in
tests/data/real (uniform time; the polymer-melt records' log-spaced time is not) through the same check.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from bench.harness import results_path, write_report  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ("alpha", "b", "a1", "a2")
#: The scenario tolerances (relative), as bench_online_scenarios.TOL.
TOL = {"alpha": 0.02, "b": 0.03, "a1": 0.05, "a2": 0.05}
#: Divergence windows (s).
WINDOW_S = 1.0
def command_line() -> str:
    """The command line that made a results document (recorded in it)."""
    return " ".join(["python -m bench.bench_online_batch", *sys.argv[1:]])


#: Windows this long after a plant change are reported apart (the change test's half second, the post-change
#: search's wait for an input move, up to 1 s, and its replay).
CHANGE_ALLOWANCE_S = 2.0


def live_run(h: float, u: np.ndarray, y: np.ndarray, **kwargs):
    """The estimator fed sample by sample; (estimator, live prediction error per sample: NaN while not tracking)."""
    from creep_online.online import OnlineEstimator
    est = OnlineEstimator(h, **kwargs)
    err = np.full(u.size, np.nan)
    for i, (a, b) in enumerate(zip(u.tolist(), y.tolist())):
        est.update(a, b)
        p = est.last_prediction
        if p is not None and est.phase == "tracking":
            err[i] = b - p
    return est, err


def window_ratios(err: np.ndarray, y: np.ndarray, h: float, window_s: float = WINDOW_S) -> list[dict]:
    """Per window of ``window_s``: the live error's rms over the output's standard deviation there (windows with at
    least half their samples predicted)."""
    w = max(2, int(round(window_s / h)))
    out = []
    for a in range(0, y.size - w // 2, w):
        e = err[a:a + w]
        ok = np.isfinite(e)
        if np.count_nonzero(ok) < w // 2:
            continue
        spread = float(np.std(y[a:a + w][ok]))
        rms = float(np.sqrt(np.mean(e[ok] ** 2)))
        n = int(np.count_nonzero(ok))
        ratio = rms / spread if spread > 0 else (0.0 if rms == 0 else math.inf)
        out.append({"t": a * h, "error_rms": rms, "output_std": spread, "ratio": ratio, "n": n,
                    "divergent": bool(ratio > 1.0 + 3.0 / math.sqrt(n))})
    return out


def divergence(windows: list[dict], change_time: float | None = None) -> dict:
    """The divergence check of one record: the largest window ratio, the divergent windows (``window_ratios``) away
    from a plant change, and the largest ratio in the windows within CHANGE_ALLOWANCE_S after it."""
    after = [w for w in windows if change_time is not None
             and w["t"] + WINDOW_S > change_time and w["t"] < change_time + CHANGE_ALLOWANCE_S]
    rest = [w for w in windows if w not in after]
    return {"max_window_ratio": max((w["ratio"] for w in windows), default=None),
            "divergent_windows": sum(w["divergent"] for w in rest),
            "max_ratio_away_from_change": max((w["ratio"] for w in rest), default=None),
            "max_ratio_after_change": max((w["ratio"] for w in after), default=None)}


def batch_segment(scen, window_s: float) -> slice:
    """The samples ``identify`` is given (module docstring)."""
    n = scen.u.size
    if scen.family == "drift":
        return slice(max(0, n - int(round(window_s / scen.h))), n)
    if scen.change_time is not None:
        return slice(int(round(scen.change_time / scen.h)), n)
    return slice(0, n)


def batch_fit(scen, window_s: float) -> dict:
    """``identify`` on the record's batch segment: its model, 1-sigma and floor ratio (or the error)."""
    from creep_online.global_fit import floor_ratio
    from creep_online.identification import FLOOR_WARNING, identify
    seg = batch_segment(scen, window_s)
    u, y = scen.u[seg], scen.y[seg]
    t = np.arange(u.size) * scen.h
    try:
        res = identify(t, u, y)
    except Exception as exc:  # noqa: BLE001 - a batch failure is a result
        return {"error": f"{type(exc).__name__}: {exc}"}
    ratio = floor_ratio(y - res.y_hat)
    return {"model": res.model.params(), "sd": dict(res.uncertainty), "floor_ratio": ratio,
            "at_floor": bool(ratio <= FLOOR_WARNING), "segment_s": [seg.start * scen.h, u.size * scen.h]}


def agreement(online: dict, sd_online: dict, batch: dict, sd_batch: dict) -> dict:
    """Per parameter: |online - batch|, the combined 1-sigma, the tolerance, and whether within the looser."""
    out = {}
    for p in PARAMS:
        on, ba = online.get(p), batch[p]
        diff = math.inf if on is None else abs(on - ba)
        sigma = math.hypot(sd_online.get(p, math.inf), sd_batch.get(p, math.inf))
        tol = TOL[p] * abs(ba)
        out[p] = {"online": on, "batch": ba, "rel_diff": diff / abs(ba) if ba else math.inf,
                  "combined_sigma_rel": sigma / abs(ba) if ba else math.inf, "within": bool(diff <= max(sigma, tol))}
    return out


def scenario_row(scen, window_s: float) -> dict:
    """One scenario record: online (sample by sample), batch, agreement, divergence."""
    t0 = time.perf_counter()
    est, err = live_run(scen.h, scen.u, scen.y)
    e = est.estimate
    online = {p: getattr(e, p) for p in PARAMS}
    windows = window_ratios(err, scen.y, scen.h)
    batch = batch_fit(scen, window_s)
    row = {"family": scen.family, "seed": scen.seed, "quality": e.quality, "start": e.start, "online": online,
           "online_sd": dict(e.uncertainty), "batch": batch, **divergence(windows, scen.change_time),
           "worst_window": max(windows, key=lambda w: w["ratio"]) if windows else None,
           "truth": scen.final_truth, "elapsed_s": time.perf_counter() - t0}
    if "model" in batch:
        row["agreement"] = agreement(online, row["online_sd"], batch["model"], batch["sd"])
        row["agrees"] = all(v["within"] for v in row["agreement"].values())
    return row


def undetermined(batch: dict) -> list[str]:
    """The parameters a batch fit leaves wider than ``DeterminedLimits`` (relative 1-sigma; module docstring)."""
    from creep_online.online.policy.limits import DeterminedLimits
    model, sd = batch["model"], batch["sd"]
    return [p for p, limit in DeterminedLimits().items()
            if not (model[p] and sd.get(p, math.inf) <= limit * abs(model[p]))]


def determined(row: dict) -> bool:
    """Whether a record determines the plant: its batch fit at the noise floor with every parameter determined."""
    return bool(row["batch"].get("at_floor")) and not undetermined(row["batch"])


def family_summary(rows: list[dict]) -> dict:
    """Per family: records, those at the batch floor, those determined (``determined``), the fraction agreeing
    there (and over all), the worst relative differences there, and the divergence check."""
    at_floor = [r for r in rows if r["batch"].get("at_floor")]
    floor = [r for r in at_floor if determined(r)]
    ratios = [r["max_window_ratio"] for r in rows if r["max_window_ratio"] is not None]
    away = [r["max_ratio_away_from_change"] for r in rows if r["max_ratio_away_from_change"] is not None]
    after = [r["max_ratio_after_change"] for r in rows if r["max_ratio_after_change"] is not None]
    return {
        "records": len(rows), "at_batch_floor": len(at_floor), "determined": len(floor),
        "agree_determined": (sum(r["agrees"] for r in floor) / len(floor)) if floor else None,
        "agree_all": sum(bool(r.get("agrees")) for r in rows) / len(rows),
        "max_rel_diff_determined": {p: max((r["agreement"][p]["rel_diff"] for r in floor), default=None)
                                    for p in PARAMS},
        "disagreeing_determined": [{"seed": r["seed"], **{p: r["agreement"][p] for p in PARAMS}}
                                   for r in floor if not r["agrees"]],
        "undetermined": [{"seed": r["seed"], "agrees": r["agrees"], "online_quality": r["quality"],
                          "batch_undetermined": undetermined(r["batch"]), "off_truth": truth_errors(r)}
                         for r in at_floor if not determined(r)],
        "max_window_ratio": max(ratios) if ratios else None,
        "max_ratio_away_from_change": max(away) if away else None,
        "max_ratio_after_change": max(after) if after else None,
        "divergent_records": sum(r["divergent_windows"] > 0 for r in rows)}


def truth_errors(row: dict) -> dict:
    """Per estimator (online, batch): the parameters outside the scenario tolerance of the record's final truth
    (close_modes: its best second-order fit): who is off where the two disagree."""
    truth = row["truth"]
    out = {}
    for name, est in (("online", row["online"]), ("batch", row["batch"].get("model") or {})):
        out[name] = sorted(p for p in PARAMS if est.get(p) is None or abs(est[p] / truth[p] - 1) > TOL[p])
    return out


def table(doc: dict) -> str:
    """The online-vs-batch table of a results document, one line per family (``--table``)."""
    lines = [f"{doc['config']['snr_db']:g} dB" + ("" if doc["config"].get("rest_samples") is None else
                                                 f", rest {doc['config']['rest_samples']} samples"),
             f"{'family':14s} {'records':>7s} {'at floor':>8s} {'determ.':>7s} {'agree':>6s} "
             f"{'max |on-batch|/batch, determined (alpha b a1 a2)':>48s}"
             f"  disagreeing: off the truth (online | batch)  undetermined: seed (batch's wide parameters; "
             f"online quality; off the truth online | batch)  divergent windows  max ratio (away / after change)"]
    for fam, rows in doc["records"].items():
        m = family_summary(rows)
        floor = [r for r in rows if determined(r)]
        off = [(r["seed"], truth_errors(r)) for r in floor if not r.get("agrees")]
        diff = " ".join("-" if v is None else f"{100 * v:.2g}%" for v in m["max_rel_diff_determined"].values())
        agree = "-" if m["agree_determined"] is None else f"{m['agree_determined']:.2f}"
        worst = "; ".join(f"{seed}: {','.join(e['online']) or 'none'} | {','.join(e['batch']) or 'none'}"
                          for seed, e in off)
        wide = "; ".join(f"{u['seed']} ({','.join(u['batch_undetermined'])}; {u['online_quality']}; "
                         f"{','.join(u['off_truth']['online']) or 'none'} | {','.join(u['off_truth']['batch']) or 'none'})"
                         for u in m["undetermined"])
        away, after = m.get("max_ratio_away_from_change"), m.get("max_ratio_after_change")
        lines.append(f"{fam:14s} {m['records']:7d} {m['at_batch_floor']:8d} {m['determined']:7d} {agree:>6s} "
                     f"{diff:>48s}  {worst or '-'}  {wide or '-'}  "
                     f"{sum(r.get('divergent_windows', 0) for r in rows)}  "
                     f"{'-' if away is None else f'{away:.3g}'} / {'-' if after is None else f'{after:.3g}'}")
    return "\n".join(lines)


def markdown(docs: list[dict]) -> str:
    """The docs table of results documents (one per SNR): per family and SNR, the records, those ``identify`` fits
    at the noise floor, those of them that determine the plant (``determined``), those of these where online and
    batch agree, and the records with a divergent window."""
    snrs = [d["config"]["snr_db"] for d in docs]
    head = "| family | " + " | ".join(f"{s:g} dB: records, at floor, determined, agree, diverged" for s in snrs) + " |"
    lines = [head, "|---|" + "---|" * len(docs)]
    families = list(dict.fromkeys(f for d in docs for f in d["summary"]))
    for fam in families:
        cells = []
        for d in docs:
            if fam not in d["records"]:
                cells.append("not run")
                continue
            m = family_summary(d["records"][fam])
            agree = sum(r["agrees"] for r in d["records"][fam] if determined(r))
            cells.append(f"{m['records']}, {m['at_batch_floor']}, {m['determined']}, {agree}, {m['divergent_records']}")
        lines.append(f"| {fam.replace('_', ' ')} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def real_records() -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """(name, t, u, y) of every uniformly sampled record in tests/data/real (its t, u, y columns: the SISO view)."""
    import gzip
    out = []
    for path in sorted((ROOT / "tests" / "data" / "real").glob("*/*.csv*")):
        opener = gzip.open if path.suffix == ".gz" else open
        with opener(path, "rt") as f:
            names = f.readline().strip().split(",")
            data = np.loadtxt(f, delimiter=",")
        t = data[:, 0]
        dt = np.diff(t)
        if not (dt.size and np.all(dt > 0) and np.ptp(dt) <= 1e-3 * np.mean(dt)):
            print(f"{path.name}: time not uniform, left out", file=sys.stderr)
            continue
        out.append((f"{path.parent.name}/{path.name}", t, data[:, names.index("u")], data[:, names.index("y")]))
    return out


def real_main(out: Path) -> dict:
    rows = []
    for name, t, u, y in real_records():
        h = float(np.mean(np.diff(t)))
        est, err = live_run(h, u, y)
        windows = window_ratios(err, y, h)
        e = est.estimate
        rows.append({"record": name, "samples": int(u.size), "quality": e.quality, "start": e.start,
                     **divergence(windows), "windows": windows})
        print(f"{name}: max window ratio {rows[-1]['max_window_ratio']}, divergent windows "
              f"{rows[-1]['divergent_windows']}, {e.quality}, start {e.start}", file=sys.stderr, flush=True)
    ratios = [r["max_window_ratio"] for r in rows if r["max_window_ratio"] is not None]
    doc = {"command": command_line(), "records": rows, "max_window_ratio": max(ratios),
           "divergent_records": sum(r["divergent_windows"] > 0 for r in rows)}
    write_report(doc, out, default=str, echo=False)
    return doc


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--seed-offset", type=int, default=0)
    ap.add_argument("--snr-db", type=float, default=40.0)
    ap.add_argument("--families", default=None)
    ap.add_argument("--rest-samples", type=int, default=None)
    ap.add_argument("--real", action="store_true", help="the divergence check on tests/data/real instead")
    ap.add_argument("--table", nargs="+", default=None, metavar="JSON",
                    help="print the tables of results files (one per SNR) and the docs table, and exit")
    ap.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                    help="merge results files of one SNR into --out (its table printed) and exit")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.merge:
        doc = merge(args.merge, Path(args.out or results_path(f"online_vs_batch_{args.snr_db:g}db")))
        print(table(doc))
        return doc
    if args.table:
        docs = [json.loads(Path(p).read_text()) for p in args.table]
        print("\n\n".join(table(d) for d in docs) + "\n\n" + markdown(docs))
        return {}
    if args.real:
        doc = real_main(Path(args.out or results_path("online_divergence_real")))
        print(json.dumps({k: v for k, v in doc.items() if k != "records"}, indent=1))
        return doc
    from hil_sim import scenarios
    from bench.bench_online_scenarios import estimator_window_s
    scenarios.SNR_DB = args.snr_db
    families = args.families.split(",") if args.families else list(scenarios.FAMILIES)
    if args.rest_samples is not None:
        families = [f for f in families if f in scenarios.FROM_REST]
    window_s = estimator_window_s()
    start = time.perf_counter()
    rest = "" if args.rest_samples is None else f"_rest{args.rest_samples}"
    out = Path(args.out or results_path(f"online_vs_batch_{args.snr_db:g}db{rest}"))
    config = {"plants": args.plants, "seed_offset": args.seed_offset, "snr_db": args.snr_db,
              "rest_samples": args.rest_samples, "tolerances": TOL, "window_s": WINDOW_S}
    rows: dict[str, list] = {}
    for fam in families:
        for seed in range(args.seed_offset, args.seed_offset + args.plants):
            row = scenario_row(scenarios.make(fam, seed, args.rest_samples), window_s)
            rows.setdefault(fam, []).append(row)
            b = row["batch"]
            print(f"{fam} {seed}: batch floor {b.get('floor_ratio', float('nan')):.2f} agrees {row.get('agrees')} "
                  f"window ratio {row['max_window_ratio']} divergent {row['divergent_windows']} {row['quality']} "
                  f"{row['elapsed_s']:.1f} s", file=sys.stderr, flush=True)
            doc = results_doc(config, rows, time.perf_counter() - start)
            write_report(doc, out, default=str, echo=False)  # after every record: a stopped run keeps its rows
    print(json.dumps(doc["summary"], indent=1, default=str))
    return doc


def results_doc(config: dict, rows: dict[str, list], elapsed_s: float) -> dict:
    """The results document of ``rows`` (per family, the records so far)."""
    return {"command": command_line(), "config": config,
            "summary": {fam: family_summary(r) for fam, r in rows.items()}, "records": rows, "elapsed_s": elapsed_s}


def merge(paths: list[str], out: Path) -> dict:
    """One results document of several runs at the same SNR (one family each, say): their records per family."""
    docs = [json.loads(Path(p).read_text()) for p in paths]
    snrs = {d["config"]["snr_db"] for d in docs}
    if len(snrs) != 1:
        raise SystemExit(f"merge: runs at different SNRs {sorted(snrs)}")
    rows: dict[str, list] = {}
    for d in docs:
        for fam, r in d["records"].items():
            rows.setdefault(fam, []).extend(r)
    config = {**docs[0]["config"], "plants": None, "seed_offset": None,
              "runs": [d["run"]["command"] if "run" in d else d["command"] for d in docs]}
    doc = results_doc(config, rows, sum(d.get("elapsed_s", 0.0) for d in docs))
    doc["command"] = "python -m bench.bench_online_batch --merge " + " ".join(paths) + f" --out {out}"
    write_report(doc, out, default=str, echo=False)
    return doc


if __name__ == "__main__":
    main()
