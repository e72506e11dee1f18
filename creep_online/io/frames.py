"""Wire formats of a sample stream and incremental parsers that survive garbage.

Two formats (docs/transports.md, "Serial frame formats"):

ASCII lines
    ``seq,t,u,y`` then optionally ``*HHHH`` (CRC-16/CCITT-FALSE of every byte
    before the ``*``, four upper-case hex digits), ended by ``\\n`` (a trailing
    ``\\r`` is accepted). Without the checksum a flipped digit cannot be
    detected, so once a checksummed line has been seen the parser requires it
    on every line (``checksum="required"`` requires it from the first).

Binary frames (22 bytes, little-endian)
    ``AA 55 | u16 len=16 | u32 seq | i32 u | i32 y | u32 status | u16 crc``
    where ``crc = CRC-16/CCITT-FALSE`` (``binascii.crc_hqx(data, 0xFFFF)``)
    over ``len..status`` (bytes 2..19). ``u = raw_u * scale_u``,
    ``y = raw_y * scale_y``; the time is ``seq / rate``.

Parsers are fed arbitrary chunks and return decoded :class:`RawSample`
tuples. Everything that is not a valid frame is counted (``garbage_bytes``,
``crc_errors``, ``malformed``) and skipped; the parser resynchronises on the
next sync word or line. CRC-16/CCITT has Hamming distance 4 at this length: any
1-3 bit errors inside a frame are always caught.
"""
from __future__ import annotations

import binascii
import math
import operator
import struct
from dataclasses import dataclass, field
from typing import NamedTuple

from ..errors import DataError

SYNC = b"\xaa\x55"
PAYLOAD_LEN = 16
FRAME_LEN = 2 + 2 + PAYLOAD_LEN + 2
_BODY = struct.Struct("<HIiiI")  # len, seq, u, y, status
_CRC = struct.Struct("<H")
#: Default wire scaling of the binary frame (1 LSB = 1e-6 input/output units).
SCALE_U = 1e-6
SCALE_Y = 1e-6
#: Longest ASCII line accepted (anything longer is garbage, not a sample).
MAX_LINE = 160
I32_MIN, I32_MAX = -(2**31), 2**31 - 1


class RawSample(NamedTuple):
    """One decoded sample as it came off the wire (seq not yet checked for order)."""

    seq: int
    t: float
    u: float
    y: float
    status: int = 0


@dataclass
class ParserStats:
    """What the parser threw away, and why."""

    frames: int = 0           # good frames decoded
    bytes: int = 0            # bytes fed
    garbage_bytes: int = 0    # bytes outside any frame (noise, resync)
    crc_errors: int = 0       # frames with a bad CRC / checksum
    malformed: int = 0        # frames or lines that cannot be decoded
    no_input: int = 0         # CAN samples whose input value (AMP_INPUT generation) was never received
    other_frames: int = 0     # CAN frames of unrelated IDs (ignored, not an error)

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


