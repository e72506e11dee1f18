"""Frame codecs, parsers and sequence accounting (creep_online.io.frames / sequence / can_frames)."""
from __future__ import annotations

import struct

import pytest

from creep_online.io import can_frames as cf
from creep_online.io.frames import (FRAME_LEN, AsciiParser, AutoParser, BinaryParser, crc16, encode_ascii,
                                    encode_binary, encode_binary_raw, make_parser)
from creep_online.io.sequence import SequenceTracker


def _crc_bitwise(data: bytes) -> int:
    """CRC-16/CCITT-FALSE done the slow, textbook way (independent of binascii)."""
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1          # the catalogue check value
    for data in (b"", b"\x00", b"\xaa\x55\x10\x00", bytes(range(256))):
        assert crc16(data) == _crc_bitwise(data)


def test_binary_layout_matches_the_spec():
    f = encode_binary_raw(7, -3, 123456, status=0x81)
    assert len(f) == FRAME_LEN == 22
    assert f[:2] == b"\xaa\x55"
    length, seq, u, y, status = struct.unpack("<HIiiI", f[2:20])
    assert (length, seq, u, y, status) == (16, 7, -3, 123456, 0x81)
    assert struct.unpack("<H", f[20:])[0] == _crc_bitwise(f[2:20])


def test_binary_roundtrip_any_chunking():
    frames = b"".join(encode_binary(i, 0.5 * i, -1e-3 * i) for i in range(50))
    for step in (1, 3, 7, 22, 23, 1000):
        p = BinaryParser(rate=1000.0)
        out = []
        for k in range(0, len(frames), step):
            out += p.feed(frames[k:k + step])
        out += p.flush()
        assert [s.seq for s in out] == list(range(50))
        assert out[10].u == pytest.approx(5.0, abs=1e-6) and out[10].y == pytest.approx(-1e-2, abs=1e-6)
        assert out[10].t == pytest.approx(0.01)
        assert p.stats.garbage_bytes == p.stats.crc_errors == p.stats.malformed == 0


def test_binary_resync_after_garbage_and_crc_errors():
    good = [encode_binary(i, i, i) for i in range(6)]
    bad = bytearray(good[2])
    bad[10] ^= 0x04
    stream = b"\x01\x02\x03" + good[0] + b"\xaa" + b"zz" + good[1] + bytes(bad) + good[3] + b"\x55\x55" + good[4] + good[5]
    p = BinaryParser()
    out = p.feed(stream) + p.flush()
    assert [s.seq for s in out] == [0, 1, 3, 4, 5]
    assert p.stats.crc_errors == 1
    assert p.stats.garbage_bytes == 3 + 3 + 2
    assert p.stats.malformed == 0


def test_binary_rejects_wrong_length_field():
    f = bytearray(encode_binary(1, 1, 1))
    f[2] = 17
    p2 = BinaryParser()
    out = p2.feed(bytes(f) + encode_binary(2, 2, 2))
    assert [s.seq for s in out] == [2]
    assert p2.stats.malformed == 1


def test_ascii_roundtrip_exact_and_checksum():
    lines = b"".join(encode_ascii(i, i * 1e-4, 0.1 * i, 1.0 / 3 + i) for i in range(20))
    p = AsciiParser()
    out = p.feed(lines)
    assert [s.seq for s in out] == list(range(20))
    assert out[7].t == 7e-4 and out[7].u == 0.1 * 7 and out[7].y == 1.0 / 3 + 7   # repr round-trips
    assert p.stats.crc_errors == 0


def test_ascii_detects_every_single_bit_flip():
    line = encode_ascii(12345, 1.2345, -0.5, 0.987654321)
    for i in range(len(line) - 1):
        if line[i] == ord("*"):
            continue
        for bit in range(8):
            b = bytearray(line)
            b[i] ^= 1 << bit
            p = AsciiParser(checksum="required")
            out = p.feed(bytes(b)) + p.flush()
            assert out == [], (i, bit)
            assert p.stats.crc_errors + p.stats.malformed >= 1


def test_ascii_auto_requires_checksum_once_seen():
    p = AsciiParser()
    out = p.feed(b"1,0.1,2,3\n" + encode_ascii(2, 0.2, 2, 3) + b"3,0.3,2,3\n")
    assert [s.seq for s in out] == [1, 2]
    assert p.stats.malformed == 1


def test_ascii_garbage_and_overlong_lines():
    p = AsciiParser()
    junk = b"x" * 500
    out = p.feed(b"hello\n" + junk + b"\n" + encode_ascii(5, 0.5, 1, 2) + b"nan,1,2,3\n" + b"1,2,3\n")
    assert [s.seq for s in out] == [5]
    assert p.stats.garbage_bytes == 6 + 501 + 10 + 6
    assert p.stats.malformed == 4


