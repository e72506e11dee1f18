"""The simulated plant as a capaNCDT 6200-style controller: its ``MEAS`` packet stream on a loopback TCP port.

The plant is sampled at the sensor's rate (3906.25 Hz by default) while the
actuator command changes at its own rate (``--command-rate``, 1 kHz by
default): the command is the schedule sampled at the command instants and
held, written to ``--command-file`` as the ``t,u`` schedule the source reads.
The plant sees the held command at each sensor instant (the idealisation
said in docs/transports.md), its output plus the sensor's standoff is
quantised to 24 bits of the measuring range, and packets of
``--frames-per-packet`` frames go to the client. Like the real controller,
acquisition starts when a client connects to the data port; the frame counter
starts at ``--counter-start`` and keeps running through a disconnect.

Faults (a "frame" of the fault plan is one packet): ``drop`` skips
``drop_frames`` measuring frames (a counter jump), ``badheader`` sends a packet
whose header is corrupt (magic, frame size, frame count or channel field,
in turn), ``garbage`` puts random bytes (never an 'M') before a packet,
``stall`` pauses, ``disconnect`` closes the connection and accepts the next
one after ``disconnect_s``; the frames of the outage are lost. The ledger
lists every one.
"""
from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass

import numpy as np

from creep_online.io.capancdt_frames import COUNTER_MODULUS, MAGIC, channel_field, encode_packet, quantize
from creep_online.io.capancdt_source import RANGE_UM
from creep_online.io.command_schedule import CommandSchedule, held_at_rate

from .faults import FaultSpec, Ledger
from .plant import PlantConfig, PlantRecord, generate, make_input

FAULTS = {"drop", "badheader", "garbage", "stall", "disconnect"}
COMMAND_RATE = 1000.0
FRAMES_PER_PACKET = 4


@dataclass
class SensorRecord:
    """What the controller streams: raw 24-bit values (n, channels), and the command schedule behind them."""

    plant: PlantRecord
    command: CommandSchedule
    raw: np.ndarray
    channel_bits: int
    range_um: float


def sensor_record(cfg: PlantConfig, *, command_rate: float = COMMAND_RATE, range_um: float = RANGE_UM,
                  offset_um: float | None = None, channels: int = 1, channel: int = 1) -> SensorRecord:
    """The plant sampled by the sensor at ``cfg.rate`` with the command held from ``command_rate`` instants.

    ``channel`` (of ``channels``) measures the actuator: its standoff ``offset_um``
    (default mid-range) plus the plant's output in um; the other channels
    watch a fixed target at the same standoff.
    """
    n = max(2, int(round(cfg.duration * cfg.rate)))
    k = np.arange(int(np.ceil(cfg.duration * command_rate)) + 1)
    t_cmd = k / command_rate
    command = held_at_rate(t_cmd, make_input(cfg.schedule, t_cmd, amplitude=cfg.amplitude, period=cfg.period,
                                             t_start=cfg.t_start))
    u = command.at(np.arange(n, dtype=np.int64) / cfg.rate)   # the source's own formula: elapsed / rate
    plant = generate(cfg, u=u)
    offset = range_um / 2 if offset_um is None else offset_um
    raw = np.empty((n, channels), dtype=np.int64)
    raw[:] = quantize(np.full(1, offset), range_um)[0]
    raw[:, channel - 1] = quantize(offset + plant.y, range_um)
    return SensorRecord(plant, command, raw, channel_field(list(range(1, channels + 1))), range_um)


