"""``python -m hil_sim.pi_controller``: a PI piezo controller's GCS 2 command subset over a pty or TCP.

Stands in for an E-727-like digital piezo controller so that PI's own library,
``pipython`` (``GCSDevice`` over its ``PISerial`` or ``PISocket`` gateway), can
be the client, unchanged: over a pseudo-terminal (RS-232) by default, or on a
loopback TCP port with ``--tcp [PORT]`` (the controller's Ethernet interface).
Behind the commands is hil_sim's simulated plant (``hil_sim.plant.generate``),
one per axis (``--axes N``; ``--params`` may give one ``;``-separated set per
axis): its input schedule is the piezo voltage, its output the sensor
position, one sample per servo cycle (``--rate``).

The commands and the replies pipython expects (one command per line, ``\\n``
ended; a multi-line reply ends every line but the last with a space before the
line feed; a query's error is collected by pipython with ``ERR?``):

=================  ==========================================================
``*IDN?``          identification line
``CSV?``           ``2.0`` (GCS 2 syntax: pipython then uses its GCS 2 classes)
``ERR?``           the last error code, then resets it to 0
``SAI?``           the axis identifiers (``1`` .. ``N``)
``TNR?``           number of data recorder tables
``RTR n``/``RTR?`` record table rate: servo cycles per recorded point
``DRC t s o``      table t records option o of axis/channel s; ``DRC?`` reads it
``DRT t s v``      trigger source; any DRT (re)starts the recording now (source 4,
                   "trigger immediately", is what the ``pi:`` source sends)
``DRT?``           the trigger settings
``DRL? [t..]``     points recorded so far in each table
``DRR? o n [t..]`` n points from point o (1-based) of the tables: the GCS data
                   header (``# KEY = value`` lines, ``# END_HEADER``), then rows
``VOL? [c]``       the present piezo voltage; ``POS? [a]`` the present position
=================  ==========================================================

Record options: 1 target position (the voltage at unit gain), 2 current position (sensor),
3 position error, 7 piezo voltage of output channel, 14 open-loop control
value. Anything else sets an error (2 unknown command, 1 syntax, 15 invalid
axis, 17 out of range) as a real controller does.

A recording holds at most ``--table-points`` points per table and then stops,
like a real record table; a new DRT starts the next one. The time base is the
system monotonic clock: servo cycle c happens at ``t0 + c / rate``, t0 being
the first trigger; ``--fast`` instead makes every recording complete at once
and start where the previous one ended (throughput measurements).

The record is ``--duration`` seconds long from the first trigger; the
emulator exits ``--linger`` seconds after it ends (with ``--fast``, when
stopped).

stdout: line 1 the port (``127.0.0.1:PORT`` with ``--tcp``); then JSON events
``ready`` (model, models: one per axis, rate, samples),
``trigger`` (servo cycle where a recording starts, its points), ``disconnect``,
``reconnect``, ``end``. ``--disconnect-after S`` closes the port S seconds after
the first trigger (a pulled cable) and exits, or with ``--back-after S2`` opens a
new pty behind ``--link`` S2 seconds later and goes on answering.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .links import PtyLink, TcpLink
from .plant import SCHEDULES, PlantConfig, PlantRecord, generate, parse_params

IDN = "Physik Instrumente (PI) GmbH & Co. KG, E-727 (hil_sim emulation), 0000000000, 01.000"
TABLES = 8

#: Record options emulated: option id -> (name pattern of the header's NAMEi, whether the source is an axis).
RECORD_OPTIONS = {
    1: "Target Position of axis {}",
    2: "Current Position of axis {}",
    3: "Position Error of axis {}",
    7: "Voltage of output channel {}",
    14: "Open Loop Control of axis {}",
}

# GCS error codes (pipython.gcserror)
PARAM_SYNTAX, UNKNOWN_COMMAND, INVALID_AXIS, OUT_OF_RANGE = 1, 2, 15, 17


def emit(event: str, **data) -> None:
    print(json.dumps({"event": event, **data}), flush=True)


def gcs_reply(lines: list[str]) -> str:
    """GCS multi-line convention: every line but the last ends with ``' \\n'``, the last with ``'\\n'``."""
    return " \n".join(lines) + "\n"


@dataclass
class Recording:
    """One recording: the servo cycle it started at and the table configuration it records."""

    start: int
    config: dict[int, tuple[str, int]]


@dataclass
class Controller:
    """The command interpreter; ``handle(line)`` returns the reply text (or None) for one command."""

    plant: PlantRecord | list[PlantRecord]
    rate: float
    table_points: int
    fast: bool = False
    rtr: int = 1
    error: int = 0
    config: dict[int, tuple[str, int]] = field(default_factory=lambda: {1: ("1", 7), 2: ("1", 2)})
    triggers: dict[int, tuple[int, str]] = field(default_factory=dict)
    recording: Recording | None = None
    t0: float | None = None

    def __post_init__(self) -> None:
        self.plants = self.plant if isinstance(self.plant, list) else [self.plant]
        self.plant = self.plants[0]
        self.axes = tuple(str(k + 1) for k in range(len(self.plants)))

    # ------------------------------------------------------------------ time and data
    def cycle_now(self) -> int:
        if self.t0 is None:
            return 0
        return int((time.monotonic() - self.t0) * self.rate)

    def trigger(self) -> None:
        """Start a recording at the present servo cycle (in --fast mode: where the last one ended)."""
        if self.t0 is None:
            self.t0 = time.monotonic()
            start = 0
        elif self.fast and self.recording is not None:
            start = self.recording.start + self.table_points * self.rtr
        else:
            start = self.cycle_now()
        self.recording = Recording(start, dict(self.config))
        emit("trigger", cycle=start, rtr=self.rtr, table_points=self.table_points,
             sample_time=self.rtr / self.rate, t_monotonic=self.t0 + start / self.rate)

    def recorded(self) -> int:
        """Points in each table of the present recording."""
        rec = self.recording
        if rec is None:
            return 0
        n_plant = self.plant.u.size
        last = n_plant - 1 if self.fast else min(self.cycle_now(), n_plant - 1)
        if last < rec.start:
            return 0
        return min(self.table_points, (last - rec.start) // self.rtr + 1)

    def present(self, option: int, axis: str = "1") -> float:
        """The signal's value at the present servo cycle (VOL?, POS?)."""
        k = min(self.cycle_now(), self.plant.u.size - 1) if self.recording else 0
        return float(self._column(option, np.array([k]), axis)[0])

    def finished(self, linger: float) -> bool:
        """The record has been played (``linger`` s ago) in real time; never in --fast mode."""
        if self.fast or self.t0 is None:
            return False
        return time.monotonic() - self.t0 > self.plant.u.size / self.rate + linger

    # ------------------------------------------------------------------ commands
    def handle(self, line: str) -> str | None:
        words = line.split()
        if not words:
            return None
        cmd, args = words[0].upper(), words[1:]
        method = COMMANDS.get(cmd)
        if method is None:
            self.error = UNKNOWN_COMMAND
            return None
        try:
            return method(self, args)
        except (ValueError, IndexError):
            self.error = PARAM_SYNTAX
            return None

    def q_idn(self, args):
        return IDN + "\n"

    def q_csv(self, args):
        return "2.0\n"

    def q_err(self, args):
        err, self.error = self.error, 0
        return f"{err}\n"

    def q_sai(self, args):
        return gcs_reply(list(self.axes))

    def q_tnr(self, args):
        return f"{TABLES}\n"

    def rtr_set(self, args):
        value = int(args[0])
        if len(args) != 1 or value < 1:
            raise ValueError
        self.rtr = value

    def q_rtr(self, args):
        return f"{self.rtr}\n"

    def _tables(self, args) -> list[int]:
        tables = [int(a) for a in args] if args else sorted(self.config)
        if any(not 1 <= t <= TABLES for t in tables):
            self.error = OUT_OF_RANGE
            return []
        return tables

    def _table_reply(self, args, settings: dict, default: tuple) -> str | None:
        """``t=a b`` per table (DRC?, DRT?)."""
        tables = self._tables(args)
        return gcs_reply([f"{t}={settings.get(t, default)[0]} {settings.get(t, default)[1]}"
                          for t in tables]) if tables else None

    @staticmethod
    def _triples(args) -> list[tuple[int, str, str]]:
        """``t a b t a b ...`` (DRC, DRT) -> [(t, a, b), ...]; ValueError (syntax error) otherwise."""
        if not args or len(args) % 3:
            raise ValueError
        return [(int(args[i]), args[i + 1], args[i + 2]) for i in range(0, len(args), 3)]

    def drc_set(self, args):
        triples = [(table, source, int(option)) for table, source, option in self._triples(args)]
        for table, source, option in triples:
            if not 1 <= table <= TABLES or (option not in RECORD_OPTIONS and option != 0):
                self.error = OUT_OF_RANGE
                return None
            if option and source not in self.axes:
                self.error = INVALID_AXIS
                return None
        for table, source, option in triples:
            if option == 0:
                self.config.pop(table, None)
            else:
                self.config[table] = (source, option)
        return None

    def q_drc(self, args):
        return self._table_reply(args, self.config, ("0", 0))

    def drt_set(self, args):
        triples = [(table, int(source), value) for table, source, value in self._triples(args)]
        if any(not 0 <= table <= TABLES or not 0 <= source <= 9 for table, source, _ in triples):
            self.error = OUT_OF_RANGE
            return None
        for table, source, value in triples:
            for t in (range(1, TABLES + 1) if table == 0 else (table,)):
                self.triggers[t] = (source, value)
        self.trigger()
        return None

    def q_drt(self, args):
        return self._table_reply(args, self.triggers, (0, "0"))

    def q_drl(self, args):
        tables = self._tables(args)
        n = self.recorded()
        return gcs_reply([f"{t}={n if t in (self.recording.config if self.recording else {}) else 0}"
                          for t in tables]) if tables else None

    def q_drr(self, args):
        rec = self.recording
        available = self.recorded()
        offset = int(args[0]) if args else 1
        count = int(args[1]) if len(args) > 1 else available - offset + 1
        tables = [int(a) for a in args[2:]] if len(args) > 2 else sorted(rec.config if rec else self.config)
        if rec is None or offset < 1 or count < 0 or any(t not in rec.config for t in tables):
            self.error = OUT_OF_RANGE
            return None
        count = max(0, min(count, available - offset + 1))   # never beyond what was recorded
        header = ["# REM E-727 (hil_sim emulation)", "#", "# VERSION = 1", "# TYPE = 1", "# SEPARATOR = 32",
                  f"# DIM = {len(tables)}", f"# SAMPLE_TIME = {self.rtr / self.rate:.9g}", f"# NDATA = {count}", "#"]
        header += [f"# NAME{i} = {RECORD_OPTIONS[rec.config[t][1]].format(rec.config[t][0])}"
                   for i, t in enumerate(tables)]
        header += ["#", "# END_HEADER"]
        cycles = rec.start + (offset - 1 + np.arange(count)) * self.rtr
        columns = [self._column(rec.config[t][1], cycles, rec.config[t][0]) for t in tables]
        rows = [" ".join(f"{v:.10g}" for v in values) for values in zip(*columns)]
        return gcs_reply(header + rows)

    def _column(self, option: int, cycles: np.ndarray, axis: str) -> list[float]:
        """Option ``option`` of ``axis`` at the given servo cycles (the target is the voltage at unit gain)."""
        plant = self.plants[int(axis) - 1]
        u, y = plant.u[cycles], plant.y[cycles]
        return {1: u, 2: y, 3: u - y, 7: u, 14: u}[option].tolist()

    def q_vol(self, args):
        channels = args or ["1"]
        if any(c not in self.axes for c in channels):
            self.error = INVALID_AXIS
            return None
        return gcs_reply([f"{c}={self.present(7, c):.10g}" for c in channels])

    def q_pos(self, args):
        axes = args or list(self.axes)
        if any(a not in self.axes for a in axes):
            self.error = INVALID_AXIS
            return None
        return gcs_reply([f"{a}={self.present(2, a):.10g}" for a in axes])


