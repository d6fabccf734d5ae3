"""The head model's fast paths give what the general routes give, to the bit.

* a clean Pelco-D frame taken at once (``PelcoParser.take_clean_d``, used by ``feed`` and by
  ``PTS303H.receive``) vs the same bytes fed one at a time (the byte-by-byte route: a one-byte read
  never takes the fast path), on fuzzed streams with garbage, split and truncated frames, bad
  checksums, bit errors and gaps inside frames;
* the trig-free closed form without ripple (``_pos1``) vs ``float(_pos(...))``;
* the segment tables kept as a mirror vs rebuilt from the segments;
* the UART's numpy-free timing without random effects vs its numpy route.
"""

import copy
import pickle
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gimbal import pelco as P
from gimbal.framing import PelcoParser
from gimbal.pts303h import PTS303H, HeadParams, _pos, _pos1
from sim.virtual_uart import VirtualUart

GAP = 0.05


def fuzz_stream(rnd: random.Random, n_chunks: int):
    """(data, per-byte times): valid D/P frames (mostly D pan/tilt), frames with a flipped bit or a
    bad checksum, truncated frames, garbage and runs of sync bytes; short, long (> GAP) and
    in-frame pauses."""
    data, times, t = bytearray(), [], 0.0
    for _ in range(n_chunks):
        what = rnd.choice(["ptz", "ptz", "ptz", "frame", "flip", "badsum", "trunc", "garbage", "syncs"])
        proto = "D" if what == "ptz" else rnd.choice("DDP")
        addr = rnd.choice([1, 1, 1, 2])
        if what == "ptz":
            f = P.encode_pan_tilt(addr, rnd.choice([-1, 0, 1]), rnd.choice([0, 3, 0x20, 0x3F, P.PAN_TURBO]),
                                  rnd.choice([-1, 0, 1]), rnd.choice([0, 5, 0x3F]))
        elif rnd.random() < 0.3:
            f = rnd.choice([P.encode_query_pan(addr, proto), P.encode_query_tilt(addr, proto),
                            P.encode_set_pan(addr, rnd.uniform(-180, 180), proto),
                            P.encode_set_tilt(addr, rnd.uniform(-20, 50), proto, "zenith"),
                            P.encode_set_preset(addr, 3, proto), P.encode_goto_preset(addr, 3, proto)])
        else:
            f = P.PelcoCommand(proto, addr, rnd.choice([0, 0, 1, 0x88]), rnd.randrange(256),
                               rnd.randrange(256), rnd.randrange(256)).to_bytes()
        b = bytearray(f)
        if what == "flip":
            k = rnd.randrange(len(b))
            b[k] ^= 1 << rnd.randrange(8)
        elif what == "badsum":
            b[-1] = (b[-1] + rnd.randint(1, 255)) & 0xFF
        elif what == "trunc":
            b = b[: rnd.randint(1, len(b) - 1)]
        elif what == "garbage":
            b = bytearray(rnd.randrange(256) for _ in range(rnd.randint(1, 12)))
        elif what == "syncs":
            b = bytearray(rnd.choice([0xFF, 0xA0, 0xAF, 0x00]) for _ in range(rnd.randint(1, 9)))
        t += rnd.choice([0.2, 0.3, 0.001, 0.0])
        for i, x in enumerate(b):
            if i and rnd.random() < 0.03:
                t += rnd.choice([0.06, GAP, 0.02])   # a pause inside the frame (above, at, below GAP)
            data.append(x)
            times.append(t)
            t += rnd.choice([0.00104, 0.00104, 0.0])
    return bytes(data), times


def reads(rnd: random.Random, n: int):
    """Random read boundaries over n bytes."""
    i, out = 0, []
    while i < n:
        k = rnd.choice([1, 3, 7, 7, 7, 8, 14, 21, 50])
        out.append((i, min(n, i + k)))
        i += k
    return out


