"""``creep-online demo``: the whole loop on the simulated plant, no hardware needed.

Starts ``python -m hil_sim`` in its own process (10 kHz, binary CRC frames over
a real pseudo-terminal), opens the port with pyserial here, runs the online
estimator on every sample and shows live progress (estimate, error against
the plant's true parameters, sample rate, latency). Ends with a summary and a
report (HTML + PNG plots when matplotlib is installed, JSON always) in
``--report DIR`` (default ``./creep_online_report/``).
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from ..errors import CreepOnlineError
from ..model import ONLINE_REFITS as REFITS
from ..reports.demo_report import plant_truth
from ._common import (MAX_HZ, event_line, finite_number, nonempty, positive_number, print_json, research_lines,
                      seconds, whole)
from ._progress import Progress

SCENARIOS = ("stationary", "payload", "drift")
#: The demo's limits: an hour of plant at up to 100 kHz, and a record between these many samples (the simulated
#: plant generates its record in memory; fewer samples than the minimum cannot show an identification).
DEMO_MAX_S = 3600.0
DEMO_MAX_RATE = 100_000.0
DEMO_SAMPLES = (1000, 50_000_000)
#: The payload scenario's added mass fraction (a2 *= 1 + PAYLOAD_MASS at half the duration).
PAYLOAD_MASS = 0.5
#: The drift scenario: alpha and b grow by these fractions over the run (temperature).
DRIFT = (0.2, 0.1)


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="stream the simulated plant over a pty and identify it live",
                              description=__doc__.splitlines()[0] + " Starts hil_sim at --rate over a real pty.")
    p.add_argument("--duration", type=positive_number(DEMO_MAX_S, "duration in s"), default=20.0, help="seconds of plant record to stream (default 20)")
    p.add_argument("--rate", type=positive_number(DEMO_MAX_RATE, "rate in Hz"), default=10_000.0, help="sample rate in Hz (default 10000)")
    p.add_argument("--transport", choices=("serial-binary", "serial-ascii"), default="serial-binary")
    p.add_argument("--params", default="", help="true plant alpha=..,fn=..,zeta=..,b=.. (default 0.12, 420 Hz, 0.08, 2.5)")
    p.add_argument("--schedule", default=None, help="input schedule: step, staircase, updown, square "
                                                     "(default: step; square for --scenario payload)")
    p.add_argument("--scenario", choices=SCENARIOS, default="stationary",
                   help="stationary: a constant plant; payload: half-way through, a payload adds 50 %% to the "
                        "moving mass (fn drops by 18 %%) while the input keeps stepping: watch the estimator "
                        "detect the change and follow it; drift: alpha +20 %% and b +10 %% over the run")
    p.add_argument("--compensate", action="store_true",
                   help="close the loop: a CreepCompensator turns a staircase reference into the plant's commands "
                        "(sent over the pty; hil_sim --command-input) and takes the live estimate (docs/compensation.md)")
    p.add_argument("--bandwidth", type=positive_number(MAX_HZ, "frequency in Hz"), default=None,
                   help="--compensate: reference filter corner in Hz (default: half the plant's natural frequency)")
    p.add_argument("--u-min", type=finite_number, default=None, help="--compensate: actuator range, lower end (default none)")
    p.add_argument("--u-max", type=finite_number, default=None, help="--compensate: actuator range, upper end (default none)")
    p.add_argument("--amplitude", type=finite_number, default=1.0, help="--compensate: reference staircase height (default 1)")
    p.add_argument("--period", type=seconds, default=None, help="--compensate: hold of each level in s (default 2)")
    p.add_argument("--refit", choices=REFITS, default=None,
                   help="the estimator's Remark-3 strategy: window (default) or recursive (docs/online.md)")
    p.add_argument("--effects", default="", help="hidden effects for the plant (see python -m hil_sim --help)")
    p.add_argument("--faults", default="", help="fault injection, e.g. drop=5,bitflip=5,garbage=5,reorder=3")
    p.add_argument("--seed", type=whole(0, 2**32 - 1), default=0)
    p.add_argument("--report", default="creep_online_report", type=nonempty, help="report folder (default ./creep_online_report)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON instead of text (no live progress)")
    p.add_argument("--quiet", action="store_true", help="no live progress")
    p.set_defaults(func=run)


def scenario_plan(name: str, plant: dict, duration: float, t_last: float) -> dict:
    """What the simulated plant does over the run (JSON-ready, ``reports.demo_report.plant_truth`` reads it):
    its parameters at the start, the abrupt changes (time, parameter factors, words) and any drift."""
    plan = {"name": name, "start": dict(plant), "changes": [], "drift": None, "t_last": t_last}
    if name == "payload":
        plan["changes"].append({"t": duration / 2, "factors": {"a2": 1.0 + PAYLOAD_MASS},
                                "what": f"payload: moving mass +{100 * PAYLOAD_MASS:.0f} %"})
    if name == "drift":
        plan["drift"] = {"alpha": DRIFT[0], "b": DRIFT[1]}
    return plan


def _errors(model, truth) -> dict:
    if model is None:
        return {}
    return {"alpha_abs": model.alpha - truth.alpha, "fn_rel": model.fn / truth.fn - 1,
            "zeta_rel": model.zeta / truth.zeta - 1, "b_rel": model.b / truth.b - 1}


def hardware_extras():
    """``open_source``, once the demo's extras (pyserial, hil_sim) import; a one-line error if they do not."""
    try:
        import hil_sim.harness  # noqa: F401
        from ..io import open_source
    except ImportError as exc:
        raise CreepOnlineError(f"demo needs the hardware extras ({exc.name} missing): "
                               "pip install 'creep_online[hardware]'") from None
    return open_source