@pytest.mark.parametrize("fmt", ["ascii", "binary"])
def test_auto_parser_detects_format(fmt):
    data = b"".join((encode_ascii(i, i / 10, 1, 2) if fmt == "ascii" else encode_binary(i, 1, 2)) for i in range(10))
    p = AutoParser(rate=10.0)
    out = []
    for k in range(0, len(data), 5):
        out += p.feed(data[k:k + 5])
    assert p.format == fmt
    assert [s.seq for s in out] == list(range(10))
    assert p.stats.frames == 10 and p.stats.garbage_bytes == 0


def test_make_parser_rejects_unknown_format():
    with pytest.raises(ValueError):
        make_parser("morse")


# ------------------------------------------------------------------ sequence accounting
def _run(seqs, window=4, modulus=None):
    tr = SequenceTracker(window=window, modulus=modulus)
    out = []
    for s in seqs:
        out += [k for k, _ in tr.push(s, s)]
    out += [k for k, _ in tr.flush()]
    return out, tr.stats


def test_sequence_in_order():
    out, st = _run(range(10))
    assert out == list(range(10)) and st.missing == st.duplicates == st.reordered == 0


def test_sequence_gap_dup_reorder():
    seqs = [0, 1, 2, 4, 3, 5, 5, 6, 8, 9, 10, 11, 12, 13, 14]
    out, st = _run(seqs)
    assert out == [0, 1, 2, 3, 4, 5, 6, 8, 9, 10, 11, 12, 13, 14]
    assert (st.reordered, st.duplicates, st.missing, st.gaps) == (1, 1, 1, 1)


def test_sequence_late_after_give_up():
    out, st = _run([0, 2, 3, 4, 5, 6, 7, 1, 8])
    assert 1 not in out
    assert st.missing == 1 and st.late == 1


def test_sequence_remembers_only_the_last_history_of_lost_numbers():
    """The lost numbers kept to tell a late sample from a duplicate are bounded by ``history``: a number lost
    longer ago than that arrives as a duplicate, a recent one as late; neither is delivered."""
    tr = SequenceTracker(window=2, history=4)
    out = [k for s in (0, 4, 5, 6, 10, 11, 12) for k, _ in tr.push(s, s)]
    assert out == [0, 4, 5, 6, 10, 11, 12]
    assert (tr.stats.gaps, tr.stats.missing) == (2, 6)
    assert tr.push(1, 1) == [] and tr.push(8, 8) == []
    assert (tr.stats.duplicates, tr.stats.late, tr.stats.delivered) == (1, 1, 7)


def test_sequence_wraps_and_resets():
    seqs = [65533, 65534, 65535, 0, 1, 2]
    out, st = _run(seqs, modulus=65536)
    assert out == [65533, 65534, 65535, 65536, 65537, 65538]
    assert st.missing == 0
    out, st = _run([10, 11, 12, 5_000_000, 5_000_001])
    assert st.resets == 1 and out[-1] == 5_000_001


# ------------------------------------------------------------------ CAN frames vs the DBC
def test_can_encoders_agree_with_cantools():
    dec = cf.CanDecoder()
    db = dec.db
    fid, data, fd = cf.encode_sample(65535, -1.23456, 0.654321)
    sig = db.decode_message(fid, data)
    assert sig["Counter"] == 65535 and sig["U"] == pytest.approx(-1.23456) and sig["Y"] == pytest.approx(0.654321)
    fid, data, fd = cf.encode_block(2**32 - 3, 5, [0.1 * i for i in range(7)], [-0.2 * i for i in range(7)])
    assert fd and len(data) == 64
    out = dec.decode(fid, data)
    assert [s.seq for s in out] == [(2**32 - 3 + i) % 65536 for i in range(7)]
    assert [s.y for s in out] == pytest.approx([-0.2 * i for i in range(7)], abs=1e-6)
    assert all(s.status == 5 for s in out)


def test_can_pair_needs_its_input_generation():
    dec = cf.CanDecoder()
    assert dec.decode(*cf.encode_pair(10, 1, 1, 0.5, 0.6)[:2]) == []
    assert dec.stats.no_input == 2
    dec.decode(*cf.encode_input(1, 2.5)[:2])
    out = dec.decode(*cf.encode_pair(12, 1, 2, 0.5, -0.6)[:2])
    assert [(s.seq, s.u) for s in out] == [(12, 2.5)]          # generation 2 unknown: refused
    assert out[0].y == pytest.approx(0.5, abs=1e-5)
    dec.decode(*cf.encode_input(2, 3.0)[:2])
    dec.decode(*cf.encode_input(10, 9.0)[:2])                  # 8 generations later: 2 and 1 are stale
    assert dec.decode(*cf.encode_pair(14, 1, 2, 0.1, 0.1)[:2]) == []
    assert dec.decode(0x7FF, b"\x00") == [] and dec.stats.other_frames == 1
    assert dec.decode(cf.ID_SAMPLE, b"\x00\x01") == [] and dec.stats.malformed == 1
