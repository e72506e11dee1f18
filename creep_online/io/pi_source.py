"""``pi:tcp:HOST[:PORT]``, ``pi:usb:SERIAL``, ``pi:rs232:PORT`` (or ``pi:PORT``): a PI piezo controller's data recorder.

The controller is driven by PI's own library, ``pipython``: a ``GCSDevice``
on one of pipython's pure-Python gateways, the ones its ``ConnectTCPIP``,
``ConnectUSB`` and ``ConnectRS232`` stand for (``PISocket(host, port)``,
``PIUSB().connect(serial, pid)``, ``PISerial(port, baudrate)``; PI's GCS DLL
is not needed). The socket and serial gateways' ``read()`` here waits for
bytes with ``select`` instead of letting pipython spin on it (``wait=0``: the
stock gateway). ``controller=NAME`` (e.g. ``E-727``) is pipython's device
name, and the controller that answers ``*IDN?`` must be that one. On
connecting the source sends, in GCS 2 syntax::

    *IDN?                      who is there (kept in ``source.idn``)
    SAI?                       the axes, when ``axes`` is not given (the first one is used)
    RTR n                      record one point every n servo cycles (``rtr``)
    DRC 1 A 7 2 A 2            table 1: piezo voltage (input u), table 2: sensor position (output y)
    DRT 0 4 0                  start recording now (trigger source 4, "immediately")

With several axes (``axes=1,2``) axis k gets tables 2k-1 (u) and 2k (y), and
every sample's ``u`` and ``y`` are tuples, one value per axis in that order.
While streaming the source sends ``DRL? 1`` (points recorded so far) and
``DRR? OFFSET N 1 2 ...`` for the points not read yet, at most ``chunk`` at a time,
each DRR? followed by ``ERR?`` (and DRL? too when nothing new was recorded). The recorder's header gives the sample
time (``SAMPLE_TIME``). Point i of a recording gets sequence number
``base + i``; a record table is finite, so when a recording has stopped
growing and has been read to the end, the source starts the next one
(``DRT`` again) and numbers it from the host clock (``base`` = time since the
first trigger / sample time, never less than where the last recording ended).
The points lost while re-triggering are therefore counted as a gap, and the
estimator is told about them; the count is an estimate good to half the DRT
round trip (kept per recording in ``trigger_uncertainty_s``; about a
millisecond on a quiet machine).

Errors: a GCS error code from the controller (a refused record option, an
invalid axis) is a :class:`TransportError` naming the command and the code;
a lost link (port gone, no reply within the timeout) is reconnected with
backoff like a serial port, or, with ``reconnect=0``, a TransportError at once.
"""
from __future__ import annotations

import time
from typing import Any

from ..errors import DataError, TransportError
from .frames import RawSample
from .pi_links import _reason, gateway_factory, parse_connection
from .source_options import RECONNECT_TIMEOUT_S, Option, flag, nonempty, positive, whole
from .sources import ReconnectingSource

#: GCS record options used by default (pipython.datarectools.RecordOptions).
PIEZO_VOLTAGE, ACTUAL_POSITION = 7, 2
#: Trigger source "immediately" (pipython.datarectools.TriggerSources.TRIGGER_IMMEDIATELY_4).
TRIGGER_IMMEDIATELY = 4
#: pipython error codes that mean the link, not the controller, failed (timeout, no data, unreadable data).
LINK_ERRORS = {-1, -7, -9, -1090}
#: Record tables of a data recorder this source fills at most (an E-727 has 8).
MAX_TABLES = 8


def _pipython():
    """(GCSDevice, GCSError), or one line saying which extra to install."""
    try:
        from pipython import GCSDevice, GCSError
    except ImportError:
        raise TransportError("pi sources need pipython: pip install 'creep_online[pi]'") from None
    return GCSDevice, GCSError


def axis_list(text: str) -> tuple[str, ...]:
    """``1,2`` -> ("1", "2"): the axes recorded, each once."""
    axes = tuple(a.strip() for a in str(text).split(","))
    if not all(axes) or len(set(axes)) != len(axes):
        raise ValueError("expected axis identifiers separated by commas, each once (e.g. 1,2)")
    return axes


