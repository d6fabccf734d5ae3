"""The Pelco-D/P codec and the byte-fed parser (``gimbal.framing.PelcoParser``) under garbage:
10^5 real frames mixed with noise, pure random bytes, and every split of a stream into reads.

"No frame fabricated" needs a stream where fabrication is distinguishable from luck: random noise
may itself contain a checksum-valid window (1 in 256 per sync byte), so noise bursts are redrawn
until they contain none.  Then every frame the parser returns must be one of the real frames.

Bounds asserted
---------------
* noise bursts separated from frames by line gaps (> max_gap_s, as on a real link): the parser
  returns exactly the real frames, in order -- none lost, none fabricated -- for 10^5 frames and
  any split into reads;
* noise with no sync byte glued to frames without any timing: again exactly the real frames;
* arbitrary noise glued to frames, or pure random bytes (10^5 frames' worth, 7*10^5 bytes): no
  exception escapes ``feed``; every returned frame is checksum-valid and is a run of consecutive
  input bytes, the runs appear in stream order without overlapping, and the parser's counters add up;
* ``decode`` on any 7/8 bytes either raises PelcoDecodeError or round-trips exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gimbal.framing import DEFAULT_MAX_GAP_S, PelcoParser
from gimbal.pelco import ETX_P, STX_P, SYNC_D, PelcoCommand, PelcoDecodeError, decode, encode
from stability_util import examples

BYTE_S = 10 / 9600  # one byte at 9600 baud, 8N1


def _valid_windows(buf: bytes) -> list[tuple[int, int]]:
    """(start, length) of every checksum-valid Pelco-D/P window in ``buf`` (reference, by brute force)."""
    out = []
    for i, b in enumerate(buf):
        if b == SYNC_D and i + 7 <= len(buf) and sum(buf[i + 1:i + 6]) & 0xFF == buf[i + 6]:
            out.append((i, 7))
        if b == STX_P and i + 8 <= len(buf) and buf[i + 6] == ETX_P:
            x = 0
            for c in buf[i:i + 7]:
                x ^= c
            if x == buf[i + 7]:
                out.append((i, 8))
    return out


def _random_frame(rng) -> bytes:
    proto = "D" if rng.random() < 0.7 else "P"
    addr = int(rng.integers(0, 256)) if proto == "D" else int(rng.integers(1, 257))
    return encode(PelcoCommand(proto, addr, *(int(v) for v in rng.integers(0, 256, 4))))


def _noise(rng, n, allow_sync=True) -> bytes:
    while True:
        if allow_sync:
            b = bytes(rng.integers(0, 256, n).astype(np.uint8))
        else:
            b = bytes(rng.choice(np.setdiff1d(np.arange(256), [SYNC_D, STX_P]), n).astype(np.uint8))
        if not _valid_windows(b):
            return b


def _stream(rng, n_frames, noise_p=0.3, gaps=True, allow_sync=True):
    """Real frames with noise bursts between them; per-byte times with a line gap around each burst."""
    data, times, frames = bytearray(), [], []
    t = 0.0
    for _ in range(n_frames):
        if rng.random() < noise_p:
            nz = _noise(rng, int(rng.integers(1, 13)), allow_sync)
            t += 1.2 * DEFAULT_MAX_GAP_S if gaps else 0.0
            for b in nz:
                data.append(b)
                times.append(t)
                t += BYTE_S
            t += 1.2 * DEFAULT_MAX_GAP_S if gaps else 0.0
        f = _random_frame(rng)
        frames.append(f)
        for b in f:
            data.append(b)
            times.append(t)
            t += BYTE_S
        t += float(rng.uniform(0.0, 0.01))  # an ordinary pause between frames, below max_gap_s
    return bytes(data), times, frames


def _feed(parser, data, times, rng):
    out = []
    i = 0
    while i < len(data):
        n = int(rng.integers(1, 65))
        out += parser.feed(data[i:i + n], None if times is None else times[i:i + n])
        i += n
    return out


def _assert_runs_of_the_stream(decoded, data):
    """Each decoded frame is checksum-valid and a run of consecutive input bytes, in stream order."""
    valid = set(_valid_windows(data))
    pos = 0
    for cmd in decoded:
        raw = encode(cmd)
        assert decode(raw) == cmd
        j = data.find(raw, pos)
        while j >= 0 and (j, len(raw)) not in valid:
            j = data.find(raw, j + 1)
        assert j >= 0, f"frame {raw.hex(' ')} is not a run of the input after byte {pos}"
        pos = j + len(raw)


def test_hundred_thousand_frames_in_noise_none_lost_none_fabricated():
    rng = np.random.default_rng(20240607)
    data, times, frames = _stream(rng, 100_000)
    parser = PelcoParser("DP")
    decoded = _feed(parser, data, times, rng)
    assert [encode(c) for c in decoded] == frames
    # the noise held sync bytes that began false frames (bad checksums): the resync was exercised
    assert parser.stats.frames == 100_000 and parser.stats.bad_frames > 0


@examples(60)
@given(st.integers(0, 2**32 - 1), st.integers(1, 60), st.floats(0.0, 1.0))
def test_any_split_and_noise_level_with_gaps(seed, n_frames, noise_p):
    rng = np.random.default_rng(seed)
    data, times, frames = _stream(rng, n_frames, noise_p)
    decoded = _feed(PelcoParser("DP"), data, times, rng)
    assert [encode(c) for c in decoded] == frames


@examples(60)
@given(st.integers(0, 2**32 - 1), st.integers(1, 60), st.floats(0.0, 1.0))
def test_sync_free_noise_needs_no_timing(seed, n_frames, noise_p):
    rng = np.random.default_rng(seed)
    data, _, frames = _stream(rng, n_frames, noise_p, gaps=False, allow_sync=False)
    decoded = _feed(PelcoParser("DP"), data, None, rng)
    assert [encode(c) for c in decoded] == frames


@examples(60)
@given(st.integers(0, 2**32 - 1), st.integers(1, 60), st.floats(0.0, 1.0), st.sampled_from(["D", "P", "DP"]))
def test_untimed_noise_glued_to_frames_never_fabricates(seed, n_frames, noise_p, protocols):
    """No timing and noise that may hold sync bytes: a noise tail + a frame's head can form a
    checksum-valid window (the facts file's merged-reply bug); without times the parser cannot
    know, but it still returns only real runs of the input, in order."""
    rng = np.random.default_rng(seed)
    data, _, _ = _stream(rng, n_frames, noise_p, gaps=False)
    parser = PelcoParser(protocols)
    decoded = _feed(parser, data, None, rng)
    assert all(c.protocol in protocols for c in decoded)
    _assert_runs_of_the_stream(decoded, data)
    assert parser.stats.frames == len(decoded)


def test_random_bytes_for_a_hundred_thousand_frames():
    rng = np.random.default_rng(7)
    data = bytes(rng.integers(0, 256, 700_000).astype(np.uint8))
    times = list(np.cumsum(rng.exponential(BYTE_S * 3, len(data))))
    for t in (None, times):
        parser = PelcoParser("DP")
        decoded = _feed(parser, data, t, rng)
        _assert_runs_of_the_stream(decoded, data)
        s = parser.stats
        assert s.frames == len(decoded) <= len(_valid_windows(data))
        # every byte is accounted for: in a frame, skipped as garbage, or still pending / gap-dropped
        frame_bytes = sum(7 if c.protocol == "D" else 8 for c in decoded)
        assert frame_bytes + s.garbage_bytes + len(parser.pending) <= len(data)
        if t is None:  # no gap drops: each rejected candidate discards exactly its sync byte
            assert frame_bytes + s.garbage_bytes + s.bad_frames + len(parser.pending) == len(data)


@examples(400)
@given(st.one_of(st.binary(min_size=7, max_size=8),
                 st.builds(lambda b, k: bytes([SYNC_D]) + b[:6] if k else bytes([STX_P]) + b,
                           st.binary(min_size=7, max_size=7), st.booleans())))
def test_decode_raises_or_round_trips(raw):
    try:
        cmd = decode(raw)
    except PelcoDecodeError:
        return
    assert encode(cmd) == raw


@pytest.mark.parametrize("max_gap", [0.001, DEFAULT_MAX_GAP_S, 1.0])
def test_merged_reply_across_a_gap_is_dropped(max_gap):
    """The field bug from the facts file: a truncated reply, a pause, then the next reply; the merged
    bytes would be checksum-valid with a fabricated word.  With the gap longer than max_gap_s the
    truncated part is dropped and only the second, real reply comes out."""
    from gimbal.pelco import encode_pan_reply

    first, second = encode_pan_reply(1, 1234), encode_pan_reply(1, 4321)
    trunc = first[:4]
    data = trunc + second
    t_gap = 2 * max_gap
    times = [0.0] * len(trunc) + [t_gap + i * 1e-4 for i in range(len(second))]
    decoded = PelcoParser("D", max_gap_s=max_gap).feed(data, times)
    assert [encode(c) for c in decoded] == [second]
