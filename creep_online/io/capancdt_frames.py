"""The capaNCDT 6200 Ethernet data format: a 32-byte ``MEAS`` header, then M frames of N int32 values.

Followed from Micro-Epsilon's capaNCDT 6200 operating instructions ("Data
Format of Measuring Values"; docs/transports.md says what is followed and what
is assumed). Everything is little-endian:

==========  ======  ====================================================
offset      type    field
==========  ======  ====================================================
0           4s      preamble ``MEAS``
4           u32     order number of the controller
8           u32     serial number
12          u64     channel bit field: two bits per channel, ``01`` = present,
                    ``00`` = absent, channel 1 in the lowest bits
20          u32     status (not used)
24          u16     M, frames in this packet (one frame = one value per channel)
26          u16     bytes per frame (4 * N); see below for the other order
28          u32     measuring value counter of the first frame
32          i32 *N  frame 1: the present channels, lowest first; then frames 2..M
==========  ======  ====================================================

The manual's table puts M first; one public DT6220 client reads bytes per
frame first. Both orders are accepted: bytes per frame must equal 4 x the
channels the channel field names, and that decides which field is which
(when both equal it, the packet reads the same either way).

A value uses the low 24 bits: ``distance = value / 0xFFFFFF * range``, so the
top byte of every int32 is 0x00 (0xFF for a negative result of the
controller's math function, which this parser also accepts).

TCP delivers the bytes intact and in order, so there is no checksum: the
parser guards against a wrong header instead. It locks onto the stream when a
plausible header is followed, exactly where the packet ends, by another
header of the same controller (order and serial number, channel field, frame
size); once locked, every header must match that identity and every value
must fit in 24 bits (a top byte of 0x00 or 0xFF; since any four consecutive
bytes of a payload hold one top byte, a payload can never contain ``MEAS``)
and ``MEAS`` must not occur anywhere after the packet's start (so a packet
cut short and completed by the next header's bytes is caught; the price: a
packet whose counter bytes spell ``MEAS``, with its first value, is refused,
about once in 2^32 frames), else the place is counted (``malformed``),
skipped, and the parser searches for the next ``MEAS`` and locks again. A
valid header whose counter went backwards or jumped by 2^20 frames or more
within one connection is taken only once the next header confirms it (so a
header cut short and completed by a damaged next header is not). Bytes outside any packet are counted as ``garbage_bytes``.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .frames import ParserStats

MAGIC = b"MEAS"
HEADER = struct.Struct("<4sIIQIHHI")
HEADER_LEN = HEADER.size            # 32
FULL_SCALE = 0xFFFFFF               # 24-bit measuring value at the end of the range
COUNTER_MODULUS = 2**32
#: Largest frame count accepted in one packet (anything above is a corrupt header).
MAX_FRAMES = 4096
#: Counter advance beyond which (or backwards) a packet within one connection needs the next header's
#: confirmation: 2^20 frames, 4.5 min at 3.9 kSa/s.
MAX_JUMP = 1 << 20
_PAIR_HIGH_BITS = 0xAAAAAAAAAAAAAAAA   # the upper bit of every 2-bit channel entry must be 0
_VALUES = np.dtype("<i4")
_TOP_BYTES = b"\x00\xff"              # a value's top byte: 0x00 (or 0xFF, a negative math result)
_TAIL = struct.Struct("<HHI")         # frames and bytes per frame (either order), counter (offset 24)


class Identity(NamedTuple):
    """What every header of one controller repeats: order and serial number, channel field, frame size."""

    order: int
    serial: int
    channels: int
    frame_bytes: int


class Packet(NamedTuple):
    """One decoded packet: the counter of its first frame and its values, shape (M, N) int32."""

    counter: int
    values: np.ndarray


def channel_list(field_bits: int) -> list[int]:
    """The present channels (1-based) of a channel bit field, lowest first."""
    return [k + 1 for k in range(32) if (field_bits >> (2 * k)) & 0b11 == 0b01]


def channel_field(channels: list[int]) -> int:
    """Bit field with ``01`` for each channel in ``channels`` (1-based, 1..32)."""
    bits = 0
    for ch in channels:
        if not 1 <= ch <= 32:
            raise ValueError(f"channel {ch} is outside 1..32")
        bits |= 1 << (2 * (ch - 1))
    return bits


def scale(values: np.ndarray | int, range_um: float) -> np.ndarray | float:
    """Distance in um of raw values for a sensor with measuring range ``range_um``."""
    return values * (float(range_um) / FULL_SCALE)


def quantize(distance_um: np.ndarray, range_um: float) -> np.ndarray:
    """Nearest 24-bit raw values of distances in um, clipped to 0..0xFFFFFF (what the controller sends)."""
    raw = np.rint(np.asarray(distance_um, dtype=float) / float(range_um) * FULL_SCALE)
    return np.clip(raw, 0, FULL_SCALE).astype(np.int64)


def encode_packet(counter: int, values: np.ndarray, *, channels: int = 0b01, order: int = 6200,
                  serial: int = 1, status: int = 0, size_first: bool = False) -> bytes:
    """One packet: header + ``values`` (shape (M, N), one column per present channel).

    ``size_first`` writes bytes per frame before the frame count (the order some clients read)."""
    vals = np.asarray(values, dtype=np.int64)
    if vals.ndim == 1:
        vals = vals[:, None]
    m, n = vals.shape
    pair = (4 * n, m) if size_first else (m, 4 * n)
    header = HEADER.pack(MAGIC, order & 0xFFFFFFFF, serial & 0xFFFFFFFF, channels, status & 0xFFFFFFFF,
                         *pair, counter % COUNTER_MODULUS)
    return header + vals.astype(_VALUES).tobytes()


def frame_count(first: int, second: int, frame_bytes: int) -> int | None:
    """M from the header's two u16 fields in either order: the other one must be ``frame_bytes`` (4 x channels)."""
    frames = first if second == frame_bytes else second if first == frame_bytes else 0
    return frames if 1 <= frames <= MAX_FRAMES else None


