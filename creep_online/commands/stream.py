"""``creep-online stream --source SPEC``: run the online estimator on a recorded or live stream.

``csv:FILE`` is replayed sample by sample through ``OnlineEstimator.update``
as fast as it goes (``--block`` uses ``update_block``), timing every call;
``csv:FILE?realtime=1`` (any option) goes through the file's source instead.
Any other spec (``serial:PORT``, ``can:IFACE:CHANNEL``, ``canlog:FILE`` or a
plug-in's kind) is opened by ``creep_online.io.registry.open_source`` and fed
by ``creep_online.io.feed.FeedLoop``: sequence gaps reach the estimator as
lost samples (time advances, output unused), each ``update()`` is timed.
"""
from __future__ import annotations

import argparse
import importlib
import math
import os
import signal
import sys
import time
from typing import TYPE_CHECKING

import numpy as np

from .. import _signals
from ..errors import CreepOnlineError, DataError, TransportError
from ..io.csvfile import load_record
from ..record import check_amplitudes, check_time_and_output
from ..model import ONLINE_REFITS as REFITS
from ._common import (MAX_SECONDS, add_column_options, event_line, fraction, nonempty, print_json, research_lines,
                      seconds, whole)
from ._progress import for_command

if TYPE_CHECKING:
    from ..online import OnlineEstimator


#: How a stream ended -> exit code (interrupted: 128 + the signal). Every end after the first sample prints the
#: estimate and the counters.
END_CODES = {"end_of_stream": 0, "limit": 0, "link_lost": 4, "error": 5, "interrupted": 130}
EXIT_CODES_HELP = """exit codes (the estimate reached so far and the link counters are printed in every case
once samples have arrived):
  0    the stream ended: end of file / log, or --max-samples / --duration reached
  2    bad input or settings, the source could not be opened, or it ended before
       2 samples arrived (no estimate)
  4    the link was lost for good (reconnect=0, or past reconnect_timeout)
  5    an unrecoverable error while streaming (the message says which)
  130  interrupted (Ctrl-C)
  143  terminated (SIGTERM, what systemd, Docker and Kubernetes send)
  129  hung up (SIGHUP, the terminal closed)"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stream", help="run the online estimator on a stream (csv:FILE, serial:PORT, can:..., canlog:FILE, pi:PORT)",
                       description="Online identification of all four parameters: a global search over "
                                   "(alpha, fn, zeta) on the first samples, then a window fit that follows the "
                                   "plant, detects abrupt changes and gates outliers (docs/online.md). Prints the "
                                   "final estimate, its quality and the per-sample update() latency.",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", required=True, type=nonempty,
                   help="csv:FILE | serial:PORT | can:IFACE:CHANNEL | canlog:FILE | "
                        "pi:tcp:HOST[:PORT] | pi:usb:SERIAL | pi:[rs232:]PORT | "
                                                    "capancdt:HOST:PORT?command=FILE | "
                                                    "KIND:... of an installed plug-in (docs/transports.md)")
    p.add_argument("--json", action="store_true",
                   help="print JSON (alpha a1 a2 b samples latency_us{p50,p99,max} phase quality ...)")
    p.add_argument("--t-c", type=seconds, default=None, help="start-up search window after the first input change, s "
                                                            "(default: chosen from the data, at most 2 s)")
    p.add_argument("--alpha0", type=fraction, default=None, help="optional alpha hint added to the search grid "
                                                               "(default: none needed)")
    p.add_argument("--window", default=None,
                   help="forgetting time constant in s (default: the estimator's, 10 s); 'none' keeps everything")
    p.add_argument("--effects", default=None, metavar="NAME[,NAME]",
                   help="effects estimated with the creep (default: none): 'hysteresis' adds a Prandtl-Ishlinskii loop on "
                        "the input, its weights fitted on the same window (docs/online.md)")
    p.add_argument("--refit", choices=REFITS, default=None,
                   help="Remark 3's strategy: window re-fits over the forgetting window (default), recursive "
                        "carries on with the newest estimate (constant work per sample; docs/online.md)")
    p.add_argument("--trace", default=None, metavar="FILE", type=nonempty,
                   help="write the estimate's trajectory as CSV (t, alpha, a1, a2, b, fn_hz, zeta, quality, "
                        "reason, events, researches: the re-searches that replaced the resonance), every 10 ms "
                        "of stream time")
    p.add_argument("--dt", type=seconds, default=None, help="sampling step in s (live sources; default: from the stream), "
                                                            "or the sample time of a PI GCS file without SAMPLE_TIME")
    p.add_argument("--block", action="store_true", help="csv: feed the whole file with update_block (throughput)")
    add_column_options(p, time=False)
    p.add_argument("--max-samples", type=whole(1, 1 << 62), default=None, help="stop after this many samples")
    p.add_argument("--duration", type=seconds, default=None,
                   help="stop after this many seconds of wall time")
    p.set_defaults(func=run)


def _options(args: argparse.Namespace) -> dict:
    """Only the settings given on the command line: the defaults are the estimator's own (one set)."""
    opts: dict = {}
    if args.t_c is not None:
        opts["t_c"] = args.t_c
    if args.alpha0 is not None:
        opts["alpha0"] = args.alpha0
    if args.refit is not None:
        opts["refit"] = args.refit
    if args.effects is not None:
        opts["effects"] = tuple(name.strip() for name in str(args.effects).split(",") if name.strip())
    if args.window is not None:
        text = str(args.window).strip().lower()
        if text in ("none", "inf"):
            opts["window_s"] = None
        else:
            try:
                opts["window_s"] = seconds(text)
            except argparse.ArgumentTypeError:
                raise DataError(f"--window must be a time in seconds (> 0, at most {MAX_SECONDS:g}) or 'none', "
                                f"got {args.window[:40]!r}") from None
    return opts