def parser_state(p: PelcoParser):
    return p.pending, p._last_t, vars(p.stats)


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["DP", "D"]), st.booleans())
def test_parser_fast_path_equals_byte_by_byte(seed, protocols, with_times):
    rnd = random.Random(seed)
    data, times = fuzz_stream(rnd, rnd.randint(1, 40))
    slow, fast = PelcoParser(protocols, GAP), PelcoParser(protocols, GAP)
    got_slow = [c for i, b in enumerate(data) for c in slow.feed(data[i:i + 1], times[i] if with_times else None)]
    got_fast = []
    for i, j in reads(rnd, len(data)):
        got_fast += fast.feed(data[i:j], times[i:j] if with_times else None)
    assert got_fast == got_slow
    assert parser_state(fast) == parser_state(slow)


def test_fast_path_is_taken_and_leaves_the_state_of_the_slow_route():
    f = P.encode_pan_tilt(1, 1, 0x20, -1, 0x10)
    times = [0.1 + 0.00104 * k for k in range(7)]
    fast = PelcoParser("DP", GAP)
    assert fast.take_clean_d(f, 0, times) == P.decode(f)
    slow = PelcoParser("DP", GAP)
    assert [c for k in range(7) for c in slow.feed(f[k:k + 1], times[k])] == [P.decode(f)]
    assert parser_state(fast) == parser_state(slow)
    # not taken (and nothing changed): bad checksum, a gap, a pending partial frame, P-only parser
    bad = f[:6] + bytes(((f[6] + 1) & 0xFF,))
    gap = times[:3] + [t + 0.051 for t in times[3:]]
    for p, data, ts in ((PelcoParser("DP", GAP), bad, times), (PelcoParser("DP", GAP), f, gap),
                        (PelcoParser("P", GAP), f, times)):
        before = parser_state(p)
        assert p.take_clean_d(data, 0, ts) is None
        assert parser_state(p) == before
    p = PelcoParser("DP", GAP)
    p.feed(b"\xff\x01", 0.0)
    assert p.take_clean_d(f, 0, times) is None and p.pending == b"\xff\x01"


def head_state(h: PTS303H):
    axes = [[(s.t0, s.t1, s.p0, s.v0, s.a, s.r, s.pinned) for s in ax.segs] for ax in (h._pan, h._tilt)]
    return (axes, list(h._rx_times), h._t_rx_last, h._t_now, h.frames_received, h.frames_ignored,
            dict(h._presets), parser_state(h._parser), h._pan.target_speed, h._tilt.target_speed)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["none", "at-rest", "always"]), st.booleans())
def test_head_fast_path_equals_byte_by_byte(seed, feedback, ripple):
    rnd = random.Random(seed)
    data, times = fuzz_stream(rnd, rnd.randint(1, 30))
    params = HeadParams(ripple_rel=0.02 if ripple else 0.0, tilt_min_deg=-5.0, tilt_max_deg=8.0)
    slow = PTS303H(params, unit_seed=seed % 7, feedback=feedback, tilt0_deg=3.0)
    fast = PTS303H(params, unit_seed=seed % 7, feedback=feedback, tilt0_deg=3.0)
    rep_slow = [r for i in range(len(data)) for r in slow.receive(data[i:i + 1], [times[i]])]
    rep_fast = []
    for i, j in reads(rnd, len(data)):
        rep_fast += fast.receive(data[i:j], times[i:j])
    assert rep_fast == rep_slow
    assert head_state(fast) == head_state(slow)
    t = np.linspace(times[0], times[-1] + 1.0, 97)
    assert all(np.array_equal(a, b) for a, b in zip(fast.angles_at(t), slow.angles_at(t)))
    if not ripple:
        pf, ps = fast.pose_segments(t[-1], t[-1]), slow.pose_segments(t[-1], t[-1])
        assert all(a.tobytes() == b.tobytes() for a, b in zip(pf, ps))


def test_head_fast_path_raises_like_the_slow_route_on_bytes_out_of_order():
    f = P.encode_pan_tilt(1, 1, 0x20, 0, 0)
    times = [0.1, 0.101, 0.102, 0.1, 0.104, 0.105, 0.106]
    heads = []
    for split in (False, True):
        h = PTS303H()
        with pytest.raises(ValueError, match="time order"):
            if split:
                for k in range(7):
                    h.receive(f[k:k + 1], [times[k]])
            else:
                h.receive(f, times)
        heads.append(head_state(h))
    assert heads[0] == heads[1]


@settings(max_examples=300, deadline=None)
@given(st.floats(-5, 5), st.floats(-200, 200), st.floats(-30, 30), st.floats(-50, 50), st.floats(-5, 5),
       st.sampled_from([0.0, 0.02]))
