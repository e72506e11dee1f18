"""CAN source: any python-can interface, signals decoded with cantools from the DBC.

``can:slcan:/dev/ttyACM0`` (or the simulated plant's pty), ``can:virtual:NAME``
(python-can's in-process bus), ``can:socketcan:can0``, ``can:pcan:PCAN_USBBUS1``
... Frames are described by ``creep_online/data/amplifier.dbc`` (or
``?dbc=FILE`` with the same message and signal names). CAN frames carry a
sample counter, not a time, so the sample rate must be given (``?rate=HZ``).

When the adapter disappears (python-can raises, the serial device is gone) the
source says so once and re-creates the bus with exponential backoff, or raises
:class:`TransportError` if ``reconnect=0``.

``CanSource(bus=BUS, rate=...)`` reads a bus the application opened and owns:
the source never shuts it down and cannot reopen it (a lost bus is a
``TransportError``). An application that already runs a ``can.Notifier`` on
its bus gives it ``can_listener.EstimatorListener`` instead: both decode and
order the frames with ``CanMessages``.
"""
from __future__ import annotations


from typing import Any, Callable

from ..errors import DataError, TransportError
from .can_frames import COUNTER_MODULUS, CanDecoder
from .frames import RawSample
from .source_options import DBC, RATE, RECONNECT_TIMEOUT_S, WINDOW, Option, flag, whole
from .sources import ReconnectingSource, Sample, SampleSource

#: Frames taken from the bus per read() call at most (bounds the work per call).
BATCH = 512


def _can():
    try:
        import can
    except ImportError:  # pragma: no cover - depends on the environment
        raise TransportError("CAN sources need python-can: pip install 'creep_online[can]'") from None
    return can


class CanSource(ReconnectingSource):
    """Samples from a live CAN bus (``can:INTERFACE:CHANNEL?rate=10000&...``)."""

    link = "adapter"
    options = tuple(WINDOW.with_default(32) if o is WINDOW else o for o in ReconnectingSource.options) + (
        RATE,
        DBC,
        Option("bitrate", whole(1), None, "bus bit rate (slcan default 1 Mbit/s)"),
        Option("fd", flag, False, "CAN FD"),
    )
    target_label = "interface and channel"

    @classmethod
    def from_spec(cls, spec: str, target: str, **kwargs: Any) -> "CanSource":
        """``INTERFACE:CHANNEL`` -> CanSource(interface, channel)."""
        if ":" not in target:
            raise DataError(f"{spec!r}: CAN spec needs an interface and a channel, e.g. can:slcan:/dev/ttyACM0")
        interface, channel = target.split(":", 1)
        return cls(interface, channel, **kwargs)

    def __init__(self, interface: str | None = None, channel: str | None = None, *, bus: Any = None,
                 rate: float | None = None, dbc: str | None = None,
                 bitrate: int | None = None, fd: bool = False, reconnect: bool = True,
                 reconnect_timeout: float | None = RECONNECT_TIMEOUT_S, window: int = 32, stall: float = 0.5,
                 bus_kwargs: dict | None = None, **kw) -> None:
        """Open ``interface``/``channel`` (``can.Bus``), or read ``bus``, a python-can bus the caller owns."""
        if (bus is None) == (interface is None or channel is None):
            raise DataError("CanSource needs either an interface and a channel, or bus= (a python-can bus)")
        super().__init__(window=window, modulus=COUNTER_MODULUS, rate=rate, t_from_seq=True, stall=stall,
                         reconnect=reconnect and bus is None, reconnect_timeout=reconnect_timeout, **kw)
        self.name = f"can:{interface}:{channel}" if bus is None else f"can:{getattr(bus, 'channel_info', 'bus')}"
        if not rate:
            example = f"can:{interface}:{channel}?rate=10000" if bus is None else "CanSource(bus=bus, rate=10000)"
            raise TransportError(f"{self.name}: CAN frames carry a counter, not a time: give the sample rate, "
                                 f"e.g. {example}")
        self.interface, self.channel = interface, channel
        self.bitrate, self.fd = bitrate, fd
        self.bus_kwargs = dict(bus_kwargs or {})
        self.decoder = CanDecoder(dbc, stats=self.stats.parser)
        self.owns_bus = bus is None
        self.bus = bus
        if bus is not None:
            self.link = "application's bus"      # (lost for good: only its owner can reopen it)
            return
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

    def _close_link(self) -> None:
        if self.bus is not None and self.owns_bus:
            try:
                self.bus.shutdown()
            except Exception:  # noqa: BLE001 - a dead adapter may fail to close; it is gone either way
                pass
        self.bus = None

    @property
    def link_up(self) -> bool:
        return self.bus is not None

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        if self.bus is None and not self._try_reconnect(timeout):
            return []
        out: list[RawSample] = []
        decoder = self.decoder
        try:
            msg = self.bus.recv(timeout)
            n = 0
            while msg is not None:
                out += decode_message(decoder, msg)
                n += 1
                if n >= BATCH:
                    break
                msg = self.bus.recv(0.0)
        except Exception as exc:  # noqa: BLE001 - python-can/pyserial raise several types when the device goes
            self._lost(_reason(exc))
        return out

    def close(self) -> None:
        self._close_link()
        super().close()


class CanMessages(SampleSource):
    """Samples from CAN messages handed in one at a time (a ``can.Listener``'s), decoded and ordered as
    ``CanSource`` does: the DBC, the counters, the reorder ``window``, lost, duplicated and late frames counted.

    ``samples_of(msg)`` returns the samples that message completes (none while a reordered frame is awaited,
    several when it fills a hole); ``flush()`` the ones still held at the end.
    """

    def __init__(self, *, rate: float, dbc: str | None = None, window: int = 32, stall: float = 0.5,
                 name: str = "can:listener", on_event: Callable[[str], None] | None = None) -> None:
        super().__init__(window=window, modulus=COUNTER_MODULUS, rate=rate, t_from_seq=True, stall=stall,
                         on_event=on_event)
        self.name = name
        if not rate:
            raise TransportError(f"{name}: CAN frames carry a counter, not a time: give the sample rate, "
                                 f"e.g. rate=10000")
        self.decoder = CanDecoder(dbc, stats=self.stats.parser)
        self._raw: list[RawSample] = []

    def samples_of(self, msg: Any) -> list[Sample]:
        """The good samples, in order, that ``msg`` (a ``can.Message``) makes available."""
        self._raw = decode_message(self.decoder, msg)
        return self.read(0.0)

    def flush(self) -> list[Sample]:
        """The samples the reorder window still holds (the stream ended)."""
        return self._deliver(self.tracker.flush(), 0.0)

    def _read_raw(self, timeout: float) -> list[RawSample]:
        raw, self._raw = self._raw, []
        return raw


def decode_message(decoder: CanDecoder, msg: Any) -> list[RawSample]:
    """The raw samples of one ``can.Message`` (error and remote frames carry none)."""
    if msg.is_error_frame or msg.is_remote_frame:
        return []
    return decoder.decode(msg.arbitration_id, msg.data)


def _reason(exc: BaseException) -> str:
    msg = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return str(msg).splitlines()[0][:120]