class Trace:
    """The estimate's trajectory, one row per ``period`` seconds of stream time (``--trace FILE``)."""

    COLUMNS = ("t", "alpha", "a1", "a2", "b", "fn_hz", "zeta", "quality", "reason", "events", "researches")

    def __init__(self, path: str | None, dt: float, period: float = 0.01) -> None:
        self.path = path
        self.every = max(1, int(round(period / dt)))
        self.rows: list[tuple] = []

    def due(self, samples: int) -> bool:
        return self.path is not None and samples % self.every == 0

    def add(self, est: OnlineEstimator) -> None:
        e = est.estimate
        switched = [rs for rs in e.researches if rs["switched"]]
        self.rows.append((e.t, e.alpha, e.a1, e.a2, e.b, e.fn_hz, e.zeta, e.quality, e.reason, _marks(e.events),
                          _marks(switched)))

    def write(self) -> None:
        if self.path is None:
            return
        from ..io.safe_files import atomic_write
        with atomic_write(self.path) as f:
            f.write(",".join(self.COLUMNS) + "\n")
            for row in self.rows:
                f.write(",".join(_cell(v) for v in row) + "\n")


def _marks(items: list[dict]) -> str:
    """``t:moved`` of each change event or re-search (``t:fault:Error`` of an internal fault), ``;``-separated (a
    trace cell)."""
    return ";".join(f"{x['t']:.4g}:fault:{x['error']}" if x.get("kind") == "internal_fault" else
                    f"{x['t']:.4g}:{'+'.join(x['moved'])}" for x in items)


def _cell(v) -> str:
    """A trace cell: text quoted if needed, a number, or empty for a value not yet estimated (None)."""
    if v is None:
        return ""
    if isinstance(v, str):
        from ..io.safe_files import spreadsheet_text
        v = spreadsheet_text(v)
        return '"' + v.replace('"', "'") + '"' if ("," in v or '"' in v or "\n" in v) else v
    return repr(float(v))