class CapancdtServer:
    """Serve ``record`` on 127.0.0.1 (ephemeral port unless given), paced in real time or as fast as possible."""

    def __init__(self, record: SensorRecord, rate: float, plan: dict[int, str], spec: FaultSpec, events, *,
                 frames_per_packet: int = FRAMES_PER_PACKET, counter_start: int = 0, realtime: bool = True,
                 seed: int = 0, port: int = 0, stop: threading.Event | None = None, size_first: bool = False) -> None:
        bad = sorted(set(plan.values()) - FAULTS)
        if bad:
            raise ValueError(f"faults {', '.join(bad)} are not supported on transport capancdt "
                             f"(supported: {', '.join(sorted(FAULTS))})")
        self.record, self.rate, self.plan, self.spec, self.events = record, float(rate), plan, spec, events
        self.m = int(frames_per_packet)
        self.counter_start = int(counter_start)
        self.size_first = size_first
        self.realtime = realtime
        self.rng = np.random.default_rng(seed + 15485863)
        self.stop = stop or threading.Event()
        self.ledger = Ledger(samples_per_frame=self.m)
        self.n_frames = record.raw.shape[0]
        self.listener = socket.create_server(("127.0.0.1", port))
        self.port = f"127.0.0.1:{self.listener.getsockname()[1]}"
        self.client: socket.socket | None = None
        self.t0 = 0.0

    # ------------------------------------------------------------ connection
    def accept(self, timeout: float | None = None) -> bool:
        """Wait for the reader (True when connected)."""
        self.listener.settimeout(timeout)
        try:
            self.client, _ = self.listener.accept()
        except (socket.timeout, OSError):
            return False
        self.client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return True

    def _hang_up(self) -> None:
        if self.client is not None:
            try:
                self.client.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self.client.close()
        self.client = None

    def close(self) -> None:
        self._hang_up()
        self.listener.close()

    # ------------------------------------------------------------ packets
    def packet(self, n: int, m: int) -> bytes:
        rec = self.record
        return encode_packet(self.counter_start + n, rec.raw[n:n + m], channels=rec.channel_bits,
                             size_first=self.size_first)

    def corrupt(self, data: bytes, which: int) -> bytes:
        """The packet with one header field made impossible (in turn: magic, frame size, frame count, channels)."""
        b = bytearray(data)
        kind = which % 4
        if kind == 0:
            b[0:4] = b"MEAX"
        elif kind == 1:
            b[24 if self.size_first else 26] ^= 0x02    # bytes per frame no longer 4 * channels
        elif kind == 2:
            b[24:26] = b"\x00\x00"             # zero frames
        else:
            b[12] |= 0x02                      # a channel entry '10': not a valid code
        return bytes(b)

    def garbage(self) -> bytes:
        vals = self.rng.integers(0, 255, int(self.rng.integers(5, 41)))
        vals[vals >= MAGIC[0]] += 1            # never 'M': no false 'MEAS'
        self.ledger.garbage_bytes += vals.size
        return bytes(vals.astype(np.uint8))

    # ------------------------------------------------------------ loop
    def _due(self) -> int:
        if not self.realtime:
            return self.n_frames
        return min(self.n_frames, int((time.monotonic() - self.t0) * self.rate) + 1)

    def run(self) -> Ledger:
        """Stream the record to the connected client (call :meth:`accept` first)."""
        led = self.ledger
        self.t0 = time.monotonic()
        self.events("start", t0_monotonic=self.t0, samples=self.n_frames, rate=self.rate,
                    counter_start=self.counter_start, frames_per_packet=self.m)
        n, p = 0, 0
        while n < self.n_frames and not self.stop.is_set():
            due = self._due()
            out: list[bytes] = []
            while n < self.n_frames:
                kind = self.plan.get(p)
                skip = self.spec.drop_frames if kind == "drop" else 0
                m = min(self.m, self.n_frames - n - skip)
                if m <= 0 or n + skip + m > due:
                    break
                if kind == "disconnect":
                    self._send(out)
                    out = []
                    resume = self._outage(p, n)
                    p += 1 + (resume - n) // self.m    # the plan counts packet slots of the record
                    n = resume
                    break
                if kind == "stall":
                    self._send(out)
                    out = []
                    self.events("stall", frame=p, seconds=self.spec.stall_s)
                    time.sleep(self.spec.stall_s)
                    led.stalls.append(p)
                data = self.packet(n + skip, m)
                if kind == "drop":
                    led.dropped.append(p)
                    led.dropped_samples += skip
                elif kind == "badheader":
                    data = self.corrupt(data, len(led.bad_headers))
                    led.bad_headers.append(p)
                    led.bad_header_samples += m
                elif kind == "garbage":
                    out.append(self.garbage())
                    led.garbage.append(p)
                out.append(data)
                led.frames_sent += 1
                n += skip + m
                p += 1
            if out:
                self._send(out)
            elif self.realtime and n < self.n_frames:
                wake = self.t0 + (n + self.m - 1) / self.rate
                time.sleep(max(0.0, min(wake - time.monotonic(), 0.01)))
            if self.realtime and out:
                led.late_max_s = max(led.late_max_s, time.monotonic() - (self.t0 + (n - 1) / self.rate))
        return led

    def _send(self, out: list[bytes]) -> None:
        if out and self.client is not None:
            try:
                self.client.sendall(b"".join(out))
            except OSError:                    # the reader went away: wait for it, at most until the record ends
                self._hang_up()
                self.events("client_lost")
                self.accept(timeout=self._left())

    def _left(self) -> float:
        """Seconds of the record still to be played (0 when not paced in real time)."""
        if not self.realtime:
            return 0.0
        return max(0.0, self.t0 + self.n_frames / self.rate - time.monotonic())

    def _outage(self, p: int, n: int) -> int:
        """Hang up, stay away ``disconnect_s``, accept the reader again; the frames meanwhile are lost."""
        self._hang_up()
        self.events("disconnect", frame=p, seq=(self.counter_start + n) % COUNTER_MODULUS)
        time.sleep(self.spec.disconnect_s)
        back = self.accept(timeout=30.0)
        self.events("reconnect", port=self.port, connected=back)
        resume = max(n, self._due() if self.realtime else n + int(round(self.spec.disconnect_s * self.rate)))
        resume = min(resume, self.n_frames)
        self.ledger.disconnects.append(p)
        self.ledger.disconnect_lost_samples += resume - n
        return resume

    def drain(self, linger: float) -> None:
        """Give the reader time to take the last packets, then close our side."""
        if self.client is not None:
            try:
                self.client.shutdown(socket.SHUT_WR)
            except OSError:
                pass
        self.stop.wait(linger)



