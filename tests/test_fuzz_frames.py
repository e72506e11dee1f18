"""Fuzzing the frame parsers (hypothesis): no exception escapes and no corrupt sample passes.

Streams of valid frames are damaged (1-3 bit flips per frame anywhere,
truncation, drops, duplicates, arbitrary garbage between frames), cut into
arbitrary chunks and fed to the parsers. Every decoded sample must be exactly
one of the samples that was sent, and an undamaged run of frames must come
through. The default suite runs a few hundred streams per format; the slow
run (``pytest -m slow``) 10^5 per format.
"""
from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from creep_online.io import can_frames as cf
from creep_online.io.frames import AsciiParser, AutoParser, BinaryParser, encode_ascii, encode_binary_raw

I32 = st.integers(-(2**31), 2**31 - 1)
OPS = st.sampled_from(["keep", "keep", "keep", "flip", "drop", "dup", "trunc", "garbage"])
FAST = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SLOW = settings(max_examples=100_000, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@st.composite
def damaged_stream(draw, kind: str):
    n = draw(st.integers(0, 25))
    seq0 = draw(st.integers(0, 2**32 - 30 if kind == "binary" else 10**9))
    sent, chunks, intact = [], [], []
    prev_clean = True
    for i in range(n):
        seq = seq0 + i
        if kind == "binary":
            u, y, status = draw(I32), draw(I32), draw(st.integers(0, 2**32 - 1))
            frame = encode_binary_raw(seq, u, y, status)
            key = (seq, u, y, status)
        else:
            t = draw(st.floats(0, 1e6, allow_nan=False))
            u = draw(st.floats(-1e9, 1e9, allow_nan=False))
            y = draw(st.floats(-1e9, 1e9, allow_nan=False))
            frame = encode_ascii(seq, t, u, y)
            key = (seq, t, u, y)
        sent.append(key)
        op = draw(OPS)
        if op == "garbage":
            chunks.append(draw(st.binary(min_size=1, max_size=40)))
            op = "keep"
            prev_clean = False
        if op == "keep":
            chunks.append(frame)
            if prev_clean:
                intact.append(key)
            prev_clean = True
            continue
        prev_clean = False
        if op == "flip":
            b = bytearray(frame)
            for _ in range(draw(st.integers(1, 3))):
                b[draw(st.integers(0, len(b) - 1))] ^= 1 << draw(st.integers(0, 7))
            if bytes(b) == frame:       # flips cancelled out: the frame is intact after all
                prev_clean = True
            chunks.append(bytes(b))
        elif op == "dup":
            chunks += [frame, frame]
            prev_clean = True
        elif op == "trunc":
            chunks.append(frame[:draw(st.integers(0, len(frame) - 1))])
    data = b"".join(chunks)
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=8)))
    pieces = [data[a:b] for a, b in zip([0] + cuts, cuts + [len(data)])]
    return sent, intact, pieces


def _key(kind, s):
    if kind == "binary":
        return (s.seq, round(s.u / 1e-6), round(s.y / 1e-6), s.status)
    return (s.seq, s.t, s.u, s.y)


def check(kind: str, stream) -> None:
    sent, intact, pieces = stream
    parser = BinaryParser(rate=1.0) if kind == "binary" else AsciiParser(checksum="required")
    out = []
    for p in pieces:
        out += parser.feed(p)
    out += parser.flush()
    allowed = set(sent)
    got = [_key(kind, s) for s in out]
    for g in got:
        assert g in allowed, f"corrupt sample passed: {g}"
        if kind == "ascii":
            assert all(math.isfinite(v) for v in g[1:])
    missing = set(intact) - set(got)
    assert not missing, f"intact frames lost: {sorted(missing)[:3]}"


@FAST
@given(damaged_stream("binary"))
def test_fuzz_binary_fast(stream):
    check("binary", stream)


@FAST
@given(damaged_stream("ascii"))
def test_fuzz_ascii_fast(stream):
    check("ascii", stream)


@FAST
@given(st.lists(st.binary(max_size=64), max_size=10))
def test_fuzz_auto_parser_arbitrary_bytes(pieces):
    p = AutoParser(rate=1.0)
    for piece in pieces:
        p.feed(piece)
    p.flush()
    assert p.stats.frames == 0 or p.format is not None


@FAST
@given(st.integers(0, 0x7FF), st.binary(max_size=64))
def test_fuzz_can_decoder_arbitrary_payloads(fid, data):
    dec = cf.CanDecoder()
    for s in dec.decode(fid, data):
        assert math.isfinite(s.u) and math.isfinite(s.y)


@pytest.mark.slow
@SLOW
@given(damaged_stream("binary"))
def test_fuzz_binary_slow(stream):
    check("binary", stream)


@pytest.mark.slow
@SLOW
@given(damaged_stream("ascii"))
def test_fuzz_ascii_slow(stream):
    check("ascii", stream)