#: How the estimator read the stream's start (``OnlineEstimate.start``), for the text report.
START_TEXT = {"rest": "at rest (first input 0)",
              "step": "a step from rest at the first sample (the input read as 0 before it)",
              "operation": "in operation (the plant moving from an unknown past input)"}


def _value(v: float | None, spec: str) -> str:
    """A value of the estimate as text: formatted, or "-" while it is not estimated (None)."""
    return "-" if v is None else format(v, spec)


def _latency(us: np.ndarray) -> dict:
    """p50/p99/max (+ mean, count over 1 ms) of per-sample update() time, given in microseconds."""
    if us.size == 0:
        return {"p50": 0.0, "p99": 0.0, "max": 0.0, "mean": 0.0, "over_1ms": 0}
    return {"p50": float(np.percentile(us, 50)), "p99": float(np.percentile(us, 99)), "max": float(us.max()),
            "mean": float(us.mean()), "over_1ms": int(np.count_nonzero(us > 1000.0))}


class AxisEstimators:
    """One estimator per axis of a multi-axis source, whose samples carry a tuple of values per axis.

    What the feed loop and the status line ask of an estimator: ``update``,
    ``gap`` (every axis loses the same samples), ``samples``, and the first
    axis's ``estimate`` and ``model`` for the status line.
    """

    def __init__(self, axes: tuple[str, ...], estimators: list[OnlineEstimator]) -> None:
        self.axes = axes
        self.estimators = estimators

    def update(self, u: tuple, y: tuple) -> None:
        for est, uk, yk in zip(self.estimators, u, y):
            est.update(uk, yk)

    def gap(self, n: int) -> None:
        for est in self.estimators:
            est.gap(n)

    @property
    def samples(self) -> int:
        return self.estimators[0].samples

    @property
    def estimate(self):
        return self.estimators[0].estimate

    @property
    def model(self):
        return self.estimators[0].model


def _report(est: OnlineEstimator, latency: dict, extra: dict) -> dict:
    e = est.estimate
    out = {"alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b, "samples": e.samples, "latency_us": latency,
           "phase": e.phase, "quality": e.quality, "reason": e.reason, "t_c": e.t_c, "fn_hz": e.fn_hz,
           "zeta": e.zeta, "offset": e.offset, "uncertainty": e.uncertainty, "skipped": est.skipped_nonfinite,
           "internal_faults": est.internal_faults, "gaps": est.gaps, "alpha_updates": est.alpha_updates,
           "divergences": est.divergences,
           "outliers": e.outliers, "input_outliers": e.input_outliers, "noise_rms": e.noise_rms,
           "residual_rms": e.residual_rms, "events": e.events, "t": e.t, "dt": est.dt,
           "b_rate": e.b_rate, "alpha_rate": e.alpha_rate, "researches": e.researches,
           "frozen": e.frozen, "start": e.start, "hysteresis": e.hysteresis}
    out.update(extra)
    return out


def run(args: argparse.Namespace) -> int:
    spec = args.source
    if args.max_samples is not None and args.max_samples < 1:
        raise DataError(f"--max-samples must be at least 1, got {args.max_samples}")
    if args.duration is not None and not args.duration > 0:
        raise DataError(f"--duration must be > 0 s, got {args.duration:g}")
    try:
        if spec.startswith("csv:") and not _has_options(spec[4:]):
            est, latency, extra = _run_csv(spec[4:], args)
        else:
            est, latency, extra = _run_live(spec, args)
    except KeyboardInterrupt as exc:        # stopped while opening or loading: say that there is no estimate yet
        if isinstance(exc, _signals.Interrupted) and exc.note:
            raise
        raise _signals.Interrupted(getattr(exc, "signum", signal.SIGINT),
                                   note="before the first sample arrived: no estimate yet") from None
    with _signals.deferred():    # the stream has ended: its report is printed whole, a signal now waits for it
        return _print_report(spec, args, est, latency, extra)


