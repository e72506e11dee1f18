"""update()'s repeatable work: the per-call minimum of its own CPU time over several runs of the latency stream.

Usage (from the repository root)::

    .venv/bin/python -m bench.bench_online_repeatable [--in-operation-s 10.05] [--seconds 100] [--runs 5]
        [--baseline REV] [--threshold 25] [--out bench/results/online_repeatable.json]

``bench_online.py`` times each update() of the latency stream (``bench_online.make_stream``: 10^6 samples at
10 kHz, a payload and a stiffness change) once; its maximum is the estimator's slowest call *plus* whatever
the machine did to that call (an interrupt, a page of the other process's cache traffic): on this shared
machine a loop around nothing has calls over 25 us of its own CPU time, so one run cannot show whether a slow
call was the estimator's work. The estimator is deterministic: run k of the stream does the same work at
call i as run j. The minimum over the runs of call i's time is that work with the machine's share removed
(an interrupt hits a given call in every one of R runs with probability ~(1e-4)^R), cold caches included:
a call whose work is cold code or cold data is slow in every run. That series' maximum is what issue 8's
"no single update() above 25 us" asks of the estimator itself; the single runs' maxima are reported beside it.
The loop is the docs' (the estimator built, then ``gc.freeze()``). The garbage collector's passes are the
interpreter's, not the estimator's work, but they land on the same calls in every run: the calls during which it
ran (in every run) are listed and the series is summarised with and without them.

Per estimator (the worktree's, and ``--baseline``'s from ``git archive`` in a subprocess), for the own CPU time
(``time.thread_time_ns``) and, beside it, the wall time (``perf_counter_ns``: preemption included, which the
minimum over runs removes as it removes interrupts): the minimum series' p50, p90, p99, max and its calls over
5, 15 and the threshold; each run's own max, p99 and calls over the threshold. For the worktree's code the calls of the minimum series over the threshold are labelled by the work
they ran (``bench_online_sites.site``, one more run with the labels). Prints one JSON document and writes it
to ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from bench._baseline import extract, run_python  # noqa: E402
from bench.bench_online import H, make_stream  # noqa: E402
from bench.bench_online_sites import site  # noqa: E402
from bench.harness import results_path, write_report  # noqa: E402

#: The measurement, as source: it runs in this process for the worktree's code and in a subprocess (the
#: baseline's package first on sys.path) for ``--baseline``; only ``OnlineEstimator(dt)`` and ``update`` are used.
MEASURE = '''
def per_call_us(u, y, runs):
    """Each run: a fresh estimator fed the stream sample by sample as the docs' loop does (built, then
    ``gc.freeze()``), update()'s own CPU time and wall time per call (us; rows 0 and 1 of each run's array) and
    the calls during which the garbage collector ran (row 2: 1)."""
    import gc
    import time
    import numpy as np
    from creep_online.online.estimator import OnlineEstimator, warm_kernels
    warm_kernels()
    out = []
    at, hits = [0], []
    def collecting(phase, info):           # (a list append: a numpy store here, cold, was ~100 us in the pass)
        if phase == "start":
            hits.append(at[0])
    for _ in range(runs):
        # the collection first: it walks every object of the process and leaves the caches cold for whatever
        # runs next; after the construction, that was the estimator's first update() (20-28 us), which a loop
        # that builds its estimator and then runs does not see
        gc.collect()
        est = OnlineEstimator(H)
        gc.freeze()
        times = np.zeros((3, len(u)), dtype=np.int64)
        cpu, wall = times[0], times[1]
        hits.clear()
        update, cpu_clock, wall_clock = est.update, time.thread_time_ns, time.perf_counter_ns
        gc.callbacks.append(collecting)
        for k in range(len(u)):
            at[0] = k
            w0 = wall_clock()
            c0 = cpu_clock()
            update(u[k], y[k])
            c1 = cpu_clock()
            w1 = wall_clock()
            cpu[k] = c1 - c0
            wall[k] = w1 - w0
        gc.callbacks.remove(collecting)
        times[2, hits] = 1
        gc.unfreeze()
        e = est.estimate
        times = times.astype(float)
        times[:2] /= 1e3
        out.append((times, {"alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b, "quality": e.quality}))
    return out
'''

WORKER = MEASURE + '''
import json, sys
import numpy as np
H = float(sys.argv[2])
with np.load(sys.argv[1]) as z:
    u, y = z["u"].tolist(), z["y"].tolist()
runs = per_call_us(u, y, int(sys.argv[3]))
np.save(sys.argv[4], np.stack([r[0] for r in runs]))
print(json.dumps([r[1] for r in runs]))
'''


def summary(series: np.ndarray, threshold: float) -> dict:
    """Distribution of one per-call series (us)."""
    return {"p50_us": float(np.median(series)), "p90_us": float(np.percentile(series, 90)),
            "p99_us": float(np.percentile(series, 99)), "max_us": float(series.max()),
            "over_5us": int(np.count_nonzero(series > 5.0)), "over_15us": int(np.count_nonzero(series > 15.0)),
            "over_threshold": int(np.count_nonzero(series > threshold))}


def report(times: np.ndarray, finals: list, threshold: float) -> dict:
    """The minimum series over the runs (``times``: run x [cpu, wall, collector ran] x call) and each run's own
    figures, for the own CPU time and the wall time. The collector's passes land on the same calls in every run
    (the estimator allocates alike), so the minimum keeps them: the series is also summarised without the calls
    in which it ran in every run, and those calls are listed."""
    low = times[:, :2].min(axis=0)
    collected = times[:, 2].min(axis=0) > 0
    out = {}
    for i, clock in enumerate(("cpu", "wall")):
        out[f"{clock}_min_over_runs"] = summary(low[i], threshold)
        out[f"{clock}_min_over_runs_without_collector"] = summary(low[i][~collected], threshold)
        out[f"{clock}_runs"] = [{"max_us": float(r.max()), "p99_us": float(np.percentile(r, 99)),
                                 "over_threshold": int(np.count_nonzero(r > threshold))} for r in times[:, i]]
    out["collector_calls"] = [{"k": int(k), "cpu_us": round(float(low[0][k]), 1)} for k in np.flatnonzero(collected)]
    return {**out, "final": finals[-1], "_low": low[0]}


def labelled(u: list, y: list, calls: np.ndarray) -> dict[int, str]:
    """The work each of ``calls`` ran (``site`` before -> after), from one more run of the worktree's code."""
    from creep_online.online.estimator import OnlineEstimator
    est = OnlineEstimator(H)
    want, out = set(int(k) for k in calls), {}
    for k in range(len(u)):
        if k in want:
            before = site(est)
            est.update(u[k], y[k])
            after = site(est)
            out[k] = before if after == before else f"{before} -> {after}"
        else:
            est.update(u[k], y[k])
    return out


