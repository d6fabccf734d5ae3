"""Pelco-D/P codec: known frames, round trips for every command, angle words."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gimbal import pelco as P
from gimbal.errors import GimbalError

addr_d = st.integers(0, 255)
addr_p = st.integers(1, 256)
proto_addr = st.one_of(st.tuples(st.just("D"), addr_d), st.tuples(st.just("P"), addr_p))
dirs = st.sampled_from([-1, 0, 1])
pan_bytes = st.one_of(st.integers(0, 0x3F), st.just(0xFF))
tilt_bytes = st.integers(0, 0x3F)


def test_known_pelco_d_frame_from_the_facts_file():
    # FF 01 00 04 20 00 25 = pan left at speed 0x20
    assert P.encode_pan_tilt(1, +1, 0x20, 0, 0) == bytes.fromhex("ff0100042000 25".replace(" ", ""))
    cmd = P.decode(bytes.fromhex("ff01000420 0025".replace(" ", "")))
    assert (cmd.kind, cmd.pan_dir, cmd.pan_byte, cmd.tilt_dir) == ("pan_tilt", 1, 0x20, 0)


def test_pelco_p_frame_layout_and_zero_based_address():
    f = P.encode_pan_tilt(1, -1, 0x10, +1, 0x08, protocol="P")
    assert f[:7] == bytes([0xA0, 0x00, 0x00, P.PAN_RIGHT | P.TILT_UP, 0x10, 0x08, 0xAF])
    x = 0
    for b in f[:7]:
        x ^= b
    assert f[7] == x
    assert P.decode(f).address == 1


def test_turbo_is_0xff_in_d_and_0x40_in_p_and_decodes_the_same():
    d = P.decode(P.encode_pan_tilt(3, 1, P.PAN_TURBO, 0, 0, "D"))
    p = P.decode(P.encode_pan_tilt(3, 1, P.PAN_TURBO, 0, 0, "P"))
    assert d.data1 == 0xFF and p.data1 == 0x40
    assert d.pan_byte == p.pan_byte == P.PAN_TURBO and d.turbo and p.turbo


def test_direction_bits_combine_and_stop_is_all_zero():
    assert P.encode_pan_tilt(1, -1, 5, 1, 5)[3] == 0x0A  # up-right
    assert P.encode_pan_tilt(1, 1, 5, -1, 5)[3] == 0x14  # down-left
    assert P.encode_stop(1) == bytes([0xFF, 1, 0, 0, 0, 0, 1])
    assert P.encode_pan_tilt(1, 0, 0x3F, 0, 0x3F) == P.encode_stop(1)
    assert P.decode(P.encode_stop(7, "P")).kind == "stop"


@given(proto_addr, dirs, pan_bytes, dirs, tilt_bytes)
def test_pan_tilt_round_trip(pa, pd, pb, td, tb):
    proto, addr = pa
    f = P.encode_pan_tilt(addr, pd, pb, td, tb, proto)
    c = P.decode(f)
    assert (c.protocol, c.address) == (proto, addr)
    assert c.pan_dir == pd and c.tilt_dir == td
    assert c.kind == ("stop" if pd == td == 0 else "pan_tilt")
    if pd:
        assert c.pan_byte == pb
    if td:
        assert c.tilt_byte == tb
    assert P.encode(c) == f and c.to_bytes() == f


EXT = [
    (P.encode_set_preset, "set_preset", "preset"),
    (P.encode_clear_preset, "clear_preset", "preset"),
    (P.encode_goto_preset, "goto_preset", "preset"),
    (P.encode_set_pan_word, "set_pan", "word"),
    (P.encode_set_tilt_word, "set_tilt", "word"),
    (P.encode_pan_reply, "pan_reply", "word"),
    (P.encode_tilt_reply, "tilt_reply", "word"),
]


@pytest.mark.parametrize("enc,kind,field", EXT)
@given(pa=proto_addr, value=st.integers(0, 0xFFFF))
def test_extended_round_trip(enc, kind, field, pa, value):
    proto, addr = pa
    if field == "preset":
        value &= 0xFF
    f = enc(addr, value, proto)
    c = P.decode(f)
    assert c.kind == kind and c.address == addr and c.protocol == proto
    assert getattr(c, field) == value
    assert c.pan_dir == 0 and c.tilt_dir == 0
    assert P.encode(c) == f


@pytest.mark.parametrize("proto,addr", [("D", 1), ("P", 1), ("D", 255), ("P", 256)])
def test_queries(proto, addr):
    assert P.decode(P.encode_query_pan(addr, proto)).kind == "query_pan"
    assert P.decode(P.encode_query_tilt(addr, proto)).kind == "query_tilt"
    # the reply from the facts file: FF addr 00 59 MSB LSB sum
    r = P.encode_pan_reply(1, 0x1234)
    assert r == bytes([0xFF, 1, 0, 0x59, 0x12, 0x34, (1 + 0x59 + 0x12 + 0x34) & 0xFF])


@given(st.binary(min_size=0, max_size=10))
def test_decode_raises_only_gimbal_errors_and_accepts_only_valid_frames(data):
    try:
        c = P.decode(data)
    except P.PelcoDecodeError:
        return
    assert P.encode(c) == data  # anything accepted re-encodes to the same bytes


def test_bad_checksum_and_bad_etx_are_rejected_with_a_message():
    f = bytearray(P.encode_stop(1))
    f[6] ^= 1
    with pytest.raises(P.PelcoDecodeError, match="checksum"):
        P.decode(f)
    g = bytearray(P.encode_stop(1, "P"))
    g[6] = 0x00
    with pytest.raises(P.PelcoDecodeError, match="ETX"):
        P.decode(g)


@pytest.mark.parametrize(
    "call",
    [
        lambda: P.encode_pan_tilt(1, 2, 0, 0, 0),
        lambda: P.encode_pan_tilt(1, 1, 0x40, 0, 0),
        lambda: P.encode_pan_tilt(1, 0, 0, 1, 0xFF),
        lambda: P.encode_stop(256),
        lambda: P.encode_stop(0, "P"),
        lambda: P.encode_stop(1, "X"),
        lambda: P.encode_goto_preset(1, 300),
        lambda: P.encode_set_pan_word(1, 70000),
        lambda: P.word_to_pan_deg(36000),
        lambda: P.tilt_deg_to_word(0.0, "horizon"),
    ],
)
def test_user_errors_name_the_allowed_values(call):
    with pytest.raises(GimbalError, match="allowed|use"):
        call()


@given(st.floats(-720, 720, allow_nan=False))
def test_pan_word_round_trip_and_wrap(deg):
    back = P.word_to_pan_deg(P.pan_deg_to_word(deg))
    assert -180 < back <= 180
    assert abs(P.wrap_pan_deg(back - deg)) <= 0.005 + 1e-9


@pytest.mark.parametrize("zero", ["level", "zenith"])
@given(deg=st.floats(-89, 89, allow_nan=False))
def test_tilt_word_round_trip(zero, deg):
    assert abs(P.word_to_tilt_deg(P.tilt_deg_to_word(deg, zero), zero) - deg) <= 0.005 + 1e-9


def test_tilt_word_conventions():
    assert P.tilt_deg_to_word(0.0, "level") == 0
    assert P.tilt_deg_to_word(-10.0, "level") == 1000  # Pelco words grow downward
    assert P.tilt_deg_to_word(90.0, "zenith") == 0  # family quirk: native 0 = zenith
    assert P.tilt_deg_to_word(0.0, "zenith") == 9000
    assert P.pan_deg_to_word(-90.0) == 27000
    assert P.wrap_pan_deg(180.0) == 180.0 and P.wrap_pan_deg(-180.0) == 180.0


def test_wrap_pan_float_path_equals_array_path_to_the_bit():
    """A plain float is wrapped without numpy (per-frame hot path); it must give the array route's
    bits, the sign of a zero included (np.ceil gives -0.0 on (-1, 0])."""
    import math

    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-1e4, 1e4, 20_000), rng.uniform(-400, 400, 20_000),
                        [180.0, -180.0, 540.0, -540.0, 0.0, -0.0, 360.0, -360.0, 1e-300, -1e-300,
                         math.nextafter(180.0, 0), math.nextafter(180.0, 360), math.nan, math.inf]])
    with np.errstate(invalid="ignore"):     # inf - inf in the array route: NaN, as intended
        arr = P.wrap_pan_deg(x)
        got_all = [P.wrap_pan_deg(float(v)) for v in x]
    for v, w, got in zip(x, arr, got_all):
        assert type(got) is float
        if math.isnan(w):
            assert math.isnan(got)
        else:
            assert got == w and math.copysign(1.0, got) == math.copysign(1.0, w), v
