"""Serial source: any pyserial port or URL, ASCII or binary frames, reconnect with backoff.

A POSIX port (``/dev/tty*``, a pseudo-terminal) is read with ``select`` +
``os.read`` on its file descriptor (one system call per burst, whatever is
there); URLs (``socket://``, ``loop://``, ``rfc2217://``) go through pyserial's
own ``read``. When the port disappears (EIO, EOF, device gone) the source
says so once, then reopens it with exponential backoff (50 ms doubling to
2 s) until it returns, for at most ``reconnect_timeout`` seconds, or raises
:class:`TransportError` at once if ``reconnect=False``.
"""
from __future__ import annotations

import os
import select
from typing import Any

from ..errors import DataError, TransportError
from .frames import SCALE_U, SCALE_Y, RawSample, make_parser
from .source_options import RATE, RECONNECT_TIMEOUT_S, Option, choice, nonempty, nonzero, whole
from .sources import ReconnectingSource


def _serial():
    try:
        import serial  # pyserial
    except ImportError:  # pragma: no cover - depends on the environment
        raise TransportError("serial sources need pyserial: pip install 'creep_online[serial]'") from None
    return serial


class SerialSource(ReconnectingSource):
    """Samples from a serial port or pyserial URL (``serial:PORT?rate=10000&...``).

    Spec keys this class does not declare stay in PORT, so a pyserial URL keeps
    its own options (``socket://host:port?logging=debug``).
    """

    link = "port"
    options = ReconnectingSource.options + (
        Option("format", choice("auto", "ascii", "binary"), "auto", "frame format (auto-detected by default)"),
        RATE,
        Option("baud", whole(1), 921600, "baud rate", keyword="baudrate"),
        Option("checksum", choice("auto", "required", "none"), "auto", "ASCII line checksum policy"),
        Option("scale_u", nonzero, SCALE_U, "binary input LSB"),
        Option("scale_y", nonzero, SCALE_Y, "binary output LSB"),
        Option("start", nonempty, None, "text sent after opening (e.g. a recorder's start command)"),
    )
    keeps_unknown_options = True
    target_label = "port"

    @classmethod
    def from_spec(cls, spec: str, target: str, **kwargs: Any) -> "SerialSource":
        """Open PORT; keys left in it are pyserial's URL options, so a device path must have none."""
        port, _, rest = target.partition("?")
        if rest and "://" not in port:
            names = ", ".join(sorted(o.name for o in cls.options))
            raise DataError(f"{spec}: unknown option(s) {rest!r} for a serial port (options: {names})")
        return cls(target, **kwargs)

    def __init__(self, port: str, *, baudrate: int = 921600, format: str = "auto",
                 rate: float | None = None, checksum: str = "auto",
                 scale_u: float = SCALE_U, scale_y: float = SCALE_Y,
                 reconnect: bool = True, reconnect_timeout: float | None = RECONNECT_TIMEOUT_S,
                 start: str | bytes | None = None, window: int = 16, stall: float = 0.5,
                 chunk: int = 1 << 16, **kw) -> None:
        fmt = format.lower()
        super().__init__(window=window, modulus=2**32 if fmt == "binary" else None, rate=rate,
                         t_from_seq=(fmt == "binary"), stall=stall, reconnect=reconnect,
                         reconnect_timeout=reconnect_timeout, **kw)
        self.name = f"serial:{port}"
        self.port = port
        self.baudrate = int(baudrate)
        self.format = fmt
        self.start = start.encode() if isinstance(start, str) else start
        self.chunk = int(chunk)
        self._parser_args = dict(fmt=fmt, rate=rate or 1.0, scale_u=scale_u, scale_y=scale_y,
                                 checksum=checksum)
        self.parser = make_parser(**self._parser_args, stats=self.stats.parser)
        self._leftovers: list[RawSample] = []
        self._ser = None
        self._fd: int | None = None
        self._open(first=True)

    # -------------------------------------------------------------- link
    def _open(self, first: bool = False) -> None:
        serial = _serial()
        try:
            if "://" in self.port:
                ser = serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=0.05)
            else:
                ser = serial.Serial(self.port, baudrate=self.baudrate, timeout=0.05, exclusive=False)
        except (serial.SerialException, OSError, ValueError) as exc:
            if first:
                raise TransportError(f"serial:{self.port}: cannot open ({_reason(exc)})") from None
            raise
        self._ser = ser
        try:
            self._fd = ser.fileno() if "://" not in self.port else None
        except Exception:  # noqa: BLE001 - URL handlers have no descriptor
            self._fd = None
        if self.start:
            ser.write(self.start)
            ser.flush()

    def _close_port(self) -> None:
        if self._ser is not None:
            try:
                self._ser.close()
            except Exception:  # noqa: BLE001 - closing a dead port may fail; it is gone either way
                pass
        self._ser = None
        self._fd = None

    def _close_link(self) -> None:
        self._close_port()
        self._absorb_parser()

    def _absorb_parser(self) -> None:
        """A partial frame from before the cut can never complete: count it and start clean."""
        self._leftovers = self.parser.flush()
        fmt = getattr(self.parser, "format", None) or self._parser_args["fmt"]
        self._parser_args["fmt"] = fmt
        self.parser = make_parser(**self._parser_args, stats=self.stats.parser)

    @property
    def link_up(self) -> bool:
        return self._ser is not None

    # -------------------------------------------------------------- reading
    def _read_bytes(self, timeout: float) -> bytes:
        if self._fd is not None:
            r, _, _ = select.select([self._fd], [], [], timeout)
            if not r:
                return b""
            data = os.read(self._fd, self.chunk)
            if not data:
                raise OSError("end of file")
            return data
        ser = self._ser
        ser.timeout = timeout
        n = ser.in_waiting
        return ser.read(n if n else 1)

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        if self._leftovers:
            out, self._leftovers = self._leftovers, []
            return out
        if self._ser is None:
            if not self._try_reconnect(timeout):
                return []
        serial = _serial()
        try:
            data = self._read_bytes(timeout)
        except (OSError, serial.SerialException, TypeError, AttributeError) as exc:
            self._lost(_reason(exc))
            return []
        if not data:
            return []
        out = self.parser.feed(data)
        if self.format == "auto" and getattr(self.parser, "format", None) == "binary" and not self.t_from_seq:
            self._switch_to_binary()
        return out

    def _switch_to_binary(self) -> None:
        if not self.rate:
            self._close_port()
            self.ended = True
            raise TransportError(f"serial:{self.port}: binary frames carry a counter, not a time: "
                                 "give the sample rate, e.g. serial:PORT?rate=10000")
        self.t_from_seq = True
        self.tracker.modulus = 2**32
        self.format = "binary"
        self._parser_args["fmt"] = "binary"

    def close(self) -> None:
        self._close_port()
        super().close()


def _reason(exc: BaseException) -> str:
    msg = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return str(msg).splitlines()[0][:120]