def baseline_run(rev: str, stream: dict, runs: int) -> tuple[np.ndarray, list, str]:
    """The per-call times of ``rev``'s estimator (a subprocess on its ``git archive``): run x [cpu, wall] x call."""
    path, commit = extract(rev)
    data = os.path.join(path, "stream.npz")
    np.savez(data, u=stream["u"], y=stream["y"])
    times = os.path.join(path, "cpu.npy")
    finals = json.loads(run_python(path, WORKER, data, repr(H), str(runs), times).strip().splitlines()[-1])
    return np.load(times), finals, commit


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--in-operation-s", type=float, default=10.05,
                    help="cut the stream this many seconds into the operation (0: from rest)")
    ap.add_argument("--seconds", type=float, default=100.0)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--baseline", default=None, help="git revision measured the same way (a subprocess)")
    ap.add_argument("--threshold", type=float, default=25.0, help="us of own CPU time (issue 8's max)")
    ap.add_argument("--out", default=str(results_path("online_repeatable")))
    args = ap.parse_args(argv)
    stream = make_stream(args.seconds, in_operation_s=args.in_operation_s)
    u, y = stream["u"].tolist(), stream["y"].tolist()
    namespace = {"H": H}
    exec(MEASURE, namespace)
    results = namespace["per_call_us"](u, y, args.runs)
    current = report(np.stack([r[0] for r in results]), [r[1] for r in results], args.threshold)
    low = current.pop("_low")
    slow = np.flatnonzero(low > args.threshold)
    labels = labelled(u, y, slow)
    current["over_threshold_calls"] = [{"k": int(k), "t_s": round(float(k) * H, 4), "cpu_us": round(float(low[k]), 1),
                                        "site": labels[int(k)]} for k in slow[np.argsort(low[slow])[::-1]]]
    print(f"[repeatable] worktree: max {current['cpu_min_over_runs']['max_us']:.1f} us "
          f"({current['cpu_min_over_runs_without_collector']['max_us']:.1f} without the collector's "
          f"{len(current['collector_calls'])} calls), {len(slow)} calls over {args.threshold:g} us", file=sys.stderr)
    doc = {"command": "python " + " ".join([Path(sys.argv[0]).name] + (argv if argv is not None else sys.argv[1:])),
           "stream": {"seconds": args.seconds, "in_operation_s": args.in_operation_s, "fs_hz": 1 / H},
           "runs": args.runs, "threshold_us": args.threshold,
           "machine": {"cpu_count": os.cpu_count(), "loadavg": os.getloadavg()}, "worktree": current}
    if args.baseline:
        times, finals, commit = baseline_run(args.baseline, stream, args.runs)
        base = report(times, finals, args.threshold)
        base.pop("_low")
        base["revision"] = commit
        doc["baseline"] = base
        cur, old = current["cpu_min_over_runs"], base["cpu_min_over_runs"]
        doc["ratio_to_baseline"] = {k: cur[k] / old[k] if old[k] else None
                                    for k in ("p50_us", "p99_us", "max_us", "over_5us", "over_15us", "over_threshold")}
        print(f"[repeatable] baseline {commit[:7]}: max {old['max_us']:.1f} us "
              f"({base['cpu_min_over_runs_without_collector']['max_us']:.1f} without the collector's "
              f"{len(base['collector_calls'])} calls), {old['over_threshold']} calls over {args.threshold:g} us",
              file=sys.stderr)
    write_report(doc, args.out)
    return doc


if __name__ == "__main__":
    main()
