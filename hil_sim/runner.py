"""The plant's send loop: encode frames, inject faults, pace them in real time, keep the ledger.

Frame ``f`` (samples ``f*spf .. f*spf+spf-1``) is released once its last
sample's time ``t0 + n / rate`` has come (``time.monotonic``, which is the
same clock in every process on Linux, so a reader can measure latency from
the plant's sample time). With ``realtime=False`` frames go as fast as the
link takes them.
"""
from __future__ import annotations

import json
import sys
import threading
import time

import numpy as np

from creep_online.io import can_frames as cf
from creep_online.io.frames import encode_ascii, encode_binary

from .faults import FaultSpec, Ledger
from .links import PtyLink, VirtualLink, slcan_text

TRANSPORTS = ("serial-ascii", "serial-binary", "slcan", "virtual")
CAN_FRAMES = ("sample", "pair", "block")
SERIAL_FAULTS = {"garbage", "bitflip", "drop", "dup", "reorder", "stall", "disconnect"}
CAN_FAULTS = {"drop", "dup", "reorder", "stall", "disconnect"}
INPUT_REPEAT = 50     # AMP_INPUT is repeated every this many pair frames


def emit_event(event: str, **fields) -> None:
    """One JSON line on stdout (the plant's event log); flushed at once."""
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


