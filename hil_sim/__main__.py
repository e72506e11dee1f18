"""``python -m hil_sim``: the simulated amplifier + plant in its own process.

stdout, line 1: the port to open (a ``/dev/pts/N`` path, or the ``--link``
symlink; ``127.0.0.1:PORT`` for ``--transport capancdt``, served by
``capancdt_server``). Every further stdout line is a JSON event: ``ready`` (model,
rate, sample count), ``start`` (``t0_monotonic``: sample n was taken at
``t0 + n / rate`` on the system monotonic clock), ``stall``, ``disconnect``,
``reconnect``, ``end`` (with the fault ledger). ``--ledger FILE`` also writes
the ledger as JSON.
"""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import tempfile
import threading

from creep_online.cli import OneLineParser

from .faults import FaultSpec, plan
from .links import PtyLink
from .plant import EFFECT_DEFAULTS, SCHEDULES, PlantConfig, generate, parse_effects, parse_params
from .runner import CAN_FRAMES, TRANSPORTS, Runner, emit_event

CAPANCDT = "capancdt"


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m hil_sim", description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=float, default=None,
                   help="samples per second (default 10000; capancdt: 3906.25, the controller's fastest rate)")
    p.add_argument("--duration", type=float, default=20.0, help="record length in seconds (default 20)")
    p.add_argument("--transport", choices=TRANSPORTS[:-1] + (CAPANCDT,), default="serial-binary",
                   help="capancdt: a capaNCDT 6200-style TCP data port on 127.0.0.1 (hil_sim/capancdt_server.py)")
    p.add_argument("--can-frame", choices=CAN_FRAMES, default="pair",
                   help="slcan: samples per CAN frame: sample (1), pair (2, classic), block (7, CAN FD)")
    p.add_argument("--params", default="", help="alpha=..,a1=..,a2=..,b=.. or alpha=..,fn=..,zeta=..,b=..")
    p.add_argument("--schedule", choices=SCHEDULES, default="step")
    p.add_argument("--amplitude", type=float, default=1.0)
    p.add_argument("--period", type=float, default=2.0, help="staircase/square period (s)")
    p.add_argument("--t-start", type=float, default=0.0, help="time of the first input step (s)")
    p.add_argument("--noise", type=float, default=2e-4, help="output noise std")
    p.add_argument("--adc-bits", type=int, default=20)
    p.add_argument("--adc-range", type=float, default=10.0)
    p.add_argument("--effects", default="", help="hidden effects (docs/diagnostics.md): 'drift;delay:delay_s=1e-3' "
                        "(name[:k=v,..] joined by ';', list values as a/b/c) or a JSON object")
    p.add_argument("--faults", default="", help="garbage=N,bitflip=N,drop=N,dup=N,reorder=N,stall=N,disconnect=N"
                                                ",stall_s=S,disconnect_s=S (N a count, or a probability < 1)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--payload", default="", help="T:M: at time T (s) a payload adds the fraction M to the moving "
                                                 "mass (a2 *= 1 + M; the state continues), e.g. 10:0.5")
    p.add_argument("--command-input", action="store_true",
                   help="closed loop: the DAC applies the reader's command frames (binary frames with the command "
                        "status bit, one per sample) instead of playing --schedule; serial-binary only")
    p.add_argument("--drift", default="", help="alpha=A,b=B: alpha and b drift by the fractions A and B over the "
                                               "record (e.g. alpha=0.2,b=0.1)")
    p.add_argument("--fast", action="store_true", help="as fast as possible instead of real time")
    p.add_argument("--wait-start", action="store_true",
                   help="serial: hold the stream until the reader sends a byte (slcan always waits for 'O')")
    p.add_argument("--link", default=None, help="stable symlink to the pty (needed to reconnect after a disconnect)")
    p.add_argument("--linger", type=float, default=2.0, help="keep the port open this long after the end (s)")
    p.add_argument("--ledger", default=None, help="write the injected-fault ledger (JSON) here")
    g = p.add_argument_group("capancdt transport")
    g.add_argument("--command-rate", type=float, default=1000.0, help="rate of the actuator command in Hz (default 1000)")
    g.add_argument("--command-file", default=None, help="write the command's t,u schedule here (the source's ?command=)")
    g.add_argument("--frames-per-packet", type=int, default=4, help="measuring frames per TCP packet (default 4)")
    g.add_argument("--sensor-range", type=float, default=200.0, help="measuring range in um (default 200)")
    g.add_argument("--sensor-offset", type=float, default=None, help="standoff in um (default: mid-range)")
    g.add_argument("--sensor-channels", type=int, default=1, help="channels in the stream (default 1)")
    g.add_argument("--sensor-channel", type=int, default=1, help="the channel that measures the actuator (default 1)")
    g.add_argument("--counter-start", type=int, default=0, help="frame counter of the first frame (default 0)")
    g.add_argument("--port", type=int, default=0, help="TCP port (default: an ephemeral one)")
    g.add_argument("--control-port", type=int, default=0,
                   help="control port answering the sample-time query $STI? (default: an ephemeral one; "
                        "the ready event names it)")
    g.add_argument("--size-first", action="store_true",
                   help="write bytes per frame before the frame count in the packet header (the other order)")
    return p


