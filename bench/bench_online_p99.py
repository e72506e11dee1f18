"""Where update()'s p99 comes from: each call's own CPU time, labelled by the work it ran, for this tree and a
baseline revision in the same run.

Usage (from the repository root)::

    .venv/bin/python -m bench.bench_online_p99 --baseline REV [--in-operation-s 10.05] [--seconds 100] [--runs 5]
        [--out bench/results/online_p99_sources.json]

The stream is ``bench_online.make_stream`` (10 kHz, a payload and a stiffness change), cut in operation as in
``bench_online_repeatable.py``. Per estimator: ``runs`` timed runs (own CPU time, ``time.thread_time_ns``; the
minimum over the runs per call removes the machine's share, as there) and one more run that labels each call
by the work it ran: ``plain`` (the tracker's sample only), ``machine`` (a re-fit or change-test slice in the
kernel), the name of the tracker's job the call visited (the outermost generator: ``_refit_job``,
``_change_job``, ``_research_job``, ...), or ``startup:<phase>`` before the tracker runs; a call that queued a
job or started a machine is labelled ``plain -> <job>``. The estimator is deterministic, so the labelled run
does the timed runs' work call by call.

Reported per label: calls, calls over 5 us, and the minimum series' p50/p99/max there; and the composition of
the slowest 1 % of calls (those at or above the p99), which is what the p99 is made of: a p99 moves when the
number of calls that run a job crosses 1 % of all calls, even if no call got slower.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from bench._baseline import extract, run_python
from bench.bench_online import H, make_stream
from bench.harness import results_path, write_report

#: The measurement, as source: run in this process for the worktree's code and in a subprocess (the baseline's
#: package first on sys.path) for ``--baseline``; it uses only ``OnlineEstimator(dt)``, ``update`` and the
#: tracker's ``_jobs`` and ``machine`` (present in both).
MEASURE = '''
def label(est):
    """The work the estimator is in between two calls (module docstring)."""
    tr = est._live
    if tr is None:
        return "startup:" + est.phase
    if getattr(tr, "machine", None) is not None:
        return "machine"
    jobs = getattr(tr, "_jobs", None)
    if not jobs:
        return "plain"
    return jobs[0].gi_code.co_name


def timed_and_labelled(u, y, runs, h):
    """(runs x calls own CPU us, labels per call)."""
    import gc
    import time
    import numpy as np
    from creep_online.online.estimator import OnlineEstimator, warm_kernels
    warm_kernels()
    cpu = np.empty((runs, len(u)))
    for r in range(runs):
        gc.collect()
        gc.freeze()
        est = OnlineEstimator(h)
        update, clock = est.update, time.thread_time_ns
        row = cpu[r]
        for k in range(len(u)):
            c0 = clock()
            update(u[k], y[k])
            row[k] = clock() - c0
        gc.unfreeze()
    est = OnlineEstimator(h)
    labels = []
    for k in range(len(u)):
        before = label(est)
        est.update(u[k], y[k])
        after = label(est)
        labels.append(before if after == before or before != "plain" else f"plain -> {after}")
    return cpu / 1e3, labels
'''

WORKER = MEASURE + '''
import json, sys
import numpy as np
with np.load(sys.argv[1]) as z:
    u, y = z["u"].tolist(), z["y"].tolist()
cpu, labels = timed_and_labelled(u, y, int(sys.argv[3]), float(sys.argv[2]))
np.save(sys.argv[4], cpu)
with open(sys.argv[5], "w") as f:
    json.dump(labels, f)
'''


def breakdown(cpu: np.ndarray, labels: list[str]) -> dict:
    """The minimum series over the runs, per label and in the slowest 1 % (module docstring)."""
    low = cpu.min(axis=0)
    lab = np.asarray(labels)
    p99 = float(np.percentile(low, 99))
    top = low >= p99
    per_label = {}
    for name in sorted(set(labels), key=lambda s: -int(np.count_nonzero(lab == s))):
        sel = lab == name
        x = low[sel]
        per_label[name] = {"calls": int(sel.sum()), "over_5us": int(np.count_nonzero(x > 5.0)),
                           "in_top_1pct": int(np.count_nonzero(top & sel)),
                           "p50_us": float(np.median(x)), "p99_us": float(np.percentile(x, 99)),
                           "max_us": float(x.max())}
    return {"calls": int(low.size), "p50_us": float(np.median(low)), "p99_us": p99, "max_us": float(low.max()),
            "over_5us": int(np.count_nonzero(low > 5.0)), "non_plain_calls": int(np.count_nonzero(lab != "plain")),
            "per_run_p99_us": [float(np.percentile(r, 99)) for r in cpu], "per_label": per_label}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="git revision measured the same way (a subprocess)")
    ap.add_argument("--in-operation-s", type=float, default=10.05)
    ap.add_argument("--seconds", type=float, default=100.0)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", default=str(results_path("online_p99_sources")))
    args = ap.parse_args(argv)
    stream = make_stream(args.seconds, in_operation_s=args.in_operation_s)
    u, y = stream["u"].tolist(), stream["y"].tolist()
    namespace: dict = {}
    exec(MEASURE, namespace)
    cpu, labels = namespace["timed_and_labelled"](u, y, args.runs, H)
    doc = {"stream": {"seconds": args.seconds, "in_operation_s": args.in_operation_s, "fs_hz": 1 / H},
           "runs": args.runs, "worktree": breakdown(cpu, labels)}
    path, commit = extract(args.baseline)
    data = os.path.join(path, "stream.npz")
    np.savez(data, u=stream["u"], y=stream["y"])
    times, names = os.path.join(path, "cpu.npy"), os.path.join(path, "labels.json")
    run_python(path, WORKER, data, repr(H), str(args.runs), times, names)
    doc["baseline"] = {"revision": commit, **breakdown(np.load(times), json.loads(open(names).read()))}
    print(f"[p99] worktree p99 {doc['worktree']['p99_us']:.2f} us, baseline {doc['baseline']['p99_us']:.2f} us",
          file=sys.stderr)
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
