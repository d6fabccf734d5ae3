"""Byte-fed frame parser: splits, merges, garbage, bad checksums, gaps; fuzzed for fabrication."""

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gimbal import pelco as P
from gimbal.framing import PelcoDParser, PelcoParser, PelcoPParser

GAP = 0.05


def frames_sample():
    return [
        P.encode_pan_tilt(1, 1, 0x20, 0, 0),
        P.encode_pan_tilt(1, -1, P.PAN_TURBO, 1, 0x3F),
        P.encode_stop(1),
        P.encode_pan_reply(1, 12345),
        P.encode_goto_preset(2, 7, "P"),
        P.encode_tilt_reply(5, 0x0D0A, "P"),  # CR LF inside
    ]


@pytest.mark.parametrize("frame", frames_sample())
def test_every_split_point(frame):
    for k in range(len(frame) + 1):
        p = PelcoParser("DP")
        got = p.feed(frame[:k], 0.0) + p.feed(frame[k:], 0.001)
        assert [g.to_bytes() for g in got] == [frame]


def test_several_frames_in_one_read_and_garbage_between():
    fs = frames_sample()
    stream = b"\x00\x13garbage" + fs[0] + fs[1] + b"\xaa\x55" + fs[2] + fs[3] + fs[4] + b"\xff" + fs[5]
    got = PelcoParser("DP").feed(stream)
    assert [g.to_bytes() for g in got] == fs


def test_d_only_and_p_only_parsers_ignore_the_other_envelope():
    d, p = P.encode_stop(1), P.encode_stop(1, "P")
    assert [c.protocol for c in PelcoDParser().feed(d + p + d)] == ["D", "D"]
    assert [c.protocol for c in PelcoPParser().feed(d + p + d)] == ["P"]


def test_resync_finds_a_frame_that_starts_inside_a_rejected_candidate():
    good = P.encode_pan_tilt(1, 1, 0x10, 0, 0)
    stream = bytes([0xFF, 0x01, 0x02]) + good  # truncated junk start; candidate fails checksum
    p = PelcoDParser()
    assert [c.to_bytes() for c in p.feed(stream)] == [good]
    assert p.stats.bad_frames >= 1


def test_bad_checksum_is_rejected():
    f = bytearray(P.encode_stop(1))
    f[-1] ^= 0x80
    assert PelcoDParser().feed(bytes(f)) == []


# the field bug from the facts file -----------------------------------------------------------
TRUNCATED = P.encode_pan_reply(1, 0x2382)[:6]  # last byte lost on the line: FF 01 00 59 23 82
NEXT = P.encode_pan_reply(1, 4500)  # the next, intact reply: 45.00 deg


def test_merged_reply_bug_is_real_without_byte_times():
    """Without times the 6 bytes of a truncated reply + the next reply's FF make a checksum-valid
    frame with a fabricated word (0x2382 = 90.90 deg), and the real reply is lost."""
    got = PelcoDParser().feed(TRUNCATED + NEXT)
    assert len(got) == 1 and got[0].kind == "pan_reply" and got[0].word == 0x2382
    assert P.checksum_d(TRUNCATED[1:6]) == 0xFF  # the merge is checksum-valid by construction


def test_gap_drops_the_partial_frame_and_the_real_reply_comes_through():
    p = PelcoDParser(max_gap_s=GAP)
    assert p.feed(TRUNCATED, 1.000) == []
    got = p.feed(NEXT, 1.100)  # 100 ms later: the next query's reply
    assert [(c.kind, c.word) for c in got] == [("pan_reply", 4500)]
    assert p.stats.gap_drops == 1


def test_per_byte_times_and_a_gap_inside_one_read():
    p = PelcoDParser(max_gap_s=GAP)
    data = TRUNCATED + NEXT
    times = [0.001 * i for i in range(6)] + [0.5 + 0.001 * i for i in range(7)]
    assert [c.word for c in p.feed(data, times)] == [4500]


# fuzz ----------------------------------------------------------------------------------------
@st.composite
def streams(draw):
    """Chunks of valid frames, truncated frames, and garbage; each chunk after a short or long
    pause.  Returns (data, times, chunks)."""
    rnd = random.Random(draw(st.integers(0, 2**32 - 1)))
    chunks = []
    for _ in range(draw(st.integers(1, 25))):
        what = rnd.choice(["frame", "frame", "trunc", "garbage", "syncs"])
        proto = rnd.choice("DP")
        addr = rnd.randint(1, 255)
        f = P.PelcoCommand(proto, addr, rnd.choice([0, 0, 1, 0x88]), rnd.randrange(256),
                           rnd.randrange(256), rnd.randrange(256)).to_bytes()
        if what == "frame":
            b = f
        elif what == "trunc":
            b = f[: rnd.randint(1, len(f) - 1)]
        elif what == "garbage":
            b = bytes(rnd.randrange(256) for _ in range(rnd.randint(1, 12)))
        else:
            b = bytes(rnd.choice([0xFF, 0xA0, 0xAF, 0x00]) for _ in range(rnd.randint(1, 9)))
        long_gap = rnd.random() < 0.5
        chunks.append((b, long_gap, what))
    data, times, t = bytearray(), [], 0.0
    for b, long_gap, _ in chunks:
        t += 0.2 if long_gap else 0.001
        for i, x in enumerate(b):
            data.append(x)
            times.append(t + 0.001 * i)
        t = times[-1]
    return bytes(data), times, chunks


def _runs(data, times, max_gap):
    """Split the stream into runs with no inter-byte gap above max_gap."""
    runs, cur = [], bytearray()
    for i, b in enumerate(data):
        if i and times[i] - times[i - 1] > max_gap:
            runs.append(bytes(cur))
            cur = bytearray()
        cur.append(b)
    runs.append(bytes(cur))
    return runs


@settings(max_examples=300, deadline=None)
@given(streams(), st.integers(1, 13))
def test_fuzz_no_exception_no_fabrication_no_loss(stream, read_size):
    data, times, chunks = stream
    p = PelcoParser("DP", max_gap_s=GAP)
    got = []
    for i in range(0, len(data), read_size):
        got += p.feed(data[i:i + read_size], times[i:i + read_size])
    runs = _runs(data, times, GAP)
    # no fabrication: each frame is a checksum-valid run of consecutive bytes without a gap
    for c in got:
        raw = c.to_bytes()
        assert P.decode(raw) == c
        assert any(raw in r for r in runs)
    # no loss: every intact frame that starts after a long pause is delivered
    raws = [c.to_bytes() for c in got]
    for b, long_gap, what in chunks:
        if what == "frame" and long_gap:
            assert b in raws


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300), st.integers(1, 20))
def test_fuzz_random_bytes_without_times(data, read_size):
    p = PelcoParser("DP")
    whole = PelcoParser("DP").feed(data)
    got = []
    for i in range(0, len(data), read_size):
        got += p.feed(data[i:i + read_size])
    assert got == whole  # read boundaries never change the result
    for c in got:
        assert c.to_bytes() in data
