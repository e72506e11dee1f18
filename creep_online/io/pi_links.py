"""How a ``pi:`` spec reaches a PI controller: the connection forms and pipython's gateway for each.

pipython users connect with ``ConnectTCPIP(ip, 50000)``, ``ConnectUSB(serial)``
or ``ConnectRS232(port, baudrate)``; the pure-Python gateways behind them
(``PISocket``, ``PIUSB``, ``PISerial``) are what the ``pi:`` source hands to
``GCSDevice(gateway=...)``, so PI's GCS DLL is never needed. The forms:

=========================  ====================================================
``pi:tcp:HOST[:PORT]``     Ethernet, port 50000 unless given (``PISocket``)
``pi:usb:SERIAL``          native USB by serial number (``PIUSB``; ``pid=`` or
                           found among PI's devices, vendor id 0x1a72)
``pi:rs232:PORT``          RS-232 or a USB virtual COM port (``PISerial``)
``pi:PORT``                the same, a device path such as ``/dev/ttyUSB0`` or ``COM3``
=========================  ====================================================

Anything else (``pi:192.168.0.10:50000``, ``pi:tcp://...``) is one line listing
these forms. The socket and serial gateways used by default wait for reply
bytes with ``select`` (at most 2 ms) instead of letting pipython poll
``read()`` in a busy loop, and the socket connects with a timeout (an
unreachable host would otherwise block for minutes).
"""
from __future__ import annotations

import ipaddress
import select
import socket
import time
from typing import Any, NamedTuple

from ..errors import DataError, TransportError

#: pipython's default TCP port of a PI controller.
TCP_PORT = 50000
#: PI's USB vendor id (pipython's ``PIUSB`` default).
PI_USB_VENDOR = 0x1A72
FORMS = "pi:tcp:HOST[:PORT] (port 50000 by default), pi:usb:SERIAL, pi:rs232:PORT or pi:PORT (RS-232)"


class Connection(NamedTuple):
    """Where the controller is: ``interface`` (tcp, usb, rs232), ``address`` (host, serial number or port),
    ``ipport`` (TCP only)."""

    interface: str
    address: str
    ipport: int | None = None

    def describe(self) -> str:
        """The spec's target, spelled the canonical way (``tcp:HOST:PORT``, ``usb:SERIAL``, ``PORT``)."""
        if self.interface == "tcp":
            return f"tcp:{self.address}:{self.ipport}"
        return f"usb:{self.address}" if self.interface == "usb" else self.address


def parse_connection(target: str) -> Connection:
    """``tcp:HOST[:PORT]`` | ``usb:SERIAL`` | ``rs232:PORT`` | ``PORT`` -> Connection; DataError listing the forms."""
    kind, sep, rest = target.partition(":")
    kind = kind.lower()
    if sep and kind == "tcp":
        return _tcp(target, rest)
    if sep and kind == "usb" and rest and ":" not in rest:
        return Connection("usb", rest)
    if sep and kind == "rs232" and rest:
        return Connection("rs232", rest)
    if target.startswith("/") or (not sep and target and not _looks_like_ip(target)):
        return Connection("rs232", target)       # a device path (by-path names hold colons) or COMn
    raise DataError(f"pi:{target}: not a PI connection; use {FORMS}")


def _tcp(target: str, rest: str) -> Connection:
    host, sep, port = rest.rpartition(":") if rest.count(":") == 1 else (rest, "", "")
    if not host or "/" in host or ":" in host:
        raise DataError(f"pi:{target}: not a PI connection; use {FORMS}")
    if not sep:
        return Connection("tcp", host, TCP_PORT)
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise DataError(f"pi:{target}: the TCP port must be a number 1..65535, got {port!r}")
    return Connection("tcp", host, int(port))


def _looks_like_ip(text: str) -> bool:
    try:
        ipaddress.ip_address(text)
    except ValueError:
        return False
    return True


