"""Closed loop: the amplifier's DAC takes its input from command frames sent by the reader.

Instead of playing a schedule computed up front, the plant is stepped in real
time, sample by sample in small batches (``varying_plant.PlantStream``: exact
for a zero-order-held input, alpha and b may drift). Sample n applies the
command the reader sent *for sample n* (``io.frames.encode_command``: the
binary frame with the command status bit, parsed by the same ``BinaryParser``
as the samples); a command that has not arrived when its sample is due is
replaced by the last applied one (a DAC holds its value) and counted as late.
Each sample goes back in the usual binary frame ``(seq, u applied, y)``.

Like the schedule-playing plant, a busy machine delays samples rather than
losing them: a sample whose command has not arrived waits for it up to
``command_timeout`` past its due time (the ledger's ``late_max_s`` says how far
the plant fell behind); only then does the DAC hold its last value.

With ``hysteresis`` (a Prandtl-Ishlinskii loop, ``play_stage.PlayStage``) the DAC's
command goes through the actuator's loop before the creep plant; the frame reports
the command applied, as a real amplifier's monitor does.

The stream starts with the first command frame (any other byte before it,
such as a reader's start command, is ignored).
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from creep_online.io.frames import STATUS_COMMAND, BinaryParser, encode_binary
from creep_online.model import CreepModel

from .play_stage import PlayStage
from .varying_plant import PlantStream

#: Largest number of samples produced in one go (bounds the pacing jitter).
BATCH = 64


@dataclass
class CommandLedger:
    """What the closed-loop plant saw of the commands."""

    commands: int = 0         # command frames received for a sample still to come
    stale: int = 0            # command frames for a sample already produced (arrived too late)
    late_samples: int = 0     # samples that held the previous command because theirs had not arrived
    other_frames: int = 0     # good frames without the command bit
    crc_errors: int = 0
    garbage_bytes: int = 0
    late_max_s: float = 0.0   # how far behind real time the plant fell (machine load)

    def to_dict(self) -> dict:
        return dict(self.__dict__)


class CommandRunner:
    """Real-time plant driven by command frames; ``run()`` returns the ledger."""

    def __init__(self, model: CreepModel, rate: float, n_samples: int, link, *, noise: float = 2e-4,
                 adc_bits: int = 20, adc_range: float = 10.0, seed: int = 0, drift: tuple[float, float] = (0.0, 0.0),
                 events=None, stop: threading.Event | None = None, start_timeout: float = 60.0,
                 command_timeout: float = 1.0, hysteresis: dict | None = None) -> None:
        self.model, self.rate, self.n = model, float(rate), int(n_samples)
        self.link = link
        self.noise, self.lsb, self.half = noise, adc_range / 2.0 ** adc_bits, adc_range / 2
        self.rng = np.random.default_rng(seed)
        t = np.arange(self.n) / self.rate
        span = max(self.n / self.rate, 1e-9)
        self.alpha = model.alpha * (1.0 + drift[0] * t / span)
        self.b = model.b * (1.0 + drift[1] * t / span)
        self.events = events or (lambda *a, **k: None)
        self.stop = stop or threading.Event()
        self.start_timeout = start_timeout
        self.command_timeout = command_timeout
        self.parser = BinaryParser(self.rate)
        self.cmd = np.full(self.n, math.nan)
        self.ledger = CommandLedger()
        self.stream = PlantStream(1.0 / self.rate, model.alpha, model.a1, model.a2, model.b,
                                  horizon_s=max(3600.0, 10 * span))
        self.stage = None if hysteresis is None else PlayStage(hysteresis)
        self.produced = 0
        self.last_u = 0.0

    def _take_commands(self, timeout: float) -> None:
        data = self.link.read_available(timeout)
        if not data:
            return
        led = self.ledger
        for s in self.parser.feed(data):
            if not s.status & STATUS_COMMAND:
                led.other_frames += 1
            elif self.produced <= s.seq < self.n:
                self.cmd[s.seq] = s.u
                led.commands += 1
            else:
                led.stale += 1
        st = self.parser.stats
        led.crc_errors, led.garbage_bytes = st.crc_errors, st.garbage_bytes

    def wait_first_command(self) -> bool:
        """Block until a command frame has arrived (the reader is ready), or timeout/stop."""
        end = time.monotonic() + self.start_timeout
        while not self.stop.is_set() and time.monotonic() < end:
            self._take_commands(0.05)
            if self.ledger.commands:
                return True
        return False

    def _produce(self, upto: int) -> None:
        """Samples produced .. upto-1: apply their commands (or hold), step the plant, send the frames."""
        k0 = self.produced
        u = self.cmd[k0:upto].copy()
        for i in range(u.size):              # a DAC holds its last value when no new one came
            if math.isnan(u[i]):
                u[i] = self.last_u
                self.ledger.late_samples += 1
            self.last_u = u[i]
        v = u if self.stage is None else self.stage.step_block(u)
        y = self.stream.step_block(v, self.alpha[k0:upto], self.b[k0:upto])
        if self.noise > 0:
            y = y + self.noise * self.rng.standard_normal(y.size)
        y = np.clip(np.round(y / self.lsb) * self.lsb, -self.half, self.half - self.lsb)
        self.link.write(b"".join(encode_binary(k0 + i, float(u[i]), float(y[i])) for i in range(u.size)))
        self.produced = upto

    def run(self) -> CommandLedger:
        self.t0 = time.monotonic()
        self.events("start", t0_monotonic=self.t0, samples=self.n, frames=self.n, samples_per_frame=1,
                    rate=self.rate, mode="command")
        led = self.ledger
        while self.produced < self.n and not self.stop.is_set():
            now = time.monotonic()
            due = min(self.n, int((now - self.t0) * self.rate) + 1)
            if due <= self.produced:
                wake = self.t0 + self.produced / self.rate
                self._take_commands(max(0.0, min(wake - now, 0.002)))
                continue
            self._take_commands(0.0)
            ready = self._commands_ready(min(due, self.produced + BATCH))
            if ready == self.produced:       # the next command is missing: wait for it, then hold
                if now - (self.t0 + self.produced / self.rate) < self.command_timeout:
                    self._take_commands(0.001)
                    continue
                ready = self.produced + 1
            led.late_max_s = max(led.late_max_s, now - (self.t0 + (ready - 1) / self.rate))
            self._produce(ready)
        return led

    def _commands_ready(self, upto: int) -> int:
        """The first sample in produced..upto-1 without a command (upto if all have one)."""
        missing = np.flatnonzero(np.isnan(self.cmd[self.produced:upto]))
        return self.produced + int(missing[0]) if missing.size else upto