def _print_report(spec: str, args: argparse.Namespace, est: OnlineEstimator, latency: dict, extra: dict) -> int:
    """The estimate, the counters and how the stream ended (JSON or text); the exit code."""
    end = extra.setdefault("end", _end("end_of_stream"))
    per_axis = list(zip(est.axes, est.estimators)) if isinstance(est, AxisEstimators) else [(None, est)]
    out = _report(per_axis[0][1], latency, extra)
    if per_axis[0][0] is not None:           # several axes: the top-level keys are the first axis's
        out["axes"] = [{"axis": axis, **_report(e, latency, {})} for axis, e in per_axis]
    if end["message"]:
        print(f"creep-online stream: {end['reason'].replace('_', ' ')}: {end['message']}", file=sys.stderr)
    if args.json:
        print_json(out)
        return end["exit_code"]
    for axis, one in per_axis:
        _print_estimate(spec if axis is None else f"{spec} axis {axis}", one)
    if "throughput_sps" in extra:
        print(f"  block mode: {extra['throughput_sps']:.4g} samples/s")
    else:
        print(f"  update() latency: p50 {latency['p50']:.3g} us, p99 {latency['p99']:.3g} us, "
              f"max {latency['max']:.4g} us, {latency['over_1ms']} over 1 ms"
              + (f" (all {len(per_axis)} axes)" if len(per_axis) > 1 else ""))
    if "link" in extra:
        print(f"  link: {extra['link']}")
    print(f"  ended: {end['reason'].replace('_', ' ')} (exit {end['exit_code']})")
    return end["exit_code"]


def _print_estimate(spec: str, est: OnlineEstimator) -> None:
    """The estimate's lines of the text output."""
    e = est.estimate
    sd = e.uncertainty
    why = f" ({e.reason})" if e.reason else ""
    print(f"{spec}: {e.samples} samples ({e.t:.4g} s at dt = {est.dt:.4g} s), phase {e.phase}, quality {e.quality}{why}")
    for name in ("alpha", "a1", "a2", "b"):
        err = f"  +/- {sd[name]:.3g}" if name in sd and math.isfinite(sd[name]) else ""
        print(f"  {name:<6} = {_value(getattr(e, name), '.6g')}{err}")
    if e.start is not None:
        print(f"  start  : {START_TEXT.get(e.start, e.start)}" + ("; frozen (freeze())" if e.frozen else ""))
    print(f"  fn     = {_value(e.fn_hz, '.5g')} Hz, zeta = {_value(e.zeta, '.4g')}, t_c = {_value(e.t_c, '.4g')} s, "
          f"offset = {_value(e.offset, '.4g')}")
    if e.hysteresis is not None:
        print(f"  hysteresis: {len(e.hysteresis['w'])} play operators (thresholds {e.hysteresis['r'][0]:.4g} .. "
              f"{e.hysteresis['r'][-1]:.4g}), weights " + ", ".join(f"{w:.4g}" for w in e.hysteresis["w"]))
    print(f"  skipped {est.skipped_nonfinite} non-finite, {est.gaps} lost, {est.alpha_updates} window fits, "
          f"outliers gated: {e.outliers} output, {e.input_outliers} input, internal faults: {est.internal_faults}")
    for ev in e.events:
        print(f"  {event_line(ev)}")
    for line in research_lines(e.researches):
        print(f"  {line}")