def start_plant(plant_args: list[str], progress: Progress, what: str):
    """``hil_sim`` in its own process (``hil_sim.harness.PlantProcess``); a one-line error if it does not come up."""
    from hil_sim.harness import PlantProcess
    progress.show(f"demo: starting {what}...", force=True)
    try:
        return PlantProcess(plant_args)
    except RuntimeError as exc:
        raise CreepOnlineError(str(exc).splitlines()[0]) from None


def run(args: argparse.Namespace) -> int:
    from ..model import CreepModel
    from ..online import OnlineEstimator, warm_kernels
    open_source = hardware_extras()
    samples = args.duration * args.rate
    if not DEMO_SAMPLES[0] <= samples <= DEMO_SAMPLES[1]:
        raise CreepOnlineError(f"--duration x --rate gives {samples:.3g} samples; the demo needs "
                               f"{DEMO_SAMPLES[0]} to {DEMO_SAMPLES[1]:.0e}")
    out_dir = Path(args.report)
    from ..io.safe_files import check_report_dir
    check_report_dir(out_dir)   # before the run, not after it
    if args.compensate:
        return _run_compensated(args, out_dir)
    payload = args.scenario == "payload"
    schedule = args.schedule or ("square" if payload else "step")
    plant_args = ["--rate", repr(args.rate), "--duration", repr(args.duration), "--transport", args.transport,
                  "--schedule", schedule, "--t-start", "0.2", "--seed", str(args.seed), "--wait-start",
                  "--linger", "30"]
    if payload:
        plant_args += ["--payload", f"{args.duration / 2!r}:{PAYLOAD_MASS!r}"]
    if args.scenario == "drift":
        plant_args += ["--drift", f"alpha={DRIFT[0]!r},b={DRIFT[1]!r}"]
    for flag, value in (("--params", args.params), ("--effects", args.effects), ("--faults", args.faults)):
        if value:
            plant_args += [flag, value]
    progress = Progress(_live(args))
    plant = start_plant(plant_args, progress, f"the simulated plant (hil_sim, {args.rate:g} Hz, {args.transport})")
    with plant:
        ready = plant.ready
        n_total = int(ready["samples"])
        scenario = scenario_plan(args.scenario, ready["model"], args.duration, (n_total - 1) / args.rate)

        def truth(t: float) -> CreepModel:      # the plant valid at plant time t
            return CreepModel(**plant_truth(scenario, t))
        warm_kernels()
        est = OnlineEstimator(1.0 / args.rate, **({} if args.refit is None else {"refit": args.refit}))
        events: list[str] = []
        src = open_source(f"serial:{plant.port}?rate={args.rate!r}&start=S", on_event=events.append)
        start = plant.wait_event("start", timeout=60)
        t0 = float(start["t0_monotonic"])
        progress.show(f"demo: streaming from {plant.port} ({ready['tty']})", force=True)
        result = _stream(src, est, truth, n_total, args, t0, progress)
        progress.close()
        try:
            ledger = plant.wait_event("end", timeout=10)["ledger"]
        except (TimeoutError, RuntimeError):
            ledger = None
        src.close()
    result.update(port=plant.port, tty=ready["tty"], transport=args.transport, rate_hz=args.rate,
                  truth=truth(result["t_end"]).describe(), scenario=scenario, link_events=events, plant_ledger=ledger,
                  source_stats=src.stats.as_dict())
    from ..reports.demo_report import write_report
    result["report"] = write_report(out_dir, result)
    _print_summary(result, args.json)
    return 0