def _payload(text: str) -> tuple[float, float] | None:
    """``T:M`` -> (T, M); empty -> None."""
    if not text:
        return None
    try:
        at, mass = (float(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"--payload expects T:M (seconds:mass fraction), got {text!r}") from None
    return at, mass


def _check_args(args: argparse.Namespace) -> None:
    """ValueError naming the first flag the plant cannot run with (the plant's own settings: ``PlantConfig``)."""
    def number(flag: str, value, low: float, high: float, low_open: bool = False) -> None:
        if value is None:
            return
        if not (math.isfinite(value) and (value > low if low_open else value >= low) and value <= high):
            raise ValueError(f"{flag} must be a finite number {'>' if low_open else '>='} {low:g} and <= {high:g}, "
                             f"got {value!r}")
    number("--command-rate", args.command_rate, 0.0, 1e6, low_open=True)
    number("--frames-per-packet", args.frames_per_packet, 1, 1 << 16)
    number("--sensor-range", args.sensor_range, 0.0, 1e9, low_open=True)
    number("--sensor-offset", args.sensor_offset, -1e9, 1e9)
    number("--sensor-channels", args.sensor_channels, 1, 8)
    number("--sensor-channel", args.sensor_channel, 1, args.sensor_channels if args.sensor_channels >= 1 else 1)
    number("--counter-start", args.counter_start, 0, (1 << 32) - 1)
    number("--port", args.port, 0, 65535)
    number("--linger", args.linger, 0.0, 3600.0)
    number("--seed", args.seed, 0, 2 ** 32 - 1)
    for flag, text in (("--link", args.link), ("--ledger", args.ledger), ("--command-file", args.command_file)):
        if text is not None and not text.strip():
            raise ValueError(f"{flag} must not be empty")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.rate is None:
        args.rate = 3906.25 if args.transport == CAPANCDT else 10_000.0
    try:
        _check_args(args)
        model = parse_params(args.params)
        spec = FaultSpec.parse(args.faults)
        effects = parse_effects(args.effects)
        drift = _drift(args.drift)
        if args.command_input:
            PlantConfig(model=model, rate=args.rate, duration=args.duration, noise=args.noise,
                        adc_bits=args.adc_bits, adc_range=args.adc_range, seed=args.seed, drift=drift)
            return _closed_loop(args, model, drift, spec, effects)
        cfg = PlantConfig(model=model, rate=args.rate, duration=args.duration, schedule=args.schedule,
                          amplitude=args.amplitude, period=args.period, t_start=args.t_start, noise=args.noise,
                          adc_bits=args.adc_bits, adc_range=args.adc_range, effects=effects,
                          payload=_payload(args.payload),
                          seed=args.seed, drift=drift)
    except ValueError as exc:
        print(f"hil_sim: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}", file=sys.stderr)
        return 2
    if args.transport == CAPANCDT:
        from .capancdt_server import serve
        return serve(args, cfg, spec)
    rec = generate(cfg)
    link_path = args.link
    if link_path is None and "disconnect" in spec.counts:
        link_path = os.path.join(tempfile.mkdtemp(prefix="hil_sim_"), "amp")
    try:
        link = PtyLink(link_path)
    except OSError as exc:
        print(f"hil_sim: cannot open the pseudo-terminal or its link {link_path}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    stop = threading.Event()

    def on_signal(signum, frame):  # noqa: ARG001 - signal handler signature
        stop.set()
        if armed:
            armed.clear()
            raise _Stopped()   # also breaks out of a write blocked on a full pty
    armed = [True]
    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)

    spf = 1 if args.transport.startswith("serial") else {"sample": 1, "pair": 2, "block": 7}[args.can_frame]
    try:
        runner = Runner(rec, args.rate, args.transport, link,
                        plan(spec, rec.t.size // spf, args.seed, frame_rate=args.rate / spf), spec,
                        can_frame=args.can_frame, realtime=not args.fast, seed=args.seed, stop=stop,
                        resume=(lambda: _wait_any(link, stop)) if args.wait_start else None)
    except ValueError as exc:
        print(f"hil_sim: {exc}", file=sys.stderr)
        link.close()
        return 2
    print(link.port, flush=True)
    emit_event("ready", port=link.port, tty=link.tty, transport=args.transport, rate=args.rate,
               samples=runner.n_samples, samples_per_frame=runner.spf, model=model.params(),
               schedule=args.schedule, amplitude=args.amplitude, noise=args.noise, lsb=rec.lsb,
               effects=cfg.effects, faults=spec.counts, pid=os.getpid())
    try:
        if args.transport == "slcan":
            link.wait_for(b"O\r", reply=b"\r")
        elif args.wait_start:
            _wait_any(link, stop)
        runner.run()
        link.drain(timeout=max(1.0, args.linger))
    except _Stopped:
        pass
    armed.clear()
    ledger = runner.ledger
    if args.ledger:
        ledger.write(args.ledger)
    try:
        emit_event("end", ledger=ledger.to_dict(), stopped=stop.is_set())
        stop.wait(args.linger)
    except BrokenPipeError:
        pass
    link.close()
    return 0


def _drift(text: str) -> tuple[float, float]:
    """``alpha=A,b=B`` -> (A, B) relative drifts over the record; empty -> no drift."""
    out = {"alpha": 0.0, "b": 0.0}
    for item in filter(None, (x.strip() for x in text.split(","))):
        key, _, value = item.partition("=")
        if key.strip() not in out:
            raise ValueError(f"--drift takes alpha=..,b=.. (fractions over the record), got {item!r}")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--drift: {key.strip()} must be a number, got {value!r}") from None
    return out["alpha"], out["b"]


def _closed_loop(args, model, drift: tuple[float, float], spec, effects) -> int:
    """``--command-input``: the plant steps in real time on the reader's command frames."""
    from .command_runner import CommandRunner
    other = sorted(set(effects) - {"hysteresis"})      # (the closed loop's plant models the actuator's loop only)
    refused = [name for name, given in (("--faults", spec.counts), (f"--effects {','.join(other)}", other),
                                        ("--payload", args.payload), ("--fast", args.fast)) if given]
    if args.transport != "serial-binary":
        print(f"hil_sim: --command-input needs --transport serial-binary (got {args.transport})", file=sys.stderr)
        return 2
    if refused:
        print(f"hil_sim: --command-input cannot be combined with {', '.join(refused)}", file=sys.stderr)
        return 2
    try:
        link = PtyLink(args.link)
    except OSError as exc:
        print(f"hil_sim: cannot open the pseudo-terminal or its link {args.link}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    n = max(2, int(round(args.duration * args.rate)))
    if effects.get("hysteresis") == EFFECT_DEFAULTS["hysteresis"]:     # bare: a loop scaled to the command stroke
        from .hysteresis_plants import command_loop
        effects = {"hysteresis": command_loop(model, args.seed)}
    try:
        runner = CommandRunner(model, args.rate, n, link, noise=args.noise, adc_bits=args.adc_bits,
                               adc_range=args.adc_range, seed=args.seed, drift=drift, events=emit_event, stop=stop,
                               hysteresis=effects.get("hysteresis"))
    except ValueError as exc:
        print(f"hil_sim: --effects hysteresis: {str(exc).splitlines()[0]}", file=sys.stderr)
        link.close()
        return 2
    print(link.port, flush=True)
    emit_event("ready", port=link.port, tty=link.tty, transport=args.transport, rate=args.rate, samples=n,
               samples_per_frame=1, model=model.params(), schedule="command", noise=args.noise,
               lsb=runner.lsb, effects=effects, faults={}, drift={"alpha": drift[0], "b": drift[1]},
               pid=os.getpid())
    if runner.wait_first_command():
        runner.run()
        link.drain(timeout=max(1.0, args.linger))
    try:
        emit_event("end", ledger=runner.ledger.to_dict(), stopped=stop.is_set(), produced=runner.produced)
        stop.wait(args.linger)
    except BrokenPipeError:
        pass
    link.close()
    return 0


class _Stopped(Exception):
    """SIGTERM/SIGINT: stop streaming, write the ledger, close the port."""


def _wait_any(link: PtyLink, stop: threading.Event) -> None:
    """Wait for any byte from the reader (its start command)."""
    while not stop.is_set():
        if link.read_available(0.05):
            return


if __name__ == "__main__":
    sys.exit(main())