def _run_csv(path: str, args: argparse.Namespace) -> tuple[OnlineEstimator, dict, dict]:
    from ..online import OnlineEstimator, warm_kernels   # numba and scipy: not for `stream --help`

    if not path:
        raise DataError("csv: missing file name after 'csv:'")
    if args.trace is not None:
        from ..io.safe_files import check_output
        check_output(args.trace, inputs=[path])
    rec = load_record(path, args.u_column, args.y_column, dt=args.dt)
    if not rec.is_uniform:
        raise DataError(f"{rec.source}: time is not uniformly sampled; the online estimator needs a fixed step")
    check_time_and_output(rec.t, rec.y, rec.source)     # the file is whole: what identify refuses, refused here
    check_amplitudes(rec.u, rec.y, rec.source)
    est = OnlineEstimator(rec.h, **_options(args))
    warm_kernels()                          # compile before the clock starts
    trace = Trace(args.trace, rec.h)
    n = rec.u.size if args.max_samples is None else min(rec.u.size, args.max_samples)
    u, y = rec.u[:n], rec.y[:n]
    deadline = math.inf if args.duration is None else time.monotonic() + args.duration
    with _signals.flagged() as stopped:     # a stop signal ends the loop between two samples, never inside one
        if args.block:
            k, elapsed = _feed_blocks(est, u, y, trace, stopped, deadline)
            extra = {"throughput_sps": k / max(elapsed, 1e-12), "file": rec.source}
            latency = _latency(np.empty(0))
        else:
            k, ns = _feed_samples(est, u, y, trace, stopped, deadline)
            extra = {"file": rec.source}
            latency = _latency(ns[:k] / 1e3)
        signum = stopped()
    trace.write()
    if signum is not None:
        extra["end"] = _end("interrupted", _signals.STOP_SIGNALS[signum], 128 + signum)
    elif k < rec.u.size:
        extra["end"] = _end("limit")
    return est, latency, extra


#: Samples between two looks at the stop signal and the deadline in the CSV replay.
CHECK_EVERY = 256


def _feed_samples(est: OnlineEstimator, u: np.ndarray, y: np.ndarray, trace: Trace, stopped, deadline: float):
    """update() sample by sample, each call timed; (samples fed, ns per call). Stops early on a stop signal or
    past the deadline (checked every CHECK_EVERY samples, outside the timed calls)."""
    ns = np.empty(u.size, dtype=np.int64)
    clock = time.perf_counter_ns
    update = est.update
    ul, yl = u.tolist(), y.tolist()
    k = 0
    while k < u.size:
        if stopped() is not None or time.monotonic() > deadline:
            break
        for k in range(k, min(k + CHECK_EVERY, u.size)):
            t0 = clock()
            update(ul[k], yl[k])
            ns[k] = clock() - t0
            if trace.due(k + 1):
                trace.add(est)
        k += 1
    return k, ns


def _feed_blocks(est: OnlineEstimator, u: np.ndarray, y: np.ndarray, trace: Trace, stopped, deadline: float):
    """update_block() over the file in slices (a trace row per slice when tracing); (samples fed, seconds)."""
    start = time.perf_counter()
    step = trace.every if trace.path else 1 << 16
    k = 0
    while k < u.size and stopped() is None and time.monotonic() <= deadline:
        est.update_block(u[k:k + step], y[k:k + step])
        k = min(k + step, u.size)
        if trace.path:
            trace.add(est)
    return k, time.perf_counter() - start


def _has_options(path: str) -> bool:
    """``FILE?key=value``: a CSV replayed through its source (e.g. ``?realtime=1``), unless FILE has a '?'."""
    return "?" in path and not os.path.exists(path)


def _column_options(spec: str, args: argparse.Namespace) -> dict:
    """--u-column/--y-column go to a file source (csv:FILE?...); a live stream has no named columns."""
    given = {k: v for k, v in (("u_column", args.u_column), ("y_column", args.y_column)) if v is not None}
    if given and not spec.lower().startswith("csv:"):
        raise DataError(f"{spec}: --u-column/--y-column choose columns of a file (csv:FILE); "
                        "a live source has no named columns")
    return given


def _end(reason: str, message: str = "", exit_code: int | None = None) -> dict:
    """How the stream ended, for the report and the exit code (``exit_code``: a stop signal's 128 + N)."""
    return {"reason": reason, "exit_code": END_CODES[reason] if exit_code is None else exit_code, "message": message}


