"""``pi:PORT``: samples from a PI (Physik Instrumente) piezo controller's data recorder, through pipython.

The controller is driven by PI's own library, ``pipython``: a ``GCSDevice``
on pipython's pure-Python RS-232 gateway (``PISerial(port, baudrate)``, which
calls ``ConnectRS232``; PI's GCS DLL is not needed), whose ``read()`` here
waits for bytes with ``select`` instead of letting pipython spin on it
(``wait=0``: the stock gateway). On connecting the source sends, in GCS 2
syntax::

    *IDN?                      who is there (kept in ``source.idn``)
    SAI?                       the axes, when ``axis`` is not given (the first one is used)
    RTR n                      record one point every n servo cycles (``rtr``)
    DRC 1 AXIS 7 2 AXIS 2      table 1: piezo voltage (input u), table 2: sensor position (output y)
    DRT 0 4 0                  start recording now (trigger source 4, "immediately")

and then, while streaming, ``DRL? 1`` (points recorded so far) and
``DRR? OFFSET N 1 2`` for the points not read yet, at most ``chunk`` at a time,
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

from ..errors import TransportError
from .frames import RawSample
from .source_options import RECONNECT_TIMEOUT_S, Option, flag, nonempty, positive, whole
from .sources import ReconnectingSource

#: GCS record options used by default (pipython.datarectools.RecordOptions).
PIEZO_VOLTAGE, ACTUAL_POSITION = 7, 2
#: Trigger source "immediately" (pipython.datarectools.TriggerSources.TRIGGER_IMMEDIATELY_4).
TRIGGER_IMMEDIATELY = 4
#: pipython error codes that mean the link, not the controller, failed (timeout, no data, unreadable data).
LINK_ERRORS = {-1, -7, -9, -1090}


def _pipython():
    """(GCSDevice, PISerial, GCSError), or one line saying which extra to install."""
    try:
        from pipython import GCSDevice, GCSError
        from pipython.pidevice.interfaces.piserial import PISerial
    except ImportError:
        raise TransportError("pi sources need pipython: pip install 'creep_online[pi]'") from None
    return GCSDevice, PISerial, GCSError


def _waiting_gateway(PISerial: type) -> type:
    """pipython's ``PISerial`` whose ``read()`` first waits (select, at most 2 ms) for bytes to arrive.

    pipython polls ``read()`` in a loop without sleeping while it waits for a
    reply; with the stock gateway that loop keeps a core busy, which on a small
    machine is taken from the process that has to answer (and from the
    estimator). Everything else is pipython's own gateway, unchanged.
    """
    import select

    class WaitingPISerial(PISerial):
        def read(self):
            fd = getattr(self._ser, "fd", None)
            if fd is not None and not self._ser.in_waiting:
                select.select([fd], [], [], 0.002)
            return super().read()

    return WaitingPISerial


class PiSource(ReconnectingSource):
    """Samples from a PI controller's data recorder (``pi:PORT?baud=115200&rtr=1&...``)."""

    link = "controller"
    target_label = "port"
    options = ReconnectingSource.options + (
        Option("baud", whole(1), 115200, "RS-232 baud rate", keyword="baudrate"),
        Option("rtr", whole(1), 1, "record table rate: servo cycles per recorded point (RTR)"),
        Option("axis", nonempty, None, "axis / output channel recorded (default: the first axis of SAI?)"),
        Option("u_record", whole(0), PIEZO_VOLTAGE, "record option of the input (7 piezo voltage, 14 open-loop value)"),
        Option("y_record", whole(0), ACTUAL_POSITION, "record option of the output (2 current position)"),
        Option("chunk", whole(1), 2000, "most points read per DRR? query"),
        Option("timeout", positive, 2.0, "seconds without a reply before the link counts as lost"),
        Option("wait", flag, True, "wait for reply bytes with select (0: pipython's stock gateway, which spins)"),
    )

    def __init__(self, port: str, *, baudrate: int = 115200, rtr: int = 1, axis: str | None = None,
                 u_record: int = PIEZO_VOLTAGE, y_record: int = ACTUAL_POSITION, chunk: int = 2000,
                 timeout: float = 2.0, wait: bool = True, reconnect: bool = True,
                 reconnect_timeout: float | None = RECONNECT_TIMEOUT_S, window: int = 16, stall: float = 0.5, **kw: Any) -> None:
        GCSDevice, PISerial, GCSError = _pipython()
        self._gcs = (GCSDevice, _waiting_gateway(PISerial) if wait else PISerial, GCSError)
        super().__init__(window=window, rate=None, t_from_seq=True, stall=stall, reconnect=reconnect,
                         reconnect_timeout=reconnect_timeout, **kw)
        if rtr < 1 or chunk < 1 or not timeout > 0:
            raise TransportError(f"pi:{port}: rtr and chunk must be >= 1 and timeout > 0")
        self.name = f"pi:{port}"
        self.port = port
        self.baudrate = int(baudrate)
        self.rtr = int(rtr)
        self.axis = axis
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

    # -------------------------------------------------------------- link
    def _open(self, first: bool = False) -> None:
        GCSDevice, PISerial, GCSError = self._gcs
        try:
            gateway = PISerial(self.port, self.baudrate)
        except Exception as exc:  # noqa: BLE001 - pyserial's SerialException, OSError, ValueError
            if first:
                raise TransportError(f"{self.name}: cannot open ({_reason(exc)})") from None
            raise
        try:
            dev = GCSDevice(gateway=gateway)
            dev.timeout = int(self.timeout_s * 1000)
            self._dev = dev
            self._configure()
        except Exception as exc:
            self._close_link()
            if not first:
                raise
            raise self._error(exc) from None

    def _configure(self) -> None:
        dev = self._dev
        self.idn = self._call("*IDN?", dev.qIDN).strip()
        axis = self.axis or self._call("SAI?", dev.qSAI)[0]
        self._call(f"RTR {self.rtr}", dev.RTR, self.rtr)
        (u, y) = self.records
        self._call(f"DRC 1 {axis} {u} 2 {axis} {y}", dev.DRC, [1, 2], [axis, axis], [u, y])
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
        command = f"DRR? {self._read + 1} {n} 1 2"
        dev.errcheck = False
        try:
            header = self._call(command, dev.qDRR, [1, 2], self._read + 1, n)
            while dev.bufstate is not True:          # raises pipython's timeout if the rows stop
                time.sleep(0.0005)
        finally:
            dev.errcheck = True
        self._check_error(command)
        u, y = dev.bufdata[:2]
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
            raise self._gcs[2](code)

    # -------------------------------------------------------------- errors
    def _is_link_error(self, exc: BaseException) -> bool:
        GCSError = self._gcs[2]
        if isinstance(exc, GCSError):
            return exc.val in LINK_ERRORS
        return isinstance(exc, (OSError, TypeError, AttributeError)) or type(exc).__name__ == "SerialException"

    def _error(self, exc: BaseException) -> TransportError:
        """One line: the GCS command and the controller's error code, or what happened to the link."""
        GCSError = self._gcs[2]
        if isinstance(exc, GCSError) and exc.val not in LINK_ERRORS:
            text = GCSError.translate_error(exc.val)
            return TransportError(f"{self.name}: the controller refused '{self._doing}': GCS error {exc.val} "
                                  f"({text.rsplit(' ', 1)[0] if text.endswith(str(exc.val)) else text})")
        return TransportError(f"{self.name}: no answer to '{self._doing}' ({_reason(exc)})")

    def close(self) -> None:
        self._close_link()
        super().close()


def _reason(exc: BaseException) -> str:
    msg = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return str(msg).strip().splitlines()[0][:160]