def _plausible(fields: tuple) -> Identity | None:
    """The header's identity when its fields are self-consistent, else None."""
    magic, order, serial, channels, _status, first, second, _counter = fields
    if magic != MAGIC or channels & _PAIR_HIGH_BITS:
        return None
    n = bin(channels).count("1")
    if n == 0 or frame_count(first, second, 4 * n) is None:
        return None
    return Identity(order, serial, channels, 4 * n)


@dataclass
class CapancdtParser:
    """Incremental decoder of the packet stream; survives garbage and corrupt headers (module docstring)."""

    stats: ParserStats = field(default_factory=ParserStats)
    identity: Identity | None = None    # the controller locked onto (kept across reconnects)
    locked: bool = False
    _key: bytes = b""                   # header bytes 0..19 of the locked controller
    _next: int | None = None            # the counter the next packet should carry (within a connection)
    _buf: bytearray = field(default_factory=bytearray, repr=False)

    def feed(self, data: bytes) -> list[Packet]:
        """Every complete packet in ``data`` (plus what was buffered), in stream order."""
        self.stats.bytes += len(data)
        buf = self._buf
        buf += data
        out: list[Packet] = []
        pos = 0
        while True:
            step = self._locked_packet(pos) if self.locked else self._search(pos)
            if step is None:
                break
            pos, packet = step
            if packet is not None:
                out.append(packet)
        del buf[:pos]
        return out

    def _locked_packet(self, pos: int) -> tuple[int, Packet | None] | None:
        """The packet at ``pos`` (locked state), or a verdict that the header is bad (-> search)."""
        buf = self._buf
        if len(buf) - pos < HEADER_LEN:
            return None
        first, second, counter = _TAIL.unpack_from(buf, pos + 24)
        frame_bytes = self.identity.frame_bytes
        frames = frame_count(first, second, frame_bytes)
        # the identity, compared as bytes: magic, order, serial, channels; then the frame size
        if buf[pos:pos + 20] != self._key or frames is None:
            return self._bad_header(pos)
        if self._next is not None and (counter - self._next) % COUNTER_MODULUS >= MAX_JUMP:
            self.locked = False             # plausible but unexpected: taken once the next header confirms it
            return pos, None
        end = pos + HEADER_LEN + frames * frame_bytes
        if len(buf) < end:
            return None if self._fits(pos, len(buf)) else self._bad_header(pos)
        values = self._values(frames, pos, end)
        if values is None:
            return self._bad_header(pos)
        return end, self._accept(counter, values)

    def _accept(self, counter: int, values: np.ndarray) -> Packet:
        self.stats.frames += 1
        self._next = (counter + values.shape[0]) % COUNTER_MODULUS
        return Packet(counter, values)

    def _bad_header(self, pos: int) -> tuple[int, None]:
        """No valid packet where one was due: count it and search from here (a header of another identity
        that the next one confirms, e.g. a reconfigured controller, is taken at once)."""
        self.stats.malformed += 1
        self.locked = False
        return pos, None

    def _search(self, pos: int) -> tuple[int, Packet | None] | None:
        """Find a header confirmed by the next one; skip (and count) everything before it."""
        buf = self._buf
        k = buf.find(MAGIC, pos)
        if k < 0:
            keep = max(pos, len(buf) - (len(MAGIC) - 1))   # a split 'MEAS' may end the buffer
            self.stats.garbage_bytes += keep - pos
            return (keep, None) if keep > pos else None
        if k > pos:
            self.stats.garbage_bytes += k - pos
            return k, None
        verdict = self._confirmed(pos)
        if verdict is None:
            self.stats.garbage_bytes += 1
            return pos + 1, None
        if verdict == "wait":
            later = self._confirmed_after(pos + 1)
            if later is None:
                return None                 # wait for the next header to confirm this one
            self.stats.garbage_bytes += later - pos   # a confirmed header inside it disproves it
            return later, None
        fields, end = verdict
        self.identity = _plausible(fields)
        self._key = bytes(buf[pos:pos + 20])
        self.locked = True
        frames = frame_count(fields[5], fields[6], self.identity.frame_bytes)
        return end, self._accept(fields[7], self._values(frames, pos, end))

    def _confirmed(self, pos: int) -> tuple[tuple, int] | str | None:
        """(fields, end) when the header at ``pos`` is followed at its end by one of the same identity;
        ``"wait"`` when the buffer does not reach that far yet; None when it is not a header."""
        buf = self._buf
        if len(buf) - pos < HEADER_LEN:
            return "wait"
        fields = HEADER.unpack_from(buf, pos)
        ident = _plausible(fields)
        if ident is None:
            return None
        end = pos + HEADER_LEN + fields[5] * fields[6]
        if len(buf) < end + HEADER_LEN:
            return "wait" if self._fits(pos, min(end, len(buf))) else None
        frames = frame_count(fields[5], fields[6], ident.frame_bytes)
        if _plausible(HEADER.unpack_from(buf, end)) != ident or self._values(frames, pos, end) is None:
            return None
        return fields, end

    def _confirmed_after(self, pos: int) -> int | None:
        """Position of the first confirmed header at or after ``pos`` within the buffer, if any."""
        buf = self._buf
        k = buf.find(MAGIC, pos)
        while k >= 0:
            if isinstance(self._confirmed(k), tuple):
                return k
            k = buf.find(MAGIC, k + 1)
        return None

    def _fits(self, pos: int, stop: int) -> bool:
        """Whether what has arrived of the packet at ``pos`` (up to ``stop``) can still be one: no ``MEAS``
        after its start and 24-bit values. A header that claims more frames than were sent, or that was cut
        and completed by the next header's bytes, is refuted by those bytes."""
        if self._buf.find(MAGIC, pos + 1, stop) >= 0:
            return False
        start = pos + HEADER_LEN
        n = (stop - start) // 4
        return n <= 0 or not self._buf[start + 3:start + 4 * n:4].translate(None, _TOP_BYTES)

    def _values(self, frames: int, pos: int, end: int) -> np.ndarray | None:
        """The values of the packet at ``pos``, shape (M, N); None unless it passes :meth:`_fits`."""
        if not self._fits(pos, end):
            return None
        payload = bytes(self._buf[pos + HEADER_LEN:end])
        return np.frombuffer(payload, _VALUES).reshape(frames, -1)

    def restart(self) -> None:
        """A new connection starts on a packet boundary: forget the partial bytes, keep the identity.

        What was buffered can never complete and is counted as garbage.
        """
        self.stats.garbage_bytes += len(self._buf)
        self._buf.clear()
        self.locked = self.identity is not None
        self._next = None                   # the controller counted on while we were away