class ControlPort:
    """The controller's control port on 127.0.0.1: ``$CMD\r\n`` text commands, of which the sample-time query
    ``$STI?`` is answered (``$STI?256OK``: the sample time in us) and anything else with ``$UNKNOWN COMMAND``."""

    def __init__(self, rate: float, port: int = 0) -> None:
        self.sample_time_us = 1e6 / float(rate)
        self.listener = socket.create_server(("127.0.0.1", port))
        self.port = self.listener.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def answer(self, line: str) -> str:
        command = line.strip().lstrip("$").strip()
        if command.upper() == "STI?":
            return f"$STI?{self.sample_time_us:.6g}OK\r\n"
        return f"${command}$UNKNOWN COMMAND\r\n"

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:
                return
            threading.Thread(target=self._session, args=(conn,), daemon=True).start()

    def _session(self, conn: socket.socket) -> None:
        with conn:
            buf = b""
            while True:
                try:
                    data = conn.recv(1024)
                except OSError:
                    return
                if not data:
                    return
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    conn.sendall(self.answer(line.decode("ascii", "replace")).encode("ascii"))

    def close(self) -> None:
        self.listener.close()


class _Stopped(Exception):
    """SIGTERM/SIGINT: stop streaming, report the ledger, close the port."""


def serve(args, cfg: PlantConfig, spec: FaultSpec) -> int:
    """``python -m hil_sim --transport capancdt``: print the port, wait for the reader, stream, report the ledger."""
    import os
    import signal

    from .faults import plan
    from .runner import emit_event

    rec = sensor_record(cfg, command_rate=args.command_rate, range_um=args.sensor_range,
                        offset_um=args.sensor_offset, channels=args.sensor_channels, channel=args.sensor_channel)
    if args.command_file:
        rec.command.write(args.command_file)
    m = args.frames_per_packet
    stop = threading.Event()
    armed = [True]

    def on_signal(signum, frame):  # noqa: ARG001 - signal handler signature
        stop.set()
        if armed:
            armed.clear()
            raise _Stopped()       # also breaks out of a send blocked on a full socket

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    try:
        n_packets = -(-rec.raw.shape[0] // m)
        server = CapancdtServer(rec, args.rate, plan(spec, n_packets, args.seed, frame_rate=args.rate / m), spec,
                                emit_event, frames_per_packet=m, counter_start=args.counter_start,
                                realtime=not args.fast, seed=args.seed, port=args.port, stop=stop,
                                size_first=args.size_first)
        control = ControlPort(args.rate, args.control_port)
    except (ValueError, OSError) as exc:
        print(f"hil_sim: {exc}", flush=True, file=__import__("sys").stderr)
        return 2
    print(server.port, flush=True)
    emit_event("ready", port=server.port, transport="capancdt", rate=args.rate, samples=int(rec.raw.shape[0]),
               frames_per_packet=m, model=cfg.model.params(), schedule=cfg.schedule, amplitude=cfg.amplitude,
               command_rate=args.command_rate, command_file=args.command_file, range_um=rec.range_um,
               channels=args.sensor_channels, channel=args.sensor_channel, counter_start=args.counter_start,
               control_port=control.port, size_first=args.size_first,
               noise=cfg.noise, effects=cfg.effects, faults=spec.counts, pid=os.getpid())
    try:
        while not stop.is_set() and not server.accept(timeout=0.2):
            pass
        if not stop.is_set():
            server.run()
            server.drain(args.linger)
    except _Stopped:
        pass
    armed.clear()
    if args.ledger:
        server.ledger.write(args.ledger)
    try:
        emit_event("end", ledger=server.ledger.to_dict(), stopped=stop.is_set())
    except BrokenPipeError:
        pass
    server.close()
    control.close()
    return 0
