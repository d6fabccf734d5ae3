"""Livox SDK v1 datagrams fuzzed: truncated, oversize, wrong version / data type / timestamp type,
invalid UTC dates, random bytes (``foveatrack.livox.protocol``; facts file "SDK v1 data packets").

Each mutation applies ONE defect to a valid packet, so the drop reason it must be counted under is
known independently of the decoder's own classification.

Bounds asserted
---------------
* ``DataDecoder.decode`` never raises; every datagram is accounted for exactly once (accepted point
  packet, IMU packet, or one drop reason), and the counts per reason equal the mutations made;
* the valid packets among the garbage decode to exactly what they decode to alone (same points,
  times and reflectivities), all finite, times non-decreasing within each packet;
* a run of UTC-stamped packets with one invalid date keeps the valid ones (one-by-one fallback);
* ``parse_control`` raises only ``PacketError`` (so ``parse_control_safe``'s catch-all is never
  needed), with the reason of the one defect applied; random bytes give a listed reason.
"""

from __future__ import annotations

import struct
from collections import Counter

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from foveatrack.livox import protocol as lp
from stability_util import examples

RATE = 240_000.0
VALID_TS = (0, 1, 4)


def _valid_packet(rng, data_type, ts_type=0):
    n = lp.POINTS_PER_PACKET[data_type] * (2 if data_type == 4 else 1)
    xyz = rng.uniform(-500, 500, (n, 3))
    xyz[rng.random(n) < 0.1] = 0.0  # some no-return slots
    refl = rng.integers(0, 256, n)
    return lp.encode_data_packets(xyz, refl, int(rng.integers(0, 2**62)), RATE, data_type=data_type,
                                  tag=rng.integers(0, 256, n), timestamp_type=ts_type)[0]


def _imu_packet(rng):
    arr = np.zeros(1, lp.packet_dtype(6))
    arr["hdr"]["version"] = lp.DATA_VERSION
    arr["hdr"]["data_type"] = 6
    arr["pts"]["gyro_x"] = rng.normal()
    return arr.tobytes()


def _utc(buf, y, mo, d, h, us):
    b = bytearray(buf)
    b[8] = lp.TIMESTAMP_TYPE_UTC
    b[10:18] = bytes((y, mo, d, h)) + struct.pack("<I", us)
    return bytes(b)


MUTATIONS = ("valid", "imu", "truncate_header", "truncate", "oversize", "version", "data_type",
             "ts_type", "bad_utc", "good_utc")
EXPECT = {"truncate_header": "data_truncated_header", "truncate": "data_truncated", "oversize": "data_oversize",
          "version": "data_bad_version", "data_type": "data_unknown_type",
          "ts_type": "data_unknown_timestamp_type", "bad_utc": "data_bad_timestamp"}


def _mutate(rng, kind):
    dt = int(rng.choice(lp.POINT_DATA_TYPES))
    buf = _valid_packet(rng, dt, int(rng.choice(VALID_TS)))
    if kind == "valid":
        return buf
    if kind == "imu":
        return _imu_packet(rng)
    if kind == "truncate_header":
        return buf[: int(rng.integers(0, lp.HEADER_LEN))]
    if kind == "truncate":
        return buf[: int(rng.integers(lp.HEADER_LEN, len(buf)))]
    if kind == "oversize":
        return buf + bytes(rng.integers(0, 256, int(rng.integers(1, 200))).astype(np.uint8))
    b = bytearray(buf)
    if kind == "version":
        b[0] = int(rng.choice([v for v in range(256) if v != lp.DATA_VERSION]))
    elif kind == "data_type":
        b[9] = int(rng.choice([v for v in range(256) if v not in lp.PACKET_LEN]))
    elif kind == "ts_type":
        b[8] = int(rng.choice([v for v in range(256) if v not in VALID_TS and v != lp.TIMESTAMP_TYPE_UTC]))
    elif kind == "bad_utc":
        bad = [(20, 13, 1, 0), (20, 0, 1, 0), (20, 2, 30, 0), (20, 1, 1, 24), (255, 1, 0, 0)]
        y, mo, d, h = bad[int(rng.integers(0, len(bad)))]
        return _utc(buf, y, mo, d, h, int(rng.integers(0, 3_600_000_000)))
    elif kind == "good_utc":
        return _utc(buf, int(rng.integers(0, 100)), int(rng.integers(1, 13)), int(rng.integers(1, 29)),
                    int(rng.integers(0, 24)), int(rng.integers(0, 3_600_000_000)))
    return bytes(b)


