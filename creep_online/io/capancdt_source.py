"""capaNCDT source: the position stream of a Micro-Epsilon capaNCDT 6200-style controller over TCP.

``capancdt:HOST:PORT?command=FILE&range=200&channel=1`` connects to the
controller's data port (10001 unless given), asks its control port (Telnet,
23 unless ``control=`` says otherwise) for the sample time (``$STI?``,
answered as ``$STI?256OK``: 256 us) unless ``rate=`` gives the data rate,
decodes its ``MEAS`` packets
(``capancdt_frames``), scales the chosen channel's 24-bit values by the
measuring range (y in um), and pairs every frame with the actuator command
zero-order held at that frame's instant (``command_schedule``): the sensor
does not carry the command, so it comes from the schedule file the
excitation was played from. The sample time and the sequence number come
from the controller's frame counter, so a counter jump is a run of frames the
controller dropped: delivered to the estimator as a gap, never interpolated.

When the connection closes or fails the source says so once and reconnects
with backoff (``ReconnectingSource``); the controller's counter keeps running
meanwhile, so the frames of the outage are counted as missing and the
command stays aligned.
"""
from __future__ import annotations

import re
import select
import socket
import time
from typing import Any

from ..errors import DataError, TransportError
from .capancdt_frames import COUNTER_MODULUS, CapancdtParser, Identity, Packet, channel_list, scale
from .command_schedule import CommandSchedule
from .frames import RawSample
from .source_options import (IDLE_TIMEOUT, RECONNECT, RECONNECT_TIMEOUT, RECONNECT_TIMEOUT_S, STALL, WINDOW, Option,
                             nonempty, port_number, positive, whole)
from .sources import ReconnectingSource

#: The controller's data port (as public DT6220 scripts use it) and fastest data rate (sample time 256 us).
DATA_PORT = 10001
DATA_RATE = 3906.25
#: The controller's control port (Telnet), where ``$STI?`` asks for the sample time in us.
CONTROL_PORT = 23
_STI_ANSWER = re.compile(r"STI\?\s*,?\s*([0-9]+(?:\.[0-9]*)?)\s*OK")
#: Measuring range assumed when none is given: a CS02 sensor (200 um).
RANGE_UM = 200.0


