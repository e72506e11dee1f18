"""Where update()'s slow calls come from: the latency stream's calls labelled by the background work they ran.

Usage (from the repository root)::

    .venv/bin/python -m bench.bench_online_sites [--in-operation-s 10.05] [--seconds 100] [--runs 3]
        [--threshold 25] [--out bench/results/online_sites.json]

``bench_online.py`` measures update()'s own CPU time (``time.thread_time_ns``) over the latency stream
(``bench_online.make_stream``: 10^6 samples at 10 kHz, a payload and a stiffness change) and reports its
distribution; this bench says which work the calls over ``--threshold`` did, so that work can be sliced.
Each call gets a *site*: where the estimator was before it and where it stopped after it. Before the
tracker runs: ``startup:<phase>``. After: ``plain`` (a sample and no background work), ``machine`` (a sample
and a slice of the re-fit or change test inside the per-sample kernel), or the queue head's job as its
generators' chain of ``function:line`` (e.g. ``_research_job:975/_run_search:1010``; a search's own chain in
brackets), before -> after.
Reading the chain's frames costs ~1 us per call outside the timed region: the timed calls run colder
than in ``bench_online.py``, so read the counts per site against each other and across runs, not
against that bench's totals.

The machine's own share: the same timers around nothing, as many calls as the stream has (``empty``): a
call over the threshold there is the machine (interrupts, the other core), not the estimator. Such events
come per second of timed code, so ``expected_from_machine`` scales the empty loop's count by the seconds
the update() calls took against the empty calls' (a plain update() is ~3x an empty call). Per run:
per site the calls, p50, p90, max and the calls over 5 us and over the threshold, sorted by the latter;
over ``--runs`` runs the per-site counts over the threshold side by side (the machine moves them).
Prints one JSON document and writes it to ``--out``.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from bench.bench_online import H, make_stream  # noqa: E402
from bench.harness import results_path, write_report  # noqa: E402

#: Sites listed per run (the most calls over the threshold first).
TOP_SITES = 25


def site(est) -> str:
    """Where the estimator is between two calls (see the module docstring)."""
    tr = est._live
    if tr is None:
        startup = est._startup
        search, starting = startup.search, startup.starting
        inner = ""
        if starting is not None:
            inner = f"[{_chain(starting)}]"
        elif est.phase == "tracking" and est._tracker is not None:   # the buffer's catch-up, the tracker's own jobs
            tr = est._tracker
            inner = "[first fit]" if tr.fitting else "[catch-up]"
            if tr._jobs:
                inner += f"[{_chain(tr._jobs[0])}]"
            elif tr.machine is not None:
                inner += "[machine]"
        elif est.phase == "searching" and search is not None:
            inner = f"[{_chain(search._gen)}]"
        return "startup:" + est.phase + inner
    if tr.machine is not None:
        return "machine"
    if not tr._jobs:
        return "plain"
    return _chain(tr._jobs[0])


def _chain(g) -> str:
    """A generator's chain of ``function:line`` (``yield from``), a search's own chain in brackets."""
    chain = []
    while g is not None and hasattr(g, "gi_code"):
        frame = g.gi_frame
        chain.append(f"{g.gi_code.co_name}:{frame.f_lineno if frame is not None else 'end'}")
        search = frame.f_locals.get("search") if frame is not None and g.gi_code.co_name == "_run_search" else None
        if search is not None:
            chain.append(f"[{_chain(search._gen)}]")
        g = g.gi_yieldfrom
    return "/".join(chain)


def labelled_run(u: list, y: list, threshold: float) -> dict:
    """One estimator over the stream: each call's own CPU time and its site (before -> after)."""
    from creep_online.online.estimator import OnlineEstimator
    est = OnlineEstimator(H)
    gc.collect()
    gc.freeze()
    clock = time.thread_time_ns
    n = len(u)
    cpu = np.empty(n)
    # the sites as codes in an array: a Python list of 10^6 labels is traversed by every garbage collection that
    # reaches its generation, and that collection runs inside the update() that triggers it (0.6-3 ms)
    codes = np.empty(n, dtype=np.int64)
    names: dict[str, int] = {}
    for k in range(n):
        before = site(est)
        c0 = clock()
        est.update(u[k], y[k])
        c1 = clock()
        cpu[k] = (c1 - c0) / 1e3
        after = site(est)
        label = before if after == before else f"{before} -> {after}"
        codes[k] = names.setdefault(label, len(names))
    gc.unfreeze()
    by_site: dict[str, list[float]] = defaultdict(list)
    label_of = {code: label for label, code in names.items()}
    for k in range(n):
        by_site[label_of[int(codes[k])]].append(cpu[k])
    rows = []
    for name, values in by_site.items():
        v = np.asarray(values)
        rows.append({"site": name, "calls": int(v.size), "p50_us": float(np.median(v)),
                     "p90_us": float(np.percentile(v, 90)), "max_us": float(v.max()),
                     "over_5us": int(np.count_nonzero(v > 5.0)), "over_threshold": int(np.count_nonzero(v > threshold))})
    rows.sort(key=lambda r: (-r["over_threshold"], -r["over_5us"]))
    e = est.estimate
    return {"p50_us": float(np.median(cpu)), "p99_us": float(np.percentile(cpu, 99)), "max_us": float(cpu.max()),
            "over_5us": int(np.count_nonzero(cpu > 5.0)), "over_threshold": int(np.count_nonzero(cpu > threshold)),
            "timed_s": float(cpu.sum() / 1e6), "sites": rows[:TOP_SITES], "other_sites_over_threshold": sum(r["over_threshold"] for r in rows[TOP_SITES:]),
            "final": {"alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b, "quality": e.quality}}


def empty_run(n: int, threshold: float) -> dict:
    """The timers around nothing, n times: the calls over the threshold the machine alone makes."""
    clock = time.thread_time_ns
    cpu = np.empty(n)
    for k in range(n):
        c0 = clock()
        c1 = clock()
        cpu[k] = (c1 - c0) / 1e3
    return {"max_us": float(cpu.max()), "over_threshold": int(np.count_nonzero(cpu > threshold)),
            "timed_s": float(cpu.sum() / 1e6)}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--in-operation-s", type=float, default=10.05,
                    help="cut the stream this many seconds into the operation (0: from rest)")
    ap.add_argument("--seconds", type=float, default=100.0)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--threshold", type=float, default=25.0, help="us of own CPU time (issue 8's max)")
    ap.add_argument("--out", default=str(results_path("online_sites")))
    args = ap.parse_args(argv)
    from creep_online.online.estimator import warm_kernels
    s = make_stream(args.seconds, in_operation_s=args.in_operation_s)
    u, y = s["u"].tolist(), s["y"].tolist()
    warm_kernels()
    runs = []
    for r in range(args.runs):
        run = labelled_run(u, y, args.threshold)
        empty = run["empty"] = empty_run(len(u), args.threshold)
        # the machine's events come per second of timed code, not per call: the empty loop's rate over the
        # seconds the update() calls took
        run["expected_from_machine"] = empty["over_threshold"] * run["timed_s"] / max(empty["timed_s"], 1e-9)
        runs.append(run)
        print(f"[sites] run {r}: {run['over_threshold']} calls over {args.threshold:g} us "
              f"(the machine's own rate over the same time: {run['expected_from_machine']:.0f}), "
              f"max {run['max_us']:.0f} us", file=sys.stderr)
    names = [row["site"] for row in runs[0]["sites"]]
    across = {name: [next((row["over_threshold"] for row in run["sites"] if row["site"] == name), None)
                     for run in runs] for name in names}
    doc = {"command": "python " + " ".join([Path(sys.argv[0]).name] + (argv if argv is not None else sys.argv[1:])),
           "stream": {"seconds": args.seconds, "in_operation_s": args.in_operation_s, "fs_hz": 1 / H},
           "threshold_us": args.threshold, "machine": {"cpu_count": os.cpu_count(), "loadavg": os.getloadavg()},
           "over_threshold_by_site_across_runs": across, "runs": runs}
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
