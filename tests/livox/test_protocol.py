"""Livox SDK v1 protocol: CRCs, control frames and data packets (round trips, every drop reason)."""

import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from foveatrack.livox import protocol as P


def _crc16_bitwise(data: bytes, init: int) -> int:
    crc = init
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def _crc32_bitwise(data: bytes, seed: int) -> int:
    # FastCRC32::crc32_calc as in the Livox SDK: register = seed ^ ~0, reflected 0xEDB88320, out ^ ~0
    crc = seed ^ 0xFFFFFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


def test_crc16_is_mcrf4xx():
    # catalogue check value of CRC-16/MCRF4XX (init 0xFFFF) for "123456789"
    assert P.crc16_mcrf4xx(b"123456789", 0xFFFF) == 0x6F91
    assert P.crc16_mcrf4xx(b"123456789") == _crc16_bitwise(b"123456789", 0x4C49)


@given(st.binary(max_size=200))
def test_crc32_matches_bitwise_sdk_algorithm(data):
    assert P.crc32_livox(data) == _crc32_bitwise(data, 0x564F580A)
    assert P.crc32_livox(data) == zlib.crc32(data, 0x564F580A)


@given(
    st.sampled_from(P.CMD_TYPES),
    st.integers(0, 0xFFFF),
    st.integers(0, 255),
    st.integers(0, 255),
    st.binary(max_size=64),
)
def test_control_round_trip(cmd_type, seq, cmd_set, cmd_id, payload):
    f = P.ControlFrame(cmd_type, seq, cmd_set, cmd_id, payload)
    raw = P.encode_control(f)
    assert raw[0] == 0xAA and raw[1] == 1
    assert struct.unpack_from("<H", raw, 2)[0] == len(raw) == 15 + len(payload)
    assert P.crc16_mcrf4xx(raw[:9]) == 0  # residue of a reflected CRC with no xorout
    assert P.parse_control(raw) == f