# ---------------------------------------------------------------- checksums
def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor-out)."""
    return binascii.crc_hqx(data, 0xFFFF)


# ---------------------------------------------------------------- encoders
def quantize(value: float, scale: float) -> int:
    """Nearest wire integer for ``value`` at ``scale`` units per LSB, clipped to i32 (DataError for NaN)."""
    q = float(value) / float(scale)
    if math.isnan(q):
        raise DataError(f"cannot quantize {value!r} at scale {scale!r}: not a number")
    if math.isinf(q):
        return I32_MAX if q > 0 else I32_MIN
    q = round(q)
    return min(max(q, I32_MIN), I32_MAX)


def encode_binary(seq: int, u: float, y: float, status: int = 0,
                  scale_u: float = SCALE_U, scale_y: float = SCALE_Y) -> bytes:
    """One 22-byte binary frame."""
    body = _BODY.pack(PAYLOAD_LEN, seq & 0xFFFFFFFF, quantize(u, scale_u), quantize(y, scale_y),
                      status & 0xFFFFFFFF)
    return SYNC + body + _CRC.pack(crc16(body))


def encode_binary_raw(seq: int, raw_u: int, raw_y: int, status: int = 0) -> bytes:
    """Binary frame from already-quantized integers (what an ADC hands over)."""
    body = _BODY.pack(PAYLOAD_LEN, seq & 0xFFFFFFFF, raw_u, raw_y, status & 0xFFFFFFFF)
    return SYNC + body + _CRC.pack(crc16(body))


#: ``status`` bit of a command frame (host -> amplifier): ``u`` is the DAC value to apply at sample ``seq``.
STATUS_COMMAND = 0x80000000


def encode_command(seq: int, u: float, scale_u: float = SCALE_U) -> bytes:
    """A command frame: the binary frame with ``STATUS_COMMAND`` set and y = 0 (same sync, length, CRC).

    The amplifier parses it with :class:`BinaryParser`, so commands get the
    same resynchronisation and CRC protection as samples.
    """
    return encode_binary(seq, u, 0.0, STATUS_COMMAND, scale_u=scale_u)


def encode_ascii(seq: int, t: float, u: float, y: float, checksum: bool = True) -> bytes:
    """One ASCII line ``seq,t,u,y[*HHHH]\\n`` (repr-exact floats; numpy scalars written as plain numbers)."""
    body = f"{operator.index(seq)},{float(t)!r},{float(u)!r},{float(y)!r}".encode()
    if checksum:
        return body + b"*%04X\n" % crc16(body)
    return body + b"\n"


# ---------------------------------------------------------------- parsers
@dataclass
class BinaryParser:
    """Incremental decoder of binary frames with resynchronisation and CRC check."""

    rate: float = 1.0
    scale_u: float = SCALE_U
    scale_y: float = SCALE_Y
    stats: ParserStats = field(default_factory=ParserStats)
    _buf: bytearray = field(default_factory=bytearray, repr=False)

    def feed(self, data: bytes) -> list[RawSample]:
        """Decode every complete frame in ``data`` (plus what was buffered)."""
        self.stats.bytes += len(data)
        buf = self._buf
        buf += data
        out: list[RawSample] = []
        pos, n = 0, len(buf)
        st = self.stats
        dt = 1.0 / self.rate
        su, sy = self.scale_u, self.scale_y
        while True:
            k = buf.find(SYNC, pos)
            if k < 0:
                # keep a trailing 0xAA: it may be the first half of a sync word
                keep = n - 1 if n > pos and buf[n - 1] == 0xAA else n
                st.garbage_bytes += keep - pos
                pos = keep
                break
            if k > pos:
                st.garbage_bytes += k - pos
                pos = k
            if n - pos < 4:
                break
            length = buf[pos + 2] | (buf[pos + 3] << 8)
            if length != PAYLOAD_LEN:
                st.malformed += 1
                st.garbage_bytes += 2
                pos += 2
                continue
            if n - pos < FRAME_LEN:
                break
            body = bytes(buf[pos + 2: pos + 20])
            if crc16(body) != (buf[pos + 20] | (buf[pos + 21] << 8)):
                # A corrupt payload: skip the whole frame when the next one starts
                # right after it, else only the sync word (the length may be what broke).
                if n - pos < FRAME_LEN + 2:
                    break
                st.crc_errors += 1
                if buf[pos + FRAME_LEN: pos + FRAME_LEN + 2] == SYNC:
                    pos += FRAME_LEN
                else:
                    st.garbage_bytes += 2
                    pos += 2
                continue
            _, seq, ru, ry, status = _BODY.unpack(body)
            out.append(RawSample(seq, seq * dt, ru * su, ry * sy, status))
            st.frames += 1
            pos += FRAME_LEN
        del buf[:pos]
        return out

    def flush(self) -> list[RawSample]:
        """End of stream: whatever is still buffered becomes a verdict."""
        out: list[RawSample] = []
        buf = self._buf
        if len(buf) >= FRAME_LEN and buf[:2] == SYNC:
            # a final frame with a bad CRC that had no successor to confirm alignment
            body = bytes(buf[2:20])
            if crc16(body) != (buf[20] | (buf[21] << 8)):
                self.stats.crc_errors += 1
                del buf[:FRAME_LEN]
            else:  # pragma: no cover - feed() consumes good frames
                out = self.feed(b"")
        if buf:
            self.stats.garbage_bytes += len(buf)
            buf.clear()
        return out


_HEX4 = frozenset(b"0123456789ABCDEF")


@dataclass
class AsciiParser:
    """Incremental decoder of ``seq,t,u,y[*HHHH]`` lines.

    ``checksum``: ``"auto"`` (require it once one line carried it), ``"required"``
    or ``"none"`` (accept lines with or without; never require).
    """

    checksum: str = "auto"
    stats: ParserStats = field(default_factory=ParserStats)
    _buf: bytearray = field(default_factory=bytearray, repr=False)
    _seen_checksum: bool = False
    _overlong: bool = False

    def feed(self, data: bytes) -> list[RawSample]:
        self.stats.bytes += len(data)
        buf = self._buf
        buf += data
        out: list[RawSample] = []
        start = 0
        while True:
            end = buf.find(b"\n", start)
            if end < 0:
                break
            line = bytes(buf[start:end])
            start = end + 1
            if self._overlong:          # tail of a line already judged too long
                self._overlong = False
                self.stats.garbage_bytes += len(line) + 1
                continue
            sample = self._line(line)
            if sample is not None:
                out.append(sample)
        del buf[:start]
        if len(buf) > MAX_LINE:
            self.stats.malformed += 1 if not self._overlong else 0
            self.stats.garbage_bytes += len(buf)
            self._overlong = True
            buf.clear()
        return out

    def flush(self) -> list[RawSample]:
        """End of stream: an unterminated last line is judged as a line."""
        buf = self._buf
        out: list[RawSample] = []
        if buf and not self._overlong:
            s = self._line(bytes(buf))
            if s is not None:
                out.append(s)
        elif buf:
            self.stats.garbage_bytes += len(buf)
        buf.clear()
        self._overlong = False
        return out

    def _reject(self, line: bytes, crc: bool = False) -> None:
        """A line with a bad checksum is a damaged frame; anything else is garbage."""
        if crc:
            self.stats.crc_errors += 1
        else:
            self.stats.malformed += 1
            self.stats.garbage_bytes += len(line) + 1

    def _line(self, line: bytes) -> RawSample | None:
        if line.endswith(b"\r"):
            line = line[:-1]
        if not line:
            self.stats.garbage_bytes += 1
            return None
        star = line.rfind(b"*")
        if star >= 0:
            body, tail = line[:star], line[star + 1:]
            if len(tail) != 4 or not _HEX4.issuperset(tail) or crc16(body) != int(tail, 16):
                self._reject(line, crc=True)
                return None
            if self.checksum == "auto":
                self._seen_checksum = True
        else:
            body = line
            if self.checksum == "required" or (self.checksum == "auto" and self._seen_checksum):
                self._reject(line)
                return None
        sample = _parse_fields(body)
        if sample is None:
            self._reject(line)
            return None
        self.stats.frames += 1
        return sample


def _parse_fields(body: bytes) -> RawSample | None:
    parts = body.split(b",")
    if len(parts) != 4:
        return None
    s = parts[0]
    if not s or len(s) > 10 or not s.isdigit():
        return None
    try:
        t, u, y = float(parts[1]), float(parts[2]), float(parts[3])
    except ValueError:
        return None
    if not (math.isfinite(t) and math.isfinite(u) and math.isfinite(y)):
        return None
    return RawSample(int(s), t, u, y, 0)


@dataclass
class AutoParser:
    """Detects the format from the data: feeds both parsers until one wins.

    A format wins with 2 good frames; the loser's counts are discarded (its view
    of the other format is all garbage by construction).
    """

    rate: float = 1.0
    scale_u: float = SCALE_U
    scale_y: float = SCALE_Y
    checksum: str = "auto"
    stats: ParserStats = field(default_factory=ParserStats)
    winner: object = None
    _bin: BinaryParser | None = None
    _asc: AsciiParser | None = None
    _pending_b: list = field(default_factory=list)
    _pending_a: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self._bin = BinaryParser(self.rate, self.scale_u, self.scale_y)
        self._asc = AsciiParser(self.checksum)

    @property
    def format(self) -> str | None:
        if self.winner is None:
            return None
        return "binary" if isinstance(self.winner, BinaryParser) else "ascii"

    def feed(self, data: bytes) -> list[RawSample]:
        if self.winner is not None:
            return self.winner.feed(data)
        self._pending_b += self._bin.feed(data)
        self._pending_a += self._asc.feed(data)
        for parser, pending in ((self._bin, self._pending_b), (self._asc, self._pending_a)):
            if len(pending) >= 2:
                return self._choose(parser, pending)
        return []

    def _choose(self, parser, pending: list) -> list[RawSample]:
        self.winner = parser
        for k, v in parser.stats.__dict__.items():
            setattr(self.stats, k, getattr(self.stats, k) + v)
        parser.stats = self.stats   # from now on the winner counts into the shared object
        return list(pending)

    def flush(self) -> list[RawSample]:
        if self.winner is not None:
            return self.winner.flush()
        # Undecided at the end: take whichever found more frames.
        for p in (self._bin, self._asc):
            p_pending = self._pending_b if p is self._bin else self._pending_a
            p_pending += p.flush()
        if len(self._pending_b) >= len(self._pending_a) and self._pending_b:
            return self._choose(self._bin, self._pending_b)
        if self._pending_a:
            return self._choose(self._asc, self._pending_a)
        self.stats.garbage_bytes += self._bin.stats.bytes
        self.stats.bytes += self._bin.stats.bytes
        return []


def make_parser(fmt: str = "auto", rate: float = 1.0, scale_u: float = SCALE_U,
                scale_y: float = SCALE_Y, checksum: str = "auto", stats: ParserStats | None = None):
    """Parser for ``fmt`` in ``auto | ascii | binary``, counting into ``stats`` if given."""
    stats = stats if stats is not None else ParserStats()
    if fmt == "binary":
        return BinaryParser(rate, scale_u, scale_y, stats=stats)
    if fmt == "ascii":
        return AsciiParser(checksum, stats=stats)
    if fmt == "auto":
        return AutoParser(rate, scale_u, scale_y, checksum, stats=stats)
    raise ValueError(f"unknown frame format {fmt!r}; choose auto, ascii or binary")
