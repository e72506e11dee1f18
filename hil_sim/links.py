"""Where the plant's frames go: a pseudo-terminal (serial or SLCAN), a loopback TCP port or python-can's virtual bus.

A pty pair is opened with ``os.openpty``; the slave is put in raw mode and kept
open here too, so the line never hangs up while the reader (pyserial, in
another process) opens and closes it. ``link`` makes a stable symlink to the
current ``/dev/pts/N`` (as socat's ``link=`` does) so a reader can reconnect
after a simulated disconnect, when the pty is replaced by a new one.
"""
from __future__ import annotations

import array
import fcntl
import os
import select
import socket
import termios
import time
import tty


class PtyLink:
    """Master side of a pseudo-terminal the reader opens as a serial port."""

    def __init__(self, link: str | None = None) -> None:
        self.link = link
        self.master: int | None = None
        self.slave: int | None = None
        self.open()

    def open(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        attrs = termios.tcgetattr(self.slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(self.slave, termios.TCSANOW, attrs)
        self.tty = os.ttyname(self.slave)
        if self.link:
            tmp = f"{self.link}.tmp{os.getpid()}"
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
            os.symlink(self.tty, tmp)
            os.replace(tmp, self.link)

    @property
    def port(self) -> str:
        return self.link or self.tty

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.master, view)
            view = view[n:]

    def read_available(self, timeout: float = 0.0) -> bytes:
        r, _, _ = select.select([self.master], [], [], timeout)
        if not r:
            return b""
        try:
            return os.read(self.master, 4096)
        except OSError:
            return b""

    def unread(self) -> int:
        """Bytes written but not yet read by the other side."""
        buf = array.array("i", [0])
        fcntl.ioctl(self.slave, termios.FIONREAD, buf, True)
        return buf[0]

    def drain(self, timeout: float = 5.0, quiet: float = 0.05) -> bool:
        """Wait until the reader has consumed everything (True) or timeout (False).

        The kernel moves written bytes to the reader's queue asynchronously, so
        an empty queue must stay empty for ``quiet`` seconds to count.
        """
        end = time.monotonic() + timeout
        empty_since = None
        while True:
            now = time.monotonic()
            if self.unread() > 0:
                empty_since = None
            elif empty_since is None:
                empty_since = now
            elif now - empty_since >= quiet:
                return True
            if now > end:
                return False
            time.sleep(0.002)

    def wait_for(self, token: bytes, timeout: float | None = None, reply: bytes | None = None) -> bool:
        """Block until the reader sends ``token`` (a start command); answer each CR-ended command."""
        buf = b""
        end = None if timeout is None else time.monotonic() + timeout
        while token not in buf:
            left = None if end is None else end - time.monotonic()
            if left is not None and left <= 0:
                return False
            chunk = self.read_available(0.05 if left is None else min(0.05, left))
            if chunk and reply is not None:
                self.write(reply * chunk.count(b"\r"))
            buf = (buf + chunk)[-256:]
        return True

    def close(self) -> None:
        if self.link:       # first the name, so nobody opens a pty that is about to go
            try:
                os.unlink(self.link)
            except FileNotFoundError:
                pass
        for fd in (self.master, self.slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self.slave = None

    def reopen(self) -> None:
        self.open()


def slcan_text(arbitration_id: int, data: bytes, fd: bool) -> bytes:
    """One frame in the SLCAN (Lawicel) ASCII protocol; FD as the CANable 2.0 'd' extension."""
    if fd:
        from can.util import len2dlc
        return b"d%03X%X%s\r" % (arbitration_id, len2dlc(len(data)), data.hex().upper().encode())
    return b"t%03X%d%s\r" % (arbitration_id, len(data), data.hex().upper().encode())


class VirtualLink:
    """python-can ``virtual`` bus (in-process only: the reader must live in this process)."""

    def __init__(self, channel: str) -> None:
        import can
        self._can = can
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.port = f"virtual:{channel}"

    def send(self, arbitration_id: int, data: bytes, fd: bool) -> None:
        self.bus.send(self._can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False,
                                        is_fd=fd, bitrate_switch=fd))

    def close(self) -> None:
        self.bus.shutdown()


class TcpLink:
    """A loopback TCP port standing for a controller's Ethernet interface: one client at a time.

    Offers what the emulators use of :class:`PtyLink` (``read_available``,
    ``write``, ``close``, ``reopen``, ``port``); a client that goes away is
    dropped and the next one accepted. ``close`` also closes the listening
    port (a pulled cable: new connections are refused), ``reopen`` listens on
    the same port again.
    """

    def __init__(self, port: int = 0, host: str = "127.0.0.1") -> None:
        self.host = host
        self._number = int(port)
        self.listener: socket.socket | None = None
        self.client: socket.socket | None = None
        self.open()

    def open(self) -> None:
        self.listener = socket.create_server((self.host, self._number))
        self._number = self.listener.getsockname()[1]
        self.tty = f"{self.host}:{self._number}"

    @property
    def port(self) -> str:
        return self.tty

    def read_available(self, timeout: float = 0.0) -> bytes:
        if self.client is None:
            ready, _, _ = select.select([self.listener], [], [], timeout)
            if ready:
                self.client, _ = self.listener.accept()
                self.client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return b""
        ready, _, _ = select.select([self.client], [], [], timeout)
        if not ready:
            return b""
        try:
            data = self.client.recv(4096)
        except OSError:
            data = b""
        if not data:
            self._drop_client()
        return data

    def write(self, data: bytes) -> None:
        if self.client is not None:
            try:
                self.client.sendall(data)
            except OSError:
                self._drop_client()

    def _drop_client(self) -> None:
        if self.client is not None:
            try:
                self.client.close()
            except OSError:
                pass
        self.client = None

    def close(self) -> None:
        self._drop_client()
        if self.listener is not None:
            self.listener.close()
            self.listener = None

    def reopen(self) -> None:
        self.open()