axis_list.__name__ = "axes"


def product_id(text: str) -> int:
    """A USB product id, decimal or ``0x`` hexadecimal (16 bits)."""
    value = int(text, 0)
    if not 0 <= value <= 0xFFFF:
        raise ValueError("expected a USB product id from 0 to 0xFFFF")
    return value


class PiSource(ReconnectingSource):
    """Samples from a PI controller's data recorder (``pi:tcp:HOST?rtr=1``, ``pi:/dev/ttyUSB0?baudrate=115200``).

    ``target`` is the spec after ``pi:`` (``tcp:HOST[:PORT]``, ``usb:SERIAL``,
    ``rs232:PORT`` or ``PORT``: ``creep_online.io.pi_links``).
    """

    link = "controller"
    target_label = "controller connection"
    options = ReconnectingSource.options + (
        Option("baudrate", whole(1), 115200, "RS-232 baud rate"),
        Option("baud", whole(1), 115200, "the same as baudrate", keyword="baudrate"),
        Option("controller", nonempty, None, "the controller's name, e.g. E-727 (*IDN? must name it)"),
        Option("rtr", whole(1), 1, "record table rate: servo cycles per recorded point (RTR)"),
        Option("axes", axis_list, None, "axes recorded, e.g. 1,2: one estimate each (default: the first of SAI?)"),
        Option("axis", nonempty, None, "one axis / output channel recorded (the same as axes=AXIS)"),
        Option("u_record", whole(0), PIEZO_VOLTAGE, "record option of the input (7 piezo voltage, 14 open-loop value)"),
        Option("y_record", whole(0), ACTUAL_POSITION, "record option of the output (2 current position)"),
        Option("chunk", whole(1), 2000, "most points read per DRR? query"),
        Option("timeout", positive, 2.0, "seconds without a reply before the link counts as lost"),
        Option("pid", product_id, None, "USB product id (default: found by the serial number)"),
        Option("wait", flag, True, "wait for reply bytes with select (0: pipython's stock gateway, which spins)"),
    )

    def __init__(self, port: str, *, baudrate: int = 115200, controller: str | None = None, rtr: int = 1,
                 axes: str | tuple[str, ...] | None = None, axis: str | None = None,
                 u_record: int = PIEZO_VOLTAGE, y_record: int = ACTUAL_POSITION, chunk: int = 2000,
                 timeout: float = 2.0, pid: int | None = None, wait: bool = True, reconnect: bool = True,
                 reconnect_timeout: float | None = RECONNECT_TIMEOUT_S, window: int = 16, stall: float = 0.5,
                 **kw: Any) -> None:
        conn = parse_connection(port)
        name = f"pi:{port}"
        if rtr < 1 or chunk < 1 or not timeout > 0:
            raise TransportError(f"pi:{port}: rtr and chunk must be >= 1 and timeout > 0")
        if axis is not None and axes is not None:
            raise DataError(f"{name}: give axes= or axis=, not both")
        if conn.interface != "rs232" and baudrate != 115200:
            raise DataError(f"{name}: baudrate applies to RS-232 connections only")
        chosen = axis_list(axes) if isinstance(axes, str) else (tuple(axes) if axes else None)
        if axis is not None:
            chosen = (str(axis),)
        if chosen and 2 * len(chosen) > MAX_TABLES:
            raise DataError(f"{name}: at most {MAX_TABLES // 2} axes (two record tables each)")
        GCSDevice, GCSError = _pipython()
        self._gcs = (GCSDevice, GCSError)
        self._gateway = gateway_factory(conn, baudrate=int(baudrate), pid=pid, wait=wait, connect_timeout=timeout)
        super().__init__(window=window, rate=None, t_from_seq=True, stall=stall, reconnect=reconnect,
                         reconnect_timeout=reconnect_timeout, **kw)
        self.name = name
        self.connection = conn
        self.port = conn.address
        self.baudrate = int(baudrate)
        self.controller = controller
        self.rtr = int(rtr)
        self.axes = chosen         # None until SAI? has named the first axis
        self.records = (int(u_record), int(y_record))
        self.chunk = int(chunk)
        self.timeout_s = float(timeout)
        self.idn = ""
        self._doing = "connecting"
        self.recordings = 0        # recordings started (DRT)
        #: per recording: half the DRT round trip, the bound on the error of its host-clock numbering
        self.trigger_uncertainty_s: list[float] = []
        self._dev = None
        self._t_first: float | None = None   # host time of the first trigger
        self._base = 0             # sequence number of point 1 of the present recording
        self._read = 0             # points of the present recording already read
        self._last_count = -1      # DRL? at the previous poll
        self._count_since = 0.0    # host time it last changed
        self._open(first=True)

    @property
    def axis(self) -> str | None:
        """The (first) axis recorded."""
        return self.axes[0] if self.axes else None

    @property
    def tables(self) -> list[int]:
        """The record tables read: 2k-1 (u) and 2k (y) for the k-th axis."""
        return list(range(1, 2 * len(self.axes or ("",)) + 1))

    # -------------------------------------------------------------- link
    def _open(self, first: bool = False) -> None:
        GCSDevice = self._gcs[0]
        try:
            gateway = self._gateway()
        except TransportError:
            raise
        except Exception as exc:  # noqa: BLE001 - pyserial's SerialException, OSError, ValueError
            if first:
                raise TransportError(f"{self.name}: cannot open ({_reason(exc)})") from None
            raise
        try:
            dev = GCSDevice(devname=self.controller or "", gateway=gateway)
            dev.timeout = int(self.timeout_s * 1000)
            self._dev = dev
            self._configure()
        except TransportError:
            self._close_link()
            raise
        except Exception as exc:
            self._close_link()
            if not first:
                raise
            raise self._error(exc) from None

    def _configure(self) -> None:
        dev = self._dev
        self.idn = self._call("*IDN?", dev.qIDN).strip()
        if self.controller and _squeezed(self.controller) not in _squeezed(self.idn):
            raise TransportError(f"{self.name}: the controller answering is not an {self.controller} "
                                 f"(*IDN?: {self.idn[:120]})")
        if self.axes is None:
            self.axes = (self._call("SAI?", dev.qSAI)[0],)
        self._call(f"RTR {self.rtr}", dev.RTR, self.rtr)
        (u, y) = self.records
        sources = [a for a in self.axes for _ in (u, y)]
        options = [u, y] * len(self.axes)
        command = "DRC " + " ".join(f"{t} {a} {o}" for t, a, o in zip(self.tables, sources, options))
        self._call(command, dev.DRC, self.tables, sources, options)
        self._arm()

    def _call(self, command: str, method, *args):
        """Run one pipython call, remembering its GCS command for the error message."""
        self._doing = command
        return method(*args)

    def _arm(self) -> None:
        """Start a recording now (DRT) and number its points after everything already handed out."""
        before = time.monotonic()
        self._call(f"DRT 0 {TRIGGER_IMMEDIATELY} 0", self._dev.DRT, 0, TRIGGER_IMMEDIATELY, 0)
        after = time.monotonic()
        now = (before + after) / 2
        self.trigger_uncertainty_s.append((after - before) / 2)
        if self._t_first is None:
            self._t_first = now
            self._base = 0
        else:
            end_of_last = self._base + self._read
            by_clock = round((now - self._t_first) * self.rate) if self.rate else end_of_last
            self._base = max(end_of_last, by_clock)
        self._read = 0
        self._last_count = -1
        self.recordings += 1

    def _close_link(self) -> None:
        """Close through the context-manager exit: plain close() leaves the GCSDevice registered in
        pipython's class-wide connection callbacks, and the next connection would call into this dead one."""
        dev, self._dev = self._dev, None
        if dev is not None:
            try:
                dev.__exit__(None, None, None)
            except Exception:  # noqa: BLE001 - closing a dead port may fail; it is gone either way
                pass

    @property
    def link_up(self) -> bool:
        return self._dev is not None

    # -------------------------------------------------------------- reading
    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        if self._dev is None and not self._try_reconnect(timeout):
            return []
        try:
            return self._poll(timeout)
        except TransportError:
            raise
        except Exception as exc:  # noqa: BLE001 - pyserial / pipython errors: classified below
            if not self._is_link_error(exc):
                raise self._error(exc) from None
            self._lost(f"no answer to '{self._doing}': {_reason(exc)}")
            return []

    def _poll(self, timeout: float) -> list[RawSample]:
        """One DRL?; then the new points, a new recording when this one has stopped, or a short wait.

        "Stopped" means: all of it read and no new point for 4 sample times (at least 50 ms).

        DRL? is sent without its own ERR? round trip (one fewer per poll): the
        error register is read after every DRR? and whenever the count stands still.
        """
        dev = self._dev
        dev.errcheck = False
        try:
            count = self._call("DRL? 1", dev.qDRL, 1)[1]
        finally:
            dev.errcheck = True
        now = time.monotonic()
        if count != self._last_count:
            self._last_count, self._count_since = count, now
        if count > self._read:
            return self._fetch(min(count - self._read, self.chunk))
        self._check_error("DRL? 1")
        dt = self.dt or 0.0
        if self._read > 0 and now - self._count_since > max(0.05, 4 * dt):
            self._arm()               # the recording stopped (table full) and all of it was read
            return []
        time.sleep(min(timeout, max(0.002, dt)))
        return []

    def _fetch(self, n: int) -> list[RawSample]:
        """Points read+1 .. read+n of both tables (pipython reads the rows in its own thread).

        The error check (ERR?) is made here after the rows, not by pipython's reading
        thread, whose own check is outside its error handling (a link lost there would
        print a thread traceback).
        """
        dev = self._dev
        tables = self.tables
        command = f"DRR? {self._read + 1} {n} {' '.join(map(str, tables))}"
        dev.errcheck = False
        try:
            header = self._call(command, dev.qDRR, tables, self._read + 1, n)
            while dev.bufstate is not True:          # raises pipython's timeout if the rows stop
                time.sleep(0.0005)
        finally:
            dev.errcheck = True
        self._check_error(command)
        columns = dev.bufdata[:len(tables)]
        if len(tables) == 2:
            u, y = columns
        else:                                    # several axes: a tuple per point, one value per axis
            u, y = list(zip(*columns[0::2])), list(zip(*columns[1::2]))
        if not self.rate:
            self.rate = 1.0 / float(header["SAMPLE_TIME"])
        seq0 = self._base + self._read
        self.stats.parser.frames += 1            # one DRR? answer
        self._read += n
        return [RawSample(seq0 + i, 0.0, u[i], y[i], 0) for i in range(n)]

    def _check_error(self, command: str) -> None:
        code = self._call("ERR?", self._dev.qERR)
        if code:
            self._doing = command
            raise self._gcs[1](code)

    # -------------------------------------------------------------- errors
    def _is_link_error(self, exc: BaseException) -> bool:
        GCSError = self._gcs[1]
        if isinstance(exc, GCSError):
            return exc.val in LINK_ERRORS
        return isinstance(exc, (OSError, TypeError, AttributeError)) or type(exc).__name__ == "SerialException"

    def _error(self, exc: BaseException) -> TransportError:
        """One line: the GCS command and the controller's error code, or what happened to the link."""
        GCSError = self._gcs[1]
        if isinstance(exc, GCSError) and exc.val not in LINK_ERRORS:
            text = GCSError.translate_error(exc.val)
            return TransportError(f"{self.name}: the controller refused '{self._doing}': GCS error {exc.val} "
                                  f"({text.rsplit(' ', 1)[0] if text.endswith(str(exc.val)) else text})")
        return TransportError(f"{self.name}: no answer to '{self._doing}' ({_reason(exc)})")

    def close(self) -> None:
        self._close_link()
        super().close()


def _squeezed(name: str) -> str:
    """A controller name compared without case, spaces and dashes (E-727 = e727)."""
    return "".join(c for c in name.upper() if c.isalnum())