def _live(args: argparse.Namespace) -> bool:
    """Show the live line? Not with ``--quiet`` or ``--json`` (a script reads the JSON; issue 9 item 6). On a
    non-terminal otherwise it is one plain line every few seconds: the demo is watched, in CI logs too."""
    return not (args.quiet or args.json)


def _run_compensated(args: argparse.Namespace, out_dir: Path) -> int:
    """``--compensate``: the closed loop (``demo_compensate``), then the usual summary and report."""
    from .demo_compensate import print_compensation, run_compensated
    result = run_compensated(args, Progress(_live(args)))
    from ..reports.demo_report import write_report
    result["report"] = write_report(out_dir, result)
    _print_summary(result, args.json)
    if not args.json:
        print_compensation(result["compensation"])
    return 0


def _stream(src, est, truth, n_total: int, args, t0: float, progress: Progress, on_batch=None) -> dict:
    """Feed the plant's stream to the estimator; ``truth``: the plant (a CreepModel), or the plant valid at
    each plant time (a function of t), which the live line and the final errors are measured against."""
    from ..io.feed import FeedLoop, SampleAge
    dt = 1.0 / args.rate
    truth_at = truth if callable(truth) else (lambda _t: truth)
    trace: list[dict] = []
    next_trace = 0.0

    def show(loop: FeedLoop) -> None:
        nonlocal next_trace
        t_plant = loop.last_seq * dt
        if t_plant >= next_trace:
            e = est.estimate
            trace.append({"t": t_plant, "alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b,
                          "phase": e.phase, "quality": e.quality, "events": len(e.events),
                          "wall": time.monotonic() - loop.started})
            next_trace = t_plant + 0.1
        progress.show(_status(loop, truth_at((loop.last_seq or 0) * dt)))
        if on_batch is not None:        # --compensate: adapt and send the next commands
            on_batch(loop)

    loop = FeedLoop(src, lambda _dt: est, dt=dt, latency=SampleAge(t0, dt), read_timeout=0.05,
                    duration=args.duration * 3 + 60, on_batch=show, record=True,
                    stop_when=lambda loop: loop.last_seq is not None and loop.last_seq >= n_total - 1)
    end = loop.run()
    if end.error is not None:      # Ctrl-C, a lost port, a bug: the CLI reports it (130, 2, 3)
        raise end.error
    lat = loop.latency_us()
    e = est.estimate
    t_end = (loop.last_seq or 0) * dt
    trace.append({"t": t_end, "alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b,
                  "phase": e.phase, "quality": e.quality, "wall": loop.wall_s})
    return {
        "estimate": e.to_dict(), "model": est.model.describe() if est.model else None, "t_end": t_end,
        "errors": _errors(est.model, truth_at(t_end)), "samples_received": loop.fed, "samples_sent_by_plant": n_total,
        "wall_s": loop.wall_s, "achieved_rate_sps": loop.fed / loop.wall_s if loop.wall_s > 0 else 0.0,
        "latency_us": _dist(lat), "gaps_not_fed": loop.lost_not_fed,
        "trace": trace, "_seq": np.asarray(loop.seqs), "_u": np.asarray(loop.us), "_y": np.asarray(loop.ys),
        "_lat_us": lat,
    }


def _dist(x: np.ndarray) -> dict:
    if x.size == 0:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan}
    return {"p50": float(np.percentile(x, 50)), "p99": float(np.percentile(x, 99)), "max": float(np.max(x))}