COMMANDS = {"*IDN?": Controller.q_idn, "CSV?": Controller.q_csv, "ERR?": Controller.q_err,
            "SAI?": Controller.q_sai, "TNR?": Controller.q_tnr, "RTR": Controller.rtr_set,
            "RTR?": Controller.q_rtr, "DRC": Controller.drc_set, "DRC?": Controller.q_drc,
            "DRT": Controller.drt_set, "DRT?": Controller.q_drt, "DRL?": Controller.q_drl,
            "DRR?": Controller.q_drr, "VOL?": Controller.q_vol, "POS?": Controller.q_pos}


def serve(link: PtyLink | TcpLink, ctl: Controller, disconnect_after: float | None, back_after: float | None,
          linger: float = 1.0) -> None:
    """Answer commands line by line until stopped (SIGTERM), the record is over (``linger`` s after its end)
    or the simulated cable is pulled for good.

    The cable is pulled ``disconnect_after`` s after the first trigger; with ``back_after``
    it is plugged in again that many seconds later (a new pty behind ``--link``) and the
    controller, which kept running, answers again.
    """
    buf = b""
    while not ctl.finished(linger):
        if disconnect_after is not None and ctl.t0 is not None and time.monotonic() - ctl.t0 > disconnect_after:
            emit("disconnect", after_s=disconnect_after, recorded=ctl.recorded())
            link.close()
            if back_after is None:
                return
            time.sleep(back_after)
            link.reopen()
            buf, disconnect_after = b"", None
            emit("reconnect", tty=link.tty)
        chunk = link.read_available(0.05)
        if not chunk:
            continue
        buf += chunk
        *lines, buf = buf.split(b"\n")
        for raw in lines:
            reply = ctl.handle(raw.decode("cp1252", errors="replace").strip())
            if reply:
                link.write(reply.encode("cp1252"))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m hil_sim.pi_controller", description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=float, default=10_000.0, help="servo cycles per second (default 10000)")
    p.add_argument("--duration", type=float, default=20.0, help="length of the plant record in seconds (default 20)")
    p.add_argument("--params", default="", help="alpha=..,fn=..,zeta=..,b=.. (default: hil_sim's demo plant)")
    p.add_argument("--schedule", choices=SCHEDULES, default="step", help="piezo voltage schedule")
    p.add_argument("--amplitude", type=float, default=1.0, help="voltage step (default 1)")
    p.add_argument("--period", type=float, default=2.0)
    p.add_argument("--t-start", type=float, default=0.0, help="time of the first voltage step (s)")
    p.add_argument("--noise", type=float, default=2e-4, help="sensor noise std")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--table-points", type=int, default=262_144, help="points per record table (default 262144)")
    p.add_argument("--fast", action="store_true", help="recordings complete at once (throughput, no real time)")
    p.add_argument("--disconnect-after", type=float, default=None,
                   help="close the port this many seconds after the first trigger and exit (a pulled cable)")
    p.add_argument("--back-after", type=float, default=None,
                   help="with --disconnect-after: plug the cable in again this many seconds later (needs --link)")
    p.add_argument("--link", default=None, help="stable symlink to the pty")
    p.add_argument("--tcp", type=int, nargs="?", const=0, default=None, metavar="PORT",
                   help="serve on 127.0.0.1:PORT instead of a pty (no PORT: a free one)")
    p.add_argument("--axes", type=int, default=1, help="axes, each with its own plant (1..4, default 1)")
    p.add_argument("--linger", type=float, default=1.0,
                   help="seconds to keep answering after the record has been played (default 1)")
    return p


