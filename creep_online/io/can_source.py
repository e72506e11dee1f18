"""CAN source: any python-can interface, signals decoded with cantools from the DBC.

``can:slcan:/dev/ttyACM0`` (or the simulated plant's pty), ``can:virtual:NAME``
(python-can's in-process bus), ``can:socketcan:can0``, ``can:pcan:PCAN_USBBUS1``
... Frames are described by ``creep_online/data/amplifier.dbc`` (or
``?dbc=FILE`` with the same message and signal names). CAN frames carry a
sample counter, not a time, so the sample rate must be given (``?rate=HZ``).

When the adapter disappears (python-can raises, the serial device is gone) the
source says so once and re-creates the bus with exponential backoff, or raises
:class:`TransportError` if ``reconnect=0``.
"""
from __future__ import annotations

import time

from .can_frames import COUNTER_MODULUS, CanDecoder
from .frames import RawSample
from .sources import SampleSource, TransportError

#: Frames taken from the bus per read() call at most (bounds the work per call).
BATCH = 512


def _can():
    try:
        import can
    except ImportError:  # pragma: no cover - depends on the environment
        raise TransportError("CAN sources need python-can: pip install 'creep_online[can]'") from None
    return can


class CanSource(SampleSource):
    """Samples from a live CAN bus."""

    def __init__(self, interface: str, channel: str, *, rate: float | None = None, dbc: str | None = None,
                 bitrate: int | None = None, fd: bool = False, reconnect: bool = True,
                 reconnect_timeout: float | None = None, window: int = 32, stall: float = 0.5,
                 bus_kwargs: dict | None = None, **kw) -> None:
        kw.pop("format", None)
        kw.pop("start", None)
        super().__init__(window=window, modulus=COUNTER_MODULUS, rate=rate, t_from_seq=True, stall=stall, **kw)
        self.name = f"can:{interface}:{channel}"
        if not rate:
            raise TransportError(f"{self.name}: CAN frames carry a counter, not a time: give the sample rate, "
                                 f"e.g. can:{interface}:{channel}?rate=10000")
        self.interface, self.channel = interface, channel
        self.bitrate, self.fd = bitrate, fd
        self.bus_kwargs = dict(bus_kwargs or {})
        self.reconnect, self.reconnect_timeout = bool(reconnect), reconnect_timeout
        self.decoder = CanDecoder(dbc, stats=self.stats.parser)
        self.bus = None
        self._down_since: float | None = None
        self._next_try = 0.0
        self._backoff = 0.05
        try:
            self._open()
        except TransportError:
            raise
        except Exception as exc:  # noqa: BLE001 - python-can raises many types at open
            raise TransportError(f"{self.name}: cannot open ({_reason(exc)})") from None

    def _open(self) -> None:
        can = _can()
        kw = dict(self.bus_kwargs)
        if self.interface == "slcan":
            kw.setdefault("sleep_after_open", 0)
            kw.setdefault("bitrate", self.bitrate or 1_000_000)
        elif self.interface == "virtual":
            kw.setdefault("receive_own_messages", False)
        else:
            if self.bitrate:
                kw.setdefault("bitrate", self.bitrate)
            if self.fd:
                kw.setdefault("fd", True)
        self.bus = can.Bus(interface=self.interface, channel=self.channel, **kw)

    def _lost(self, why: str) -> None:
        self._shutdown()
        self.stats.disconnects += 1
        if not self.reconnect:
            self.event(f"adapter disappeared ({why}); not reconnecting")
            raise TransportError(f"{self.name}: adapter disappeared ({why}); reconnect is off")
        self.event(f"adapter disappeared ({why}); reconnecting with backoff")
        self._down_since = time.monotonic()
        self._next_try = self._down_since + 0.05
        self._backoff = 0.05

    def _shutdown(self) -> None:
        if self.bus is not None:
            try:
                self.bus.shutdown()
            except Exception:  # noqa: BLE001 - a dead adapter may fail to close; it is gone either way
                pass
        self.bus = None

    def _try_reconnect(self, timeout: float) -> bool:
        now = time.monotonic()
        if self.reconnect_timeout is not None and now - self._down_since > self.reconnect_timeout:
            raise TransportError(f"{self.name}: adapter did not come back within {self.reconnect_timeout:g} s")
        if now < self._next_try:
            time.sleep(min(timeout, self._next_try - now))
            return False
        try:
            self._open()
        except Exception:  # noqa: BLE001 - not back yet
            self._backoff = min(self._backoff * 2, 2.0)
            self._next_try = time.monotonic() + self._backoff
            return False
        self.stats.reconnects += 1
        self.tracker.expect_restart()
        self.event(f"reconnected after {time.monotonic() - self._down_since:.2f} s")
        self._down_since = None
        return True

    @property
    def link_up(self) -> bool:
        return self.bus is not None

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        if self.bus is None and not self._try_reconnect(timeout):
            return []
        out: list[RawSample] = []
        decode = self.decoder.decode
        try:
            msg = self.bus.recv(timeout)
            n = 0
            while msg is not None:
                if not msg.is_error_frame and not msg.is_remote_frame:
                    out += decode(msg.arbitration_id, msg.data)
                n += 1
                if n >= BATCH:
                    break
                msg = self.bus.recv(0.0)
        except Exception as exc:  # noqa: BLE001 - python-can/pyserial raise several types when the device goes
            self._lost(_reason(exc))
        return out

    def close(self) -> None:
        self._shutdown()
        super().close()


def _reason(exc: BaseException) -> str:
    msg = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return str(msg).splitlines()[0][:120]