class Runner:
    def __init__(self, rec, rate: float, transport: str, link, plan: dict[int, str], spec: FaultSpec,
                 *, can_frame: str = "pair", realtime: bool = True, seed: int = 0,
                 events=emit_event, stop: threading.Event | None = None, resume=None) -> None:
        self.rec, self.rate, self.transport, self.link = rec, float(rate), transport, link
        self.plan, self.spec = plan, spec
        self.realtime = realtime
        self.resume = resume          # called after a reconnect: wait for the reader's start command
        self.events = events
        self.stop = stop or threading.Event()
        self.rng = np.random.default_rng(seed + 104729)
        self.is_can = transport in ("slcan", "virtual")
        self.can_frame = can_frame if self.is_can else None
        self.spf = {"sample": 1, "pair": 2, "block": cf.BLOCK_SAMPLES}[can_frame] if self.is_can else 1
        n = rec.t.size
        self.n_samples = n - n % self.spf
        self.n_frames = self.n_samples // self.spf
        allowed = CAN_FAULTS if self.is_can else SERIAL_FAULTS
        bad = sorted({k for k in plan.values()} - allowed)
        if bad:
            raise ValueError(f"faults {', '.join(bad)} are not supported on transport {transport} "
                             f"(supported: {', '.join(sorted(allowed))})")
        if transport == "virtual" and "disconnect" in plan.values():
            raise ValueError("a virtual bus cannot disconnect")
        self.ledger = Ledger(samples_per_frame=self.spf)
        self.t0 = 0.0
        if self.can_frame == "pair":
            changes = np.concatenate([[0], np.cumsum(np.diff(rec.u) != 0)])
            self.gen = (changes % 16).astype(int)
            self._gen_sent = -1
        self._u = rec.u.tolist()
        self._y = rec.y.tolist()
        self._t = rec.t.tolist()

    # ------------------------------------------------------------ encoding
    def encode(self, f: int) -> tuple[list, list]:
        """(unfaultable preamble, data items) of frame f."""
        n = f * self.spf
        tr = self.transport
        if tr == "serial-ascii":
            return [], [encode_ascii(n, self._t[n], self._u[n], self._y[n])]
        if tr == "serial-binary":
            return [], [encode_binary(n, self._u[n], self._y[n])]
        pre: list = []
        if self.can_frame == "sample":
            msg = cf.encode_sample(n, self._u[n], self._y[n])
        elif self.can_frame == "block":
            k = cf.BLOCK_SAMPLES
            msg = cf.encode_block(n, 0, self._u[n:n + k], self._y[n:n + k])
        else:
            g0, g1 = int(self.gen[n]), int(self.gen[n + 1])
            for g, i in ((g0, n), (g1, n + 1)):
                if g != self._gen_sent or f % INPUT_REPEAT == 0:
                    pre.append(cf.encode_input(g, self._u[i]))
                    self._gen_sent = g
            msg = cf.encode_pair(n, g0, g1, self._y[n], self._y[n + 1])
        if tr == "slcan":
            return [slcan_text(*m) for m in pre], [slcan_text(*msg)]
        return pre, [msg]

    def _flip(self, frame: bytes) -> bytes:
        """One bit flipped where it cannot change the framing (payload/CRC, not sync, length or EOL)."""
        b = bytearray(frame)
        if self.transport == "serial-binary":
            i = int(self.rng.integers(4, len(b)))
        else:
            i = int(self.rng.integers(0, len(b) - 1))   # anything but the newline
            while b[i] == ord("*"):
                i = int(self.rng.integers(0, len(b) - 1))
        b[i] ^= 1 << int(self.rng.integers(0, 8))
        return bytes(b)

    def _garbage(self) -> bytes:
        n = int(self.rng.integers(5, 41))
        if self.transport == "serial-binary":
            vals = self.rng.integers(0, 255, n)
            vals[vals >= 0xAA] += 1                      # never 0xAA: no false sync words
            self.ledger.garbage_bytes += n
            return bytes(vals.astype(np.uint8))
        pool = np.array([c for c in range(0x20, 0x7F) if c != ord("*")], dtype=np.uint8)
        self.ledger.garbage_bytes += n + 1
        return bytes(self.rng.choice(pool, n)) + b"\n"

    # ------------------------------------------------------------ output
    def _send(self, items: list) -> None:
        if not items:
            return
        if isinstance(self.link, VirtualLink):
            for m in items:
                self.link.send(*m)
        else:
            self.link.write(b"".join(items))

    def _due_frames(self, now: float) -> int:
        """Frames whose last sample time has come."""
        k = int(((now - self.t0) * self.rate + 1.0) / self.spf)
        return min(self.n_frames, max(0, k))

    def _disconnect(self, f: int) -> int:
        """Hang up, stay away disconnect_s, come back on a new pty; return the next frame to send.

        The frames the plant produced while the line was down (from the hang-up
        until the reader is back) are lost, in real time and in fast mode alike.
        """
        link: PtyLink = self.link
        link.drain(timeout=5.0)
        t_down = time.monotonic()
        link.close()
        self.events("disconnect", frame=f, seq=f * self.spf)
        time.sleep(self.spec.disconnect_s)
        link.reopen()
        if self.transport == "slcan":
            self.events("reconnect", port=link.port, tty=link.tty, waiting="open command")
            link.wait_for(b"O\r", timeout=30.0, reply=b"\r")
        else:
            self.events("reconnect", port=link.port, tty=link.tty)
            if self.resume is not None:
                self.resume()
        lost = max(1, int(round((time.monotonic() - t_down) * self.rate / self.spf)))
        nxt = min(f + lost, self.n_frames)
        self.ledger.disconnects.append(f)
        self.ledger.disconnect_lost_samples += (nxt - f) * self.spf
        return nxt

    # ------------------------------------------------------------ loop
    def run(self) -> Ledger:
        led = self.ledger
        self.t0 = time.monotonic()
        self.events("start", t0_monotonic=self.t0, samples=self.n_samples, frames=self.n_frames,
                    samples_per_frame=self.spf, rate=self.rate)
        f = 0
        held: list | None = None
        batch = 512
        while f < self.n_frames and not self.stop.is_set():
            if self.realtime:
                now = time.monotonic()
                upto = self._due_frames(now)
                if upto <= f:
                    wake = self.t0 + ((f + 1) * self.spf - 1) / self.rate
                    time.sleep(max(0.0, min(wake - now, 0.01)))
                    continue
                lag = now - (self.t0 + ((f + 1) * self.spf - 1) / self.rate)
                led.late_max_s = max(led.late_max_s, lag)
                upto = min(upto, f + batch)
            else:
                upto = min(self.n_frames, f + batch)
            out: list = []
            g = f
            while g < upto:
                kind = self.plan.get(g)
                pre, items = self.encode(g)
                out += pre
                if kind is None:
                    out += items
                elif kind == "drop":
                    led.dropped.append(g)
                elif kind == "dup":
                    out += items + items
                    led.duplicated.append(g)
                elif kind == "reorder":
                    if g + 1 < self.n_frames:
                        held = items
                        led.reordered.append(g)
                    else:
                        out += items
                elif kind == "bitflip":
                    out.append(self._flip(items[0]))
                    led.bitflips.append(g)
                elif kind == "garbage":
                    out.append(self._garbage())
                    out += items
                    led.garbage.append(g)
                elif kind == "stall":
                    self._send(out)
                    out = []
                    self.events("stall", frame=g, seconds=self.spec.stall_s)
                    time.sleep(self.spec.stall_s)
                    out += items
                    led.stalls.append(g)
                elif kind == "disconnect":
                    self._send(out)
                    out = []
                    g = self._disconnect(g)
                    upto = g            # re-evaluate pacing after the outage
                    continue
                if held is not None and kind != "reorder":
                    out += held
                    held = None
                led.frames_sent += 1 if kind != "drop" else 0
                g += 1
            self._send(out)
            f = g
        return led


def run_virtual_plant(rec, rate: float, channel: str, *, can_frame: str = "block", faults: str = "",
                      realtime: bool = True, seed: int = 0) -> tuple[threading.Thread, Runner]:
    """Start the plant on python-can's virtual bus in a thread of this process (for tests and notebooks)."""
    from .faults import plan as make_plan
    spec = FaultSpec.parse(faults)
    link = VirtualLink(channel)
    spf = {"sample": 1, "pair": 2, "block": cf.BLOCK_SAMPLES}[can_frame]
    runner = Runner(rec, rate, "virtual", link, make_plan(spec, rec.t.size // spf, seed, frame_rate=rate / spf), spec,
                    can_frame=can_frame, realtime=realtime, seed=seed, events=lambda *a, **k: None)

    def target() -> None:
        try:
            runner.run()
        finally:
            link.close()

    th = threading.Thread(target=target, name=f"hil_sim-virtual-{channel}", daemon=True)
    return th, runner