def gateway_factory(conn: Connection, *, baudrate: int, pid: int | None, wait: bool,
                    connect_timeout: float) -> Any:
    """A function that opens pipython's gateway for ``conn`` (called again on every reconnect)."""
    if conn.interface == "tcp":
        PISocket = _closing_once(_import("pipython.pidevice.interfaces.pisocket", "PISocket"))
        cls = _waiting_socket(PISocket, connect_timeout) if wait else PISocket
        return lambda: cls(conn.address, conn.ipport)
    if conn.interface == "usb":
        return lambda: _open_usb(conn.address, pid)
    PISerial = _import("pipython.pidevice.interfaces.piserial", "PISerial")
    cls = _waiting_serial(PISerial) if wait else PISerial
    return lambda: cls(conn.address, baudrate)


def _import(module: str, name: str) -> Any:
    try:
        return getattr(__import__(module, fromlist=[name]), name)
    except ImportError as exc:
        raise TransportError(f"pi sources need pipython ({exc.name} is missing): "
                             "pip install 'creep_online[pi]'") from None


def _waiting_serial(PISerial: type) -> type:
    """pipython's ``PISerial`` whose ``read()`` first waits (select, at most 2 ms) for bytes to arrive.

    pipython polls ``read()`` in a loop without sleeping while it waits for a
    reply; with the stock gateway that loop keeps a core busy, which on a small
    machine is taken from the process that has to answer (and from the
    estimator). Everything else is pipython's own gateway, unchanged.
    """
    class WaitingPISerial(PISerial):
        def read(self):
            fd = getattr(self._ser, "fd", None)
            if fd is not None and not self._ser.in_waiting:
                select.select([fd], [], [], 0.002)
            return super().read()

    return WaitingPISerial


def _closing_once(PISocket: type) -> type:
    """pipython's ``PISocket`` whose ``close()`` may be called twice: ``GCSDevice`` closes its gateway on
    exit and again when it is garbage-collected, and the stock socket raises (EBADF) the second time."""
    class PISocketClosingOnce(PISocket):
        def close(self):
            if self._socket is None or self._socket.fileno() < 0:
                return
            try:
                super().close()
            except OSError:       # shutdown() of a connection the controller reset
                self._socket.close()
                self._connected = False

    return PISocketClosingOnce


def _waiting_socket(PISocket: type, connect_timeout: float) -> type:
    """pipython's ``PISocket`` that connects with a timeout and whose ``read()`` waits like the serial one."""
    class WaitingPISocket(PISocket):
        def ConnectTCPIP(self, ipaddress, ipport=TCP_PORT):  # noqa: N802 - pipython's method name
            # pipython's own steps, on a socket created with a connect timeout
            self._host, self._port = ipaddress, ipport
            sock = socket.create_connection((ipaddress, ipport), timeout=connect_timeout)
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._socket = sock
            self._connected = True
            self.flush()
            self.call_connection_status_changed_callback(self)

        def read(self):
            if not select.select([self._socket], [], [], 0.002)[0]:
                return ""
            text = super().read()
            if not text:          # readable yet empty: the controller closed the connection
                time.sleep(0.002)
            return text

    return WaitingPISocket


def _open_usb(serial: str, pid: int | None) -> Any:
    """pipython's ``PIUSB`` connected to the PI device with this serial number (product id found if not given)."""
    PIUSB = _import("pipython.pidevice.interfaces.piusb", "PIUSB")
    name = f"pi:usb:{serial}"
    try:
        if pid is None:
            found = PIUSB.enumerate(vid=PI_USB_VENDOR)
            match = [d for d in found if d.get("SerialNumber") == serial]
            if not match:
                serials = ", ".join(d.get("SerialNumber", "?") for d in found) or "none"
                raise TransportError(f"{name}: no PI USB device with this serial number (found: {serials}); "
                                     "a controller on a virtual COM port is pi:rs232:PORT")
            pid = int(match[0]["PID"], 16)
        gateway = PIUSB()
        gateway.connect(serial, pid, PI_USB_VENDOR)
    except TransportError:
        raise
    except Exception as exc:  # noqa: BLE001 - pyusb's NoBackendError, USBError, pipython's GCSError
        why = "no USB backend: install libusb-1.0" if type(exc).__name__ == "NoBackendError" else _reason(exc)
        raise TransportError(f"{name}: cannot open ({why})") from None
    return gateway


def _reason(exc: BaseException) -> str:
    """The first line of what went wrong (an OSError's strerror, else the message), at most 160 characters."""
    msg = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return str(msg).strip().splitlines()[0][:160]