@examples(80)
@given(st.integers(0, 2**32 - 1), st.integers(1, 80))
def test_fuzzed_data_packets_are_counted_by_reason(seed, n):
    rng = np.random.default_rng(seed)
    kinds = [MUTATIONS[int(i)] for i in rng.integers(0, len(MUTATIONS), n)]
    grams = [_mutate(rng, k) for k in kinds]
    dec = lp.DataDecoder(point_rate_hz=RATE)
    batches = dec.decode(grams)
    want = Counter(EXPECT[k] for k in kinds if k in EXPECT)
    assert dict(dec.dropped) == dict(want)
    good = [g for g, k in zip(grams, kinds) if k in ("valid", "good_utc")]
    assert dec.counters["packets"] == len(good)
    assert dec.counters["imu_packets"] == kinds.count("imu")
    assert sum(dec.dropped.values()) + dec.counters["packets"] + dec.counters["imu_packets"] == n
    # the good packets decode among the garbage exactly as they do alone
    alone = lp.PointBatch.concat([lp.decode_packet(g, RATE) for g in good])
    got = lp.PointBatch.concat(batches)
    assert np.array_equal(got.xyz, alone.xyz) and np.array_equal(got.t_ns, alone.t_ns)
    assert np.array_equal(got.reflectivity, alone.reflectivity) and np.array_equal(got.tag, alone.tag)
    assert np.isfinite(got.xyz).all()
    assert dec.counters["points"] == len(got)


@examples(150)
@given(st.lists(st.binary(min_size=0, max_size=1500), min_size=1, max_size=20))
def test_random_datagrams_never_raise(grams):
    dec = lp.DataDecoder(point_rate_hz=RATE)
    batches = dec.decode(grams)
    assert set(dec.dropped) <= set(lp.DATA_DROP_REASONS)
    assert sum(dec.dropped.values()) + dec.counters["packets"] + dec.counters["imu_packets"] == len(grams)
    for b in batches:
        assert np.isfinite(b.xyz).all()


@examples(150)
@given(st.integers(0, 2**32 - 1), st.sampled_from(lp.POINT_DATA_TYPES), st.binary(min_size=0, max_size=64))
def test_random_payload_behind_a_valid_header(seed, data_type, tail):
    """A valid header, a right-sized body of random bytes (any depth, angle, coordinate): accepted,
    decoded to finite points with times within the packet's span; a wrong size is counted."""
    rng = np.random.default_rng(seed)
    hdr = _valid_packet(rng, data_type)[: lp.HEADER_LEN]
    body = bytes(rng.integers(0, 256, lp.PACKET_LEN[data_type] - lp.HEADER_LEN).astype(np.uint8))
    dec = lp.DataDecoder(point_rate_hz=RATE)
    out = lp.PointBatch.concat(dec.decode([hdr + body, hdr + body + tail, (hdr + body)[:-1]]))
    assert dec.counters["packets"] == (1 if tail else 2)
    assert dec.dropped["data_truncated"] == 1 and dec.dropped["data_oversize"] == (1 if tail else 0)
    assert np.isfinite(out.xyz).all()
    out = lp.decode_packet(hdr + body, RATE)  # one packet: its times
    if len(out):
        t0 = struct.unpack_from("<Q", hdr, 10)[0]
        span = int(round(lp.POINTS_PER_PACKET[data_type] * 1e9 / RATE))
        assert t0 <= out.t_ns.min() and out.t_ns.max() < t0 + span
        assert np.all(np.diff(out.t_ns) >= 0)