def _status(loop, truth) -> str:
    """The live line: plant time, rate, phase, latest change, estimate and its error, latency, link trouble."""
    est, src = loop.estimator, loop.source
    e = est.estimate
    el = time.monotonic() - loop.started
    n = src.stats.samples
    text = f"t={(loop.last_seq or 0) * est.dt:6.2f}s {n / max(el, 1e-9) / 1e3:5.1f} kS/s "
    text += f"[{e.phase}/{e.quality}] "
    if e.events:
        ev = e.events[-1]
        text += (f"fault@{ev['t']:.1f}s({ev['error']}) " if ev.get("kind") == "internal_fault" else
                 f"change@{ev['t']:.1f}s({','.join(ev['moved']) or '?'}) ")
    switched = [rs for rs in e.researches if rs["switched"]]
    if switched:
        text += f"research@{switched[-1]['t']:.1f}s({','.join(switched[-1]['moved'])}) "
    if e.outliers or e.input_outliers:
        text += f"outliers y{e.outliers} u{e.input_outliers} "
    m = est.model
    if m is not None:
        err = _errors(m, truth)
        text += (f"alpha={m.alpha:.4f} ({err['alpha_abs']:+.1e}) fn={m.fn:.1f}Hz ({100 * err['fn_rel']:+.2f}%) "
                 f"zeta={m.zeta:.3f} b={m.b:.4f} ({100 * err['b_rel']:+.2f}%) ")
    recent = loop.recent_latency_us(2000)
    if recent.size:
        text += f"lat p99={np.percentile(recent, 99):.0f}us "
    st = src.stats
    bad = st.missing + st.bad_frames + st.sequence.duplicates + st.disconnects
    if bad:
        text += f"| lost {st.missing} bad {st.bad_frames} dup {st.sequence.duplicates} disc {st.disconnects}"
    return text


def _print_summary(r: dict, as_json: bool) -> None:
    public = {k: v for k, v in r.items() if not k.startswith("_") and k != "trace"}
    if as_json:
        print_json(public)
        return
    t = r["truth"]
    m = r["model"]
    print("creep-online demo: summary")
    print(f"  plant   : hil_sim over {r['tty']} ({r['transport']}), {r['rate_hz']:g} Hz, "
          f"{r['samples_sent_by_plant']} samples")
    print(f"  received: {r['samples_received']} samples in {r['wall_s']:.1f} s "
          f"({r['achieved_rate_sps'] / 1e3:.1f} kS/s sustained)")
    led = r.get("plant_ledger") or {}
    if led.get("late_max_s", 0) > 0.05:
        print(f"  note    : the plant fell behind real time by up to {led['late_max_s'] * 1e3:.0f} ms "
              "(machine busy); samples were delivered late, none lost")
    for change in (r.get("scenario") or {}).get("changes", []):
        print(f"  change  : at t = {change['t']:.4g} s, {change['what']} (errors are measured against the plant "
              "valid at each moment)")
    if (r.get("scenario") or {}).get("drift"):
        d = r["scenario"]["drift"]
        print(f"  drift   : alpha {100 * d['alpha']:+.0f} %, b {100 * d['b']:+.0f} % over the run (errors are measured "
              "against the plant valid at each moment)")
    lat = r["latency_us"]
    print(f"  latency : plant sample time -> estimator updated: p50 {lat['p50']:.0f} us, p99 {lat['p99']:.0f} us, "
          f"max {lat['max']:.0f} us")
    print(f"  link    : {_stats_line(r['source_stats'])}")
    if m is None:
        print(f"  estimate: none yet (phase {r['estimate']['phase']})")
    else:
        e = r["errors"]
        est = r["estimate"]
        why = f" ({est['reason']})" if est.get("reason") else ""
        print(f"  estimate: phase {est['phase']}, quality {est['quality']}{why}")
        for ev in est.get("events", []):
            print(f"    {event_line(ev)}")
        for line in research_lines(est.get("researches", [])):
            print(f"    {line}")
        print(f"    alpha {m['alpha']:.5f}  (true {t['alpha']:.5f}, error {e['alpha_abs']:+.2e})")
        print(f"    fn    {m['fn_hz']:.2f} Hz (true {t['fn_hz']:.2f}, error {100 * e['fn_rel']:+.3f} %)")
        print(f"    zeta  {m['zeta']:.4f}  (true {t['zeta']:.4f}, error {100 * e['zeta_rel']:+.3f} %)")
        print(f"    b     {m['b']:.5f}  (true {t['b']:.5f}, error {100 * e['b_rel']:+.3f} %)")
    print(f"  report  : {r['report']}")


def _stats_line(s: dict) -> str:
    return (f"{s['samples']} good; missing {s['missing']} in {s['gaps']} gap(s), duplicates {s['duplicates']}, "
            f"reordered {s['reordered']}, CRC errors {s['crc_errors']}, malformed {s['malformed']}, "
            f"garbage {s['garbage_bytes']} B, disconnects {s['disconnects']}, stalls {s['stalls']}")