def test_pos1_is_pos_to_the_bit(t0, p0, v0, a, dt, r):
    omega, phi = 2 * np.pi * np.float64(1.37), 0.4
    for args in ((t0, p0, v0, a, r, omega, phi, t0 + dt), (t0, 0.0, 0.0, 0.0, r, omega, phi, t0 + dt),
                 (t0, -0.0, 0.0, 0.0, r, omega, phi, t0 + dt), (t0, -0.0, -0.0, 0.0, r, omega, phi, t0),
                 (t0, -0.0, -0.0, -0.0, r, omega, phi, t0)):
        want = float(_pos(*args))
        got = _pos1(*args)
        assert type(got) is float and got.hex() == want.hex()


def test_segment_tables_match_a_rebuild_through_many_commands_and_pruning():
    """The mirrored tables equal the segments (the mirror grows and compacts along the way)."""
    rnd = random.Random(5)
    h = PTS303H(HeadParams(ripple_rel=0.0, history_s=0.5), tilt0_deg=55.0)
    t = 0.0
    for k in range(400):
        t += rnd.choice([0.01, 0.1, 0.3])
        if rnd.random() < 0.1:
            frame = P.encode_set_pan(1, rnd.uniform(-180, 180))
            t += 0.5
        else:
            frame = P.encode_pan_tilt(1, rnd.choice([-1, 1]), rnd.choice([0x3F, 0x10, P.PAN_TURBO]),
                                      rnd.choice([-1, 0, 1]), 0x3F)
        h.receive(frame, t)
        h.advance_to(t + 0.011)
        for ax in (h._pan, h._tilt):
            want = np.array([(s.t0, s.p0, s.v0, s.a, s.r) for s in ax.segs]).T
            got = np.array(ax.arrays())
            assert got.tobytes() == want.tobytes()
            table, ripple = ax.pieces()
            assert table.flags.c_contiguous and table.tobytes() == want[:4].copy().tobytes()
            assert ripple is False
    assert h._pan._cols.shape[1] <= 256   # compacted, not grown without end


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([2400, 9600, 115200]), st.booleans())
def test_uart_timing_without_random_effects_equals_the_numpy_route(seed, baud, echo):
    """A line with bit errors and drops at rate 0 takes the numpy route and must deliver the same
    bytes at the same times as a line without them (the fast route)."""
    rnd = random.Random(seed)
    fx = {"echo"} if echo else set()
    plain = VirtualUart(baud, fx)
    numpy_route = VirtualUart(baud, fx | {"bit_errors", "drop"}, rng=np.random.default_rng(seed),
                              bit_error_rate=0.0, drop_rate=0.0)
    t = rnd.uniform(0, 2)
    for _ in range(30):
        data = bytes(rnd.randrange(256) for _ in range(rnd.choice([0, 1, 7, 8, 20])))
        t += rnd.choice([0.0, 0.001, 0.1])
        a, b = plain.send(data, t), numpy_route.send(data, t)
        assert a == b and [x[0].hex() for x in a] == [x[0].hex() for x in b]
        assert plain.line_free_at_s.hex() == numpy_route.line_free_at_s.hex()
        assert plain.pop_echo() == numpy_route.pop_echo()
    assert plain.bytes_sent == numpy_route.bytes_sent


def test_a_head_still_pickles_and_deep_copies_and_the_copy_runs_on_identically():
    h = PTS303H(HeadParams(ripple_rel=0.0), tilt0_deg=10.0)
    h.receive(P.encode_pan_tilt(1, 1, 0x30, -1, 0x20), 0.1)
    h.pose_segments(0.0, 0.2)
    heads = [h, pickle.loads(pickle.dumps(h)), copy.deepcopy(h)]
    for k in range(3, 40):   # enough commands to make the column mirror compact and grow
        for x in heads:
            x.receive(P.encode_pan_tilt(1, (-1) ** k, 0x10 + k, 1, 0x3F), 0.1 * k)
            x.advance_to(0.1 * k + 0.05)
    got = [x.pose_segments(3.8, 4.0) for x in heads]
    assert all(x.tobytes() == y.tobytes() for g in got[1:] for x, y in zip(g, got[0]))
