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
from pathlib import Path

from ..errors import CreepOnlineError
from ..model import ONLINE_REFITS as REFITS
from ..reports.demo_report import plant_truth
from ._common import (MAX_HZ, event_line, finite_number, nonempty, positive_number, print_json, research_lines,
                      seconds, whole)
from ._progress import Progress
from .demo_plant import DRIFT, hardware_extras, start_plant, stream_plant

SCENARIOS = ("stationary", "payload", "drift")
#: The demo's limits: an hour of plant at up to 100 kHz, and a record between these many samples (the simulated
#: plant generates its record in memory; fewer samples than the minimum cannot show an identification).
DEMO_MAX_S = 3600.0
DEMO_MAX_RATE = 100_000.0
DEMO_SAMPLES = (1000, 50_000_000)
#: The payload scenario's added mass fraction (a2 *= 1 + PAYLOAD_MASS at half the duration).
PAYLOAD_MASS = 0.5


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
        result = stream_plant(src, est, truth, n_total, args, t0, progress)
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