def status_line(spec: str, loop) -> str:
    """The live status line of a stream on a terminal: samples, stream time, rate, phase, estimate, link trouble."""
    est = loop.estimator
    if est is None:
        return f"stream {spec}: waiting for samples"
    e = est.estimate
    wall = time.monotonic() - loop.started
    text = (f"stream {spec}: {loop.fed} samples, t = {e.t:.2f} s, {loop.fed / max(wall, 1e-9) / 1e3:.1f} kS/s, "
            f"{e.phase}/{e.quality}")
    if est.model is not None:
        text += f", alpha {e.alpha:.4g}, fn {e.fn_hz:.4g} Hz, zeta {e.zeta:.3g}, b {e.b:.4g}"
    if e.events:
        text += f", {len(e.events)} change(s)"
    if loop.lost:
        text += f", {loop.lost} lost"
    return text


def _run_live(spec: str, args: argparse.Namespace) -> tuple[OnlineEstimator, dict, dict]:
    from ..online import OnlineEstimator, warm_kernels

    try:
        registry = importlib.import_module("creep_online.io.registry")
        feed = importlib.import_module("creep_online.io.feed")
    except ModuleNotFoundError as exc:
        raise CreepOnlineError(f"{spec}: live sources are not available in this build ({exc.name} missing)") from None
    if args.trace is not None:
        from ..io.safe_files import check_output
        check_output(args.trace, inputs=registry.spec_files(spec))   # never over a file the source reads
    warm_kernels()                          # compile before the first sample arrives
    source = registry.open_source(spec, **_column_options(spec, args))
    trace = Trace(None, 1.0)
    options = _options(args)
    axes = tuple(getattr(source, "axes", None) or ())
    if len(axes) > 1 and args.trace is not None:
        source.close()
        raise DataError(f"{spec}: --trace follows one axis; stream one axis to trace it")

    def make_estimator(dt: float) -> OnlineEstimator | AxisEstimators:
        nonlocal trace
        trace = Trace(args.trace, dt)
        if len(axes) > 1:
            return AxisEstimators(axes, [OnlineEstimator(dt, **options) for _ in axes])
        return OnlineEstimator(dt, **options)

    def add_to_trace(loop, _sample) -> None:
        if trace.due(loop.estimator.samples):
            trace.add(loop.estimator)

    def enough(loop) -> bool:
        return stopped() is not None or (loop.estimator is not None and args.max_samples is not None
                                         and loop.estimator.samples >= args.max_samples)

    with _signals.flagged() as stopped, for_command(args.json) as progress:
        # a stop signal ends the feed between two batches
        progress.stage(f"stream {spec}: waiting for samples")
        loop = feed.FeedLoop(source, make_estimator, dt=args.dt, duration=args.duration, stop_when=enough,
                             on_sample=add_to_trace if args.trace is not None else None,
                             on_batch=lambda loop: progress.show(status_line(spec, loop)))
        try:
            end = loop.run()
        finally:
            source.close()
        signum = stopped()
    stats = getattr(source, "stats", None)
    trace.write()
    est = loop.estimator
    if signum is not None:
        end = feed.End("interrupted", _signals.STOP_SIGNALS[signum], _signals.Interrupted(signum))
    if est is None:
        if end.reason == "interrupted":
            signum = getattr(end.error, "signum", signal.SIGINT)
            raise _signals.Interrupted(signum, note="before the first sample arrived: no estimate yet")
        why = end.message or "fewer than 2 samples arrived; cannot tell the sampling step (use --dt)"
        raise (TransportError if end.reason == "link_lost" else DataError)(f"{spec}: no estimate: {why}")
    extra = {"source_stats": stats.as_dict() if stats is not None and hasattr(stats, "as_dict") else {},
             "end": _end(end.reason, end.message, end.exit_code)}
    if stats is not None and hasattr(stats, "summary"):
        extra["link"] = stats.summary()
    return est, _latency(loop.latency_us()), extra