def plant_configs(args: argparse.Namespace) -> list[PlantConfig]:
    """The plant of each axis, sampled once per servo cycle (tests rebuild them from the same args).

    Axis k takes the k-th ``;``-separated set of ``--params`` (the last set when there are fewer)
    and noise seed ``seed + k - 1``.
    """
    sets = args.params.split(";")
    return [PlantConfig(parse_params(sets[min(k, len(sets) - 1)]), rate=args.rate, duration=args.duration,
                        schedule=args.schedule, amplitude=args.amplitude, period=args.period, t_start=args.t_start,
                        noise=args.noise, seed=args.seed + k) for k in range(args.axes)]


def plant_config(args: argparse.Namespace) -> PlantConfig:
    """The plant of axis 1."""
    return plant_configs(args)[0]


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not 1 <= args.axes <= TABLES // 2:
        parser.error(f"--axes must be 1..{TABLES // 2}")
    if args.tcp is not None and args.link:
        parser.error("--link names a pty; a --tcp port stays the same across --back-after")
    configs = plant_configs(args)
    plants = [generate(cfg) for cfg in configs]
    link = TcpLink(args.tcp) if args.tcp is not None else PtyLink(args.link)
    print(link.port, flush=True)
    models = [{"alpha": c.model.alpha, "a1": c.model.a1, "a2": c.model.a2, "b": c.model.b} for c in configs]
    emit("ready", model=models[0], models=models, rate=args.rate, samples=int(plants[0].u.size), tty=link.tty)
    ctl = Controller(plants, args.rate, args.table_points, fast=args.fast)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        serve(link, ctl, args.disconnect_after, args.back_after, args.linger)
    finally:
        emit("end", recorded=ctl.recorded())
        link.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