def test_one_bad_utc_date_keeps_the_rest_of_the_run():
    rng = np.random.default_rng(3)
    good = [_mutate(rng, "good_utc") for _ in range(5)]
    bad = _mutate(rng, "bad_utc")
    grams = good[:2] + [bad] + good[2:]
    dec = lp.DataDecoder(point_rate_hz=RATE)
    got = lp.PointBatch.concat(dec.decode(grams))
    assert dec.dropped == Counter({"data_bad_timestamp": 1})
    assert dec.counters["packets"] == 5
    alone = lp.PointBatch.concat([lp.decode_packet(g, RATE) for g in good])
    assert np.array_equal(got.xyz, alone.xyz) and np.array_equal(got.t_ns, alone.t_ns)


# ------------------------------------------------------------------------------------------------
# control frames

CTRL_KINDS = ("valid", "too_short", "sof", "version", "header_crc", "truncated", "oversize", "crc32",
              "cmd_type")


def _ctrl(rng, kind):
    payload = bytes(rng.integers(0, 256, int(rng.integers(0, 64))).astype(np.uint8))
    frame = lp.ControlFrame(int(rng.integers(0, 3)), int(rng.integers(0, 65536)), int(rng.integers(0, 3)),
                            int(rng.integers(0, 256)), payload)
    buf = bytearray(lp.encode_control(frame))
    if kind == "valid":
        return bytes(buf), None, frame
    if kind == "too_short":
        return bytes(buf[: int(rng.integers(0, lp.CTRL_HEADER_LEN))]), "ctrl_too_short", None
    if kind == "sof":
        buf[0] = int(rng.choice([v for v in range(256) if v != lp.SOF]))
        return bytes(buf), "ctrl_bad_sof", None
    if kind == "version":
        buf[1] = int(rng.choice([v for v in range(256) if v != lp.CTRL_VERSION]))
        return bytes(buf), "ctrl_bad_version", None
    if kind == "header_crc":
        i = int(rng.integers(2, lp.CTRL_HEADER_LEN))
        buf[i] ^= int(rng.integers(1, 256))
        return bytes(buf), "ctrl_bad_header_crc", None
    if kind == "truncated":
        return bytes(buf[: int(rng.integers(lp.CTRL_HEADER_LEN, len(buf)))]), "ctrl_truncated", None
    if kind == "oversize":
        return bytes(buf) + bytes(int(rng.integers(1, 100))), "ctrl_oversize", None
    if kind == "crc32":
        i = int(rng.integers(lp.CTRL_HEADER_LEN, len(buf)))
        buf[i] ^= int(rng.integers(1, 256))
        return bytes(buf), "ctrl_bad_crc32", None
    bad = lp.ControlFrame(int(rng.integers(3, 256)), frame.seq, frame.cmd_set, frame.cmd_id, payload)
    return lp.encode_control(bad), "ctrl_unknown_cmd_type", None


@examples(100)
@given(st.integers(0, 2**32 - 1))
def test_fuzzed_control_frames_give_the_defect_as_reason(seed):
    rng = np.random.default_rng(seed)
    for kind in CTRL_KINDS:
        buf, reason, frame = _ctrl(rng, kind)
        try:
            parsed = lp.parse_control(buf)
            got = None
        except lp.PacketError as exc:  # anything else escaping is a bug the safe wrapper would hide
            parsed, got = None, exc.reason
        assert got == reason, kind
        assert lp.parse_control_safe(buf) == ((frame, None) if reason is None else (None, reason))
        if frame is not None:
            assert parsed == frame and lp.encode_control(parsed) == buf


@examples(300)
@given(st.one_of(st.binary(max_size=200),
                 st.binary(max_size=200).map(lambda b: bytes([lp.SOF, lp.CTRL_VERSION]) + b)))
def test_random_control_bytes_raise_only_packet_errors(buf):
    try:
        lp.parse_control(buf)
    except lp.PacketError as exc:
        assert exc.reason in lp.CTRL_DROP_REASONS
    frame, reason = lp.parse_control_safe(buf)
    assert (frame is None) != (reason is None)