def test_every_single_bit_flip_is_rejected():
    raw = P.make_cmd(P.CMD_ID_HANDSHAKE, 7, P.handshake_payload("192.168.1.50", 56000, 56001, 56002))
    for i in range(len(raw) * 8):
        bad = bytearray(raw)
        bad[i // 8] ^= 1 << (i % 8)
        frame, reason = P.parse_control_safe(bytes(bad))
        assert frame is None and reason in P.CTRL_DROP_REASONS, i


def test_control_truncation_and_oversize_reasons():
    raw = P.make_cmd(P.CMD_ID_HEARTBEAT, 1)
    seen = set()
    for n in range(len(raw)):
        frame, reason = P.parse_control_safe(raw[:n])
        assert frame is None
        seen.add(reason)
    assert {"ctrl_too_short", "ctrl_truncated"} <= seen
    assert P.parse_control_safe(raw + b"\0")[1] == "ctrl_oversize"
    assert P.parse_control_safe(b"\x55" + raw[1:])[1] == "ctrl_bad_sof"
    bad_ver = bytearray(raw)
    bad_ver[1] = 2
    assert P.parse_control_safe(bytes(bad_ver))[1] == "ctrl_bad_version"
    # a well-formed frame with cmd_type 7
    pre = struct.pack("<BBHBH", 0xAA, 1, 15, 7, 0)
    body = pre + struct.pack("<H", P.crc16_mcrf4xx(pre)) + b"\0\3"
    assert P.parse_control_safe(body + struct.pack("<I", P.crc32_livox(body)))[1] == "ctrl_unknown_cmd_type"


@given(st.binary(max_size=300))
def test_control_safe_never_raises(data):
    frame, reason = P.parse_control_safe(data)
    assert (frame is None) != (reason is None)


def test_payload_helpers_round_trip():
    assert P.parse_handshake(P.handshake_payload("10.0.0.7", 1, 2, 3)) == ("10.0.0.7", 1, 2, 3)
    assert P.handshake_payload("192.168.1.2", 0, 0)[:4] == bytes([192, 168, 1, 2])
    assert P.parse_handshake(P.handshake_payload("10.0.0.7", 1, 2, 3)[:8]) == ("10.0.0.7", 1, 2, 0)
    code, dev = P.parse_broadcast(P.broadcast_payload("0TFDG3B006H2Z11", 3))
    assert (code, dev) == ("0TFDG3B006H2Z11", 3)
    assert len(P.heartbeat_ack_payload()) == 7


# ------------------------------------------------------------------ data packets


def _random_points(rng, n, zero_every=7):
    xyz = np.round(rng.uniform(-300, 300, (n, 3)), 3)
    xyz[::zero_every] = 0.0
    refl = rng.integers(0, 256, n).astype(np.uint8)
    tag = rng.integers(0, 256, n).astype(np.uint8)
    return xyz, refl, tag


def test_packet_sizes_match_the_sdk_table():
    assert {dt: P.PACKET_LEN[dt] for dt in (0, 1, 2, 3, 4, 6)} == {
        0: 1318, 1: 918, 2: 1362, 3: 978, 4: 1362, 6: 42
    }


@pytest.mark.parametrize("data_type", [0, 2, 4])
def test_cartesian_round_trip(data_type):
    rng = np.random.default_rng(1)
    n = 5 * P.POINTS_PER_PACKET[data_type] * (2 if data_type == 4 else 1)
    xyz, refl, tag = _random_points(rng, n)
    rate = 240_000.0
    pk = P.encode_data_packets(xyz, refl, 1_000_000, rate, data_type=data_type, tag=tag)
    assert all(len(b) == P.PACKET_LEN[data_type] for b in pk)
    dec = P.DataDecoder(point_rate_hz=rate, keep_no_return=True)
    b = P.PointBatch.concat(dec.decode(pk))
    assert len(b) == n
    np.testing.assert_allclose(b.xyz, xyz, atol=1e-9)
    np.testing.assert_array_equal(b.reflectivity, refl)
    if data_type == 4:
        slot = np.arange(n) // 2
        np.testing.assert_array_equal(b.tag, tag)
    else:
        slot = np.arange(n)
        np.testing.assert_array_equal(b.tag, tag if data_type == 2 else 0)
    # packet stamp and in-packet offset are each rounded to the ns
    assert np.abs(b.t_ns - (1_000_000 + slot * 1e9 / rate)).max() <= 1.0
    assert dec.counters["packets"] == len(pk) and not dec.dropped


@pytest.mark.parametrize("data_type", [1, 3])
def test_spherical_round_trip_within_wire_resolution(data_type):
    rng = np.random.default_rng(2)
    xyz, refl, tag = _random_points(rng, 200)
    pk = P.encode_data_packets(xyz, refl, 0, 100_000.0, data_type=data_type, tag=tag)
    b = P.PointBatch.concat(P.DataDecoder(100_000.0).decode(pk))
    ok = np.any(xyz != 0, axis=1)
    r = np.linalg.norm(xyz[ok], axis=1)
    assert len(b) == ok.sum()
    # 0.5 mm range + 0.005 deg in each of two angles
    err = np.linalg.norm(b.xyz - xyz[ok], axis=1)
    assert np.all(err <= 0.0005 + r * np.deg2rad(0.005) * 1.5 + 1e-9)


def test_spherical_axes_follow_the_lidar_frame():
    # zenith 90 deg, azimuth 90 deg is +Y (left); zenith 0 is +Z (up); azimuth 0 is +X (forward)
    pts = np.zeros(1, P.packet_dtype(1))
    pts["hdr"]["version"] = 5
    pts["hdr"]["data_type"] = 1
    p = pts["pts"][0]
    p["depth"][:3] = 10_000
    p["zenith"][:3] = [9000, 9000, 0]
    p["azimuth"][:3] = [0, 9000, 0]
    b = P.decode_packet(pts.tobytes(), 100_000.0)
    np.testing.assert_allclose(b.xyz, [[10, 0, 0], [0, 10, 0], [0, 0, 10]], atol=1e-9)


def test_batched_decode_equals_packet_by_packet():
    rng = np.random.default_rng(3)
    xyz, refl, tag = _random_points(rng, 96 * 8)
    pk = P.encode_data_packets(xyz, refl, 5, 240_000.0, data_type=2, tag=tag)
    whole = P.PointBatch.concat(P.DataDecoder().decode(pk))
    parts = P.PointBatch.concat([P.decode_packet(b) for b in pk])
    for a, c in ((whole.xyz, parts.xyz), (whole.t_ns, parts.t_ns), (whole.tag, parts.tag)):
        np.testing.assert_array_equal(a, c)


def test_no_return_points_are_dropped_and_counted():
    xyz = np.zeros((96, 3))
    xyz[10] = [1, 2, 3]
    pk = P.encode_data_packets(xyz, np.ones(96), 0, 240_000.0)
    dec = P.DataDecoder()
    b = P.PointBatch.concat(dec.decode(pk))
    assert len(b) == 1 and dec.counters["no_return_points"] == 95
    assert b.t_ns[0] == round(10 * 1e9 / 240_000)


def test_utc_timestamp_type():
    pk = bytearray(P.encode_data_packets(np.ones((96, 3)), np.ones(96), 0, 240_000.0, timestamp_type=3)[0])
    pk[10:18] = bytes([26, 11, 23, 9]) + (1_500_000).to_bytes(4, "little")  # 2026-11-23 09:00 + 1.5 s
    b = P.decode_packet(bytes(pk))
    import datetime as dt

    t0 = int(dt.datetime(2026, 11, 23, 9, tzinfo=dt.timezone.utc).timestamp()) * 10**9 + 1_500_000_000
    assert b.t_ns[0] == t0
    pk[11] = 13  # month 13
    dec = P.DataDecoder()
    assert dec.decode([bytes(pk)]) == [] and dec.dropped["data_bad_timestamp"] == 1


def test_every_data_drop_reason():
    good = P.encode_data_packets(np.ones((96, 3)), np.ones(96), 0, 240_000.0)[0]
    cases = {
        "data_truncated_header": good[:17],
        "data_bad_version": b"\x04" + good[1:],
        "data_unknown_type": good[:9] + b"\x09" + good[10:],
        "data_unknown_timestamp_type": good[:8] + b"\x07" + good[9:],
        "data_truncated": good[:-1],
        "data_oversize": good + b"\0",
    }
    dec = P.DataDecoder()
    for reason, buf in cases.items():
        assert dec.decode([buf]) == []
        with pytest.raises(P.PacketError) as ei:
            P.decode_packet(buf)
        assert ei.value.reason == reason
    assert dict(dec.dropped) == {r: 1 for r in cases}
    assert dec.counters["packets"] == 0
    # IMU packets are counted, not dropped
    imu = bytes([5, 1, 1, 0, 0, 0, 0, 0, 0, 6]) + bytes(8) + bytes(24)
    assert dec.decode([imu]) == [] and dec.counters["imu_packets"] == 1


@settings(max_examples=300)
@given(st.lists(st.binary(max_size=1400), max_size=5), st.integers(0, 4))
def test_decoder_never_raises(garbage, dt):
    good = P.encode_data_packets(np.ones((96, 3)), np.ones(96), 0, 240_000.0, data_type=dt)
    # garbage with a plausible header too
    garbage = garbage + [bytes([5]) + g[1:] for g in garbage]
    dec = P.DataDecoder()
    out = P.PointBatch.concat(dec.decode(garbage + good + garbage))
    assert len(out) >= 96  # the good packet always gets through
    assert set(dec.dropped) <= set(P.DATA_DROP_REASONS)