class CapancdtSource(ReconnectingSource):
    """Samples (u from the command schedule, y = distance in um) from a capaNCDT-style TCP stream."""

    link = "connection"
    options = (WINDOW.with_default(0), STALL, RECONNECT, RECONNECT_TIMEOUT, IDLE_TIMEOUT) + (
        Option("command", nonempty, None, "t,u file of the actuator command, zero-order held (required)", path=True),
        Option("rate", positive, None, "the controller's data rate in Hz (default: asked on the control port)"),
        Option("control", port_number, CONTROL_PORT, "the controller's control (Telnet) port, asked for the sample time"),
        Option("channel", whole(1), 1, "the channel that measures the actuator (1-based)"),
        Option("range", positive, RANGE_UM, "the sensor's measuring range in um", keyword="range_um"),
        Option("counter0", whole(0), None, "frame counter at the command's t = 0 (default: the first frame received)"),
        Option("timeout", positive, 2.0, "seconds to wait for the TCP connection", keyword="connect_timeout"),
    )
    target_label = "host"

    @classmethod
    def from_spec(cls, spec: str, target: str, **kwargs: Any) -> "CapancdtSource":
        """``HOST[:PORT]`` -> CapancdtSource(host, port)."""
        host, sep, port = target.rpartition(":")
        if not sep:
            return cls(target, DATA_PORT, **kwargs)
        try:
            number = int(port)
        except ValueError:
            raise DataError(f"{spec}: the port after the host must be a number, got {port!r}") from None
        return cls(host, number, **kwargs)

    def __init__(self, host: str, port: int = DATA_PORT, *, command: str | CommandSchedule | None = None,
                 rate: float | None = None, control: int = CONTROL_PORT, channel: int = 1,
                 range_um: float = RANGE_UM,
                 counter0: int | None = None, connect_timeout: float = 2.0, reconnect: bool = True,
                 reconnect_timeout: float | None = RECONNECT_TIMEOUT_S, window: int = 0, stall: float = 0.5, **kw) -> None:
        name = f"capancdt:{host}:{port}"
        if command is None:
            raise DataError(f"{name}: the sensor streams only the position; give the actuator command as a t,u "
                            "schedule file, e.g. ?command=excitation.csv (docs/transports.md)")
        if (rate is not None and not rate > 0) or not range_um > 0 or channel < 1:
            raise DataError(f"{name}: rate and range must be > 0 and channel >= 1")
        super().__init__(window=window, modulus=COUNTER_MODULUS, rate=rate, t_from_seq=True, stall=stall,
                         reconnect=reconnect, reconnect_timeout=reconnect_timeout, **kw)
        self.name = name
        self.host, self.port = host, int(port)
        self.schedule = command if isinstance(command, CommandSchedule) else CommandSchedule.load(command)
        self.channel = int(channel)
        self.range_um = float(range_um)
        self.counter0 = counter0
        self.connect_timeout = float(connect_timeout)
        self.parser = CapancdtParser(stats=self.stats.parser)
        self._column: tuple[Identity, int] | None = None
        self._sock: socket.socket | None = None
        try:
            self._open()
        except OSError as exc:
            raise TransportError(f"{name}: cannot connect ({_reason(exc)})") from None
        self.control = int(control)
        if rate is None:
            try:
                self.rate = read_data_rate(host, self.control, self.connect_timeout)
            except (OSError, ValueError) as exc:
                self._close_socket()
                raise TransportError(f"{name}: no data rate given and the control port {host}:{self.control} did "
                                     f"not tell it ({_reason(exc)}); give ?rate=HZ or ?control=PORT") from None

    # -------------------------------------------------------------- link
    def _open(self) -> None:
        sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
        sock.setblocking(False)
        self._sock = sock

    def _close_socket(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError:
                pass
        self._sock = None

    def _close_link(self) -> None:
        self._close_socket()
        self.parser.restart()

    @property
    def link_up(self) -> bool:
        return self._sock is not None

    # -------------------------------------------------------------- reading
    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        if self._sock is None and not self._try_reconnect(timeout):
            return []
        try:
            ready, _, _ = select.select([self._sock], [], [], timeout)
            if not ready:
                return []
            data = self._sock.recv(1 << 16)
        except OSError as exc:
            self._lost(_reason(exc))
            return []
        if not data:
            self._lost("closed by the controller")
            return []
        out: list[RawSample] = []
        for packet in self.parser.feed(data):
            out += self._samples(packet)
        return out

    def _samples(self, packet: Packet) -> list[RawSample]:
        """The packet's frames as samples: y from our channel, u held from the schedule, seq = counter.

        Plain Python per frame: a packet holds a few frames, where numpy's per-call overhead dominates.
        """
        if self.counter0 is None:
            self.counter0 = packet.counter
        first = packet.counter
        c0, rate, lsb = self.counter0, self.rate, scale(1.0, self.range_um)
        held = self.schedule.at_time
        out = []
        for j, raw in enumerate(packet.values[:, self._channel_column()].tolist()):
            c = (first + j) % COUNTER_MODULUS
            out.append(RawSample(c, 0.0, held(((c - c0) % COUNTER_MODULUS) / rate), raw * lsb, 0))
        return out

    def _channel_column(self) -> int:
        """Where our channel sits in a frame (present channels, lowest first) for the locked controller."""
        ident = self.parser.identity
        if self._column is None or self._column[0] != ident:
            present = channel_list(ident.channels)
            if self.channel not in present:
                raise DataError(f"{self.name}: channel {self.channel} is not in the stream "
                                f"(channels present: {', '.join(map(str, present))})")
            self._column = (ident, present.index(self.channel))
        return self._column[1]

    def close(self) -> None:
        self._close_socket()
        super().close()


def read_data_rate(host: str, port: int = CONTROL_PORT, timeout: float = 2.0) -> float:
    """The data rate in Hz from the controller's sample time, asked on its control port (``$STI?``).

    The answer echoes the command and ends with ``OK`` (``$STI?256OK``, in
    us); anything before it (a greeting, Telnet negotiation bytes) is
    skipped. ValueError when the answer is not that, OSError when the port
    does not answer within ``timeout`` seconds.
    """
    deadline = time.monotonic() + timeout
    with socket.create_connection((host, port), timeout=timeout) as sock:
        sock.sendall(b"$STI?\r\n")
        text = ""
        while True:
            found = _STI_ANSWER.search(text)
            if found:
                sample_time_us = float(found.group(1))
                if not sample_time_us > 0:
                    raise ValueError(f"sample time {found.group(1)} us")
                return 1e6 / sample_time_us
            if "UNKNOWN COMMAND" in text or "WRONG PARAMETER" in text:
                raise ValueError(f"it answered {text.strip()[-60:]!r}")
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            try:
                data = sock.recv(1024)
            except socket.timeout:
                raise OSError("no answer to $STI?") from None
            if not data:
                raise OSError("closed without answering $STI?")
            text += data.decode("ascii", errors="ignore")


def _reason(exc: BaseException) -> str:
    msg = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return str(msg).splitlines()[0][:120]
