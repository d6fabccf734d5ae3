"""Livox Viewer .lvx v1.1 reader, checked against files written with the packet encoder."""

import struct
from collections import Counter

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import LvxDevice, LvxReader, read_lvx, write_lvx

HORIZON = LvxDevice("3WEDH7600101621", "", 0, 3, False, 0, 0, 0, 0, 0, 0)
MID40 = LvxDevice("1PQDH5B00100041", "", 1, 1, True, 1.0, 2.0, 3.0, 0.1, 0.2, 0.3)


def make_frames(rng, n_frames=3):
    frames, truth = [], []
    for k in range(n_frames):
        t0 = 10**9 + k * 50_000_000
        xa = np.round(rng.uniform(1, 50, (192, 3)), 3)
        xb = np.round(rng.uniform(1, 50, (100, 3)), 3)
        pa = P.encode_data_packets(xa, np.full(192, 10), t0, 240_000.0, data_type=2)
        pb = P.encode_data_packets(xb, np.full(100, 20), t0, 100_000.0, data_type=0)
        frames.append([(0, pa[0]), (1, pb[0]), (0, pa[1])])
        truth.append((t0, xa, xb))
    return frames, truth


def test_round_trip_two_devices(tmp_path):
    rng = np.random.default_rng(0)
    frames, truth = make_frames(rng)
    p = tmp_path / "rec.lvx"
    write_lvx(p, frames, [HORIZON, MID40])
    with LvxReader(p) as r:
        assert r.frame_duration_ms == 50
        assert [d.lidar_code for d in r.devices] == [HORIZON.lidar_code, MID40.lidar_code]
        assert r.devices[1].extrinsic_enable and r.devices[1].yaw_deg == pytest.approx(3.0)
        got = list(r.frames())
        assert not r.truncated
        assert r.counters["packets"] == 9 and r.counters["points"] == 3 * 292
    for f, (t0, xa, xb) in zip(got, truth):
        b = f.points
        horizon = b.reflectivity == 10
        np.testing.assert_allclose(b.xyz[horizon], xa, atol=1e-9)
        np.testing.assert_allclose(b.xyz[~horizon], xb, atol=1e-9)
        # per-point time from each device type's rate: Horizon 240 k/s, Mid-40 100 k/s
        assert np.abs(b.t_ns[horizon] - (t0 + np.arange(192) * 1e9 / 240_000)).max() <= 1
        assert np.abs(b.t_ns[~horizon] - (t0 + np.arange(100) * 1e9 / 100_000)).max() <= 1
    assert [len(b) for b in read_lvx(p)] == [292, 292, 292]


def test_cut_short_file_yields_the_complete_frames(tmp_path):
    frames, _ = make_frames(np.random.default_rng(1))
    p = tmp_path / "rec.lvx"
    write_lvx(p, frames, [HORIZON, MID40])
    data = p.read_bytes()
    q = tmp_path / "cut.lvx"
    q.write_bytes(data[:-500])
    with LvxReader(q) as r:
        assert len(list(r.frames())) == 2
        assert r.truncated and "cut short" in r.problem and "cut.lvx" in r.problem


def test_not_lvx_files_give_clear_errors(tmp_path):
    p = tmp_path / "x.lvx"
    p.write_bytes(b"hello")
    with pytest.raises(UserError, match=r"x\.lvx is not a readable Livox \.lvx v1\.1 file.*public header"):
        LvxReader(p)
    p.write_bytes(b"not_livox".ljust(16, b"\0") + bytes([1, 1, 0, 0]) + struct.pack("<I", 0xAC0EA767) + bytes(5))
    with pytest.raises(UserError, match="signature"):
        LvxReader(p)
    p.write_bytes(b"livox_tech".ljust(16, b"\0") + bytes([1, 1, 0, 0]) + struct.pack("<I", 0x12345678) + bytes(5))
    with pytest.raises(UserError, match="magic"):
        LvxReader(p)
    p.write_bytes(b"livox_tech".ljust(16, b"\0") + bytes([2, 0, 0, 0]) + struct.pack("<I", 0xAC0EA767) + bytes(5))
    with pytest.raises(UserError, match="only 1.1"):
        LvxReader(p)
    with pytest.raises(UserError, match="cannot open"):
        LvxReader(tmp_path / "missing.lvx")


def test_corrupt_frames_give_clear_errors(tmp_path):
    frames, _ = make_frames(np.random.default_rng(2), n_frames=1)
    p = tmp_path / "rec.lvx"
    write_lvx(p, frames, [HORIZON, MID40])
    data = bytearray(p.read_bytes())
    first = 24 + 5 + 2 * 59
    bad = bytearray(data)
    bad[first : first + 8] = struct.pack("<Q", 7)  # wrong current_offset
    (tmp_path / "a.lvx").write_bytes(bad)
    with pytest.raises(UserError, match="a.lvx.*offsets"):
        list(read_lvx(tmp_path / "a.lvx"))
    bad = bytearray(data)
    bad[first + 24 + 1 + 9] = 9  # unknown data type in the first package
    (tmp_path / "b.lvx").write_bytes(bad)
    with pytest.raises(UserError, match="b.lvx.*unknown data type 9"):
        list(read_lvx(tmp_path / "b.lvx"))


# ---- data types 0-8, IMU stream, package fields, fuzzing ---------------------------------------------

AVIA = LvxDevice("3JEDK1B00100961", "", 2, 7, False, 0, 0, 0, 0, 0, 0)


def _slot_points(rng, data_type, n_slots):
    """Points for ``n_slots`` slots of ``data_type``; multi-return spherical slots share a direction."""
    per = P.RETURNS_PER_SLOT[data_type]
    d = rng.normal(size=(n_slots, 1, 3))
    d[..., 0] = np.abs(d[..., 0]) + 1.0
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    r = np.sort(rng.uniform(2.0, 90.0, (n_slots, per, 1)), axis=1)
    xyz = (d * r).reshape(-1, 3)
    if data_type in P.CARTESIAN_TYPES:
        xyz = np.round(xyz, 3)
    return xyz


@pytest.mark.parametrize("data_type", P.POINT_DATA_TYPES)
def test_every_point_data_type_reads_back(tmp_path, data_type):
    rng = np.random.default_rng(data_type)
    per = P.RETURNS_PER_SLOT[data_type]
    n_slots = 2 * P.POINTS_PER_PACKET[data_type]
    xyz = _slot_points(rng, data_type, n_slots)
    refl = rng.integers(1, 256, len(xyz)).astype(np.uint8)
    tag = rng.integers(0, 256, len(xyz)).astype(np.uint8)
    t0 = 5 * 10**9
    pk = P.encode_data_packets(xyz, refl, t0, 240_000.0, data_type=data_type, tag=tag)
    assert [len(b) for b in pk] == [P.PACKET_LEN[data_type]] * 2
    write_lvx(tmp_path / "t.lvx", [[(2, b) for b in pk]], [AVIA])
    with LvxReader(tmp_path / "t.lvx") as r:
        (f,) = list(r.frames())
    b = f.points
    assert len(b) == len(xyz)
    # wire resolution: 1 mm Cartesian; 1 mm and 0.01 deg spherical (0.005 deg * 90 m = 8 mm)
    tol = 0.5e-3 + 1e-9 if data_type in P.CARTESIAN_TYPES else 0.5e-3 + np.radians(0.005) * 90 * 1.5
    assert np.abs(b.xyz - xyz).max() <= tol
    np.testing.assert_array_equal(b.reflectivity, refl)
    np.testing.assert_array_equal(b.tag, tag if data_type not in (0, 1) else 0)
    slot_t = t0 + np.round(np.arange(n_slots) * 1e9 / 240_000)
    assert np.abs(b.t_ns - np.repeat(slot_t, per)).max() <= 1
    assert (f.point_device == 2).all() and f.imu is None


def _imu_packet(t_ns, values):
    hdr = struct.pack("<BBBBIBBQ", 5, 1, 1, 0, 0, 0, 6, t_ns)
    return hdr + struct.pack("<6f", *values)


def test_imu_packets_go_to_their_own_stream(tmp_path):
    from foveatrack.livox.lvx import decode_imu, read_lvx_imu

    pts = P.encode_data_packets(np.full((96, 3), 5.0), np.full(96, 9), 10**9, 240_000.0, data_type=2)
    imu = [_imu_packet(10**9 + k * 5_000_000, (0.1 * k, -0.2, 0.3, 0.0, 0.01 * k, 1.0)) for k in range(4)]
    assert [len(b) for b in imu] == [P.PACKET_LEN[6]] * 4 == [42] * 4
    frames = [[(2, imu[0]), (2, pts[0]), (2, imu[1])], [(2, imu[2]), (2, imu[3])]]
    write_lvx(tmp_path / "i.lvx", frames, [AVIA])
    with LvxReader(tmp_path / "i.lvx") as r:
        got = list(r.frames())
        assert r.counters["imu_packets"] == 4 and r.counters["packets"] == 1
    assert len(got[0].points) == 96 and len(got[1].points) == 0
    assert len(got[0].imu) == 2 and len(got[1].imu) == 2
    all_imu = read_lvx_imu(tmp_path / "i.lvx")
    np.testing.assert_array_equal(all_imu.t_ns, 10**9 + np.arange(4) * 5_000_000)
    np.testing.assert_allclose(all_imu.gyro_rad_s[:, 0], np.float32(0.1 * np.arange(4)))
    np.testing.assert_allclose(all_imu.acc_g[:, 1], np.float32(0.01 * np.arange(4)))
    assert decode_imu(imu[3][18:]) == pytest.approx((0.3, -0.2, 0.3, 0.0, 0.03, 1.0), rel=1e-6)


def _one_frame_file(tmp_path, name="p.lvx"):
    pk = P.encode_data_packets(np.full((96, 3), 5.0), np.full(96, 9), 10**9, 240_000.0, data_type=2)
    write_lvx(tmp_path / name, [[(2, pk[0]), (2, pk[0])]], [AVIA])
    return tmp_path / name, 24 + 5 + 59 + 24   # first package


@pytest.mark.parametrize("offset, value, field", [
    (0, 7, r"field device_index \(byte {pkg}\) = 7, not one of the file's devices \[2\]"),
    (1, 4, r"field version \(byte {v}\) = 4, expected 5"),
    (10, 9, r"field data_type \(byte {dt}\) = 9: unknown data type 9"),
    (9, 2, r"field timestamp_type \(byte {ts}\) = 2"),
])
def test_bad_package_field_is_named_with_its_byte_offset(tmp_path, offset, value, field):
    p, pkg = _one_frame_file(tmp_path)
    second = pkg + 1 + P.PACKET_LEN[2]
    data = bytearray(p.read_bytes())
    data[second + offset] = value
    p.write_bytes(bytes(data))
    msg = field.format(pkg=second, v=second + 1, dt=second + 10, ts=second + 9)
    with pytest.raises(UserError, match=rf"p\.lvx .*frame 0, package at byte {second}: {msg}"):
        list(read_lvx(p))


def test_bad_utc_date_is_named(tmp_path):
    p, pkg = _one_frame_file(tmp_path)
    data = bytearray(p.read_bytes())
    data[pkg + 9] = 3                      # PPS+GPS: UTC bytes
    data[pkg + 11 : pkg + 15] = bytes((20, 13, 1, 0))   # month 13
    p.write_bytes(bytes(data))
    with pytest.raises(UserError, match=rf"package at byte {pkg}: field timestamp \(byte {pkg + 11}\) is not a valid UTC"):
        list(read_lvx(p))


def test_replay_refuses_a_bad_version_package_and_survives_an_empty_file(tmp_path):
    """The replay path of issue 15: a package version other than 5 made ``replay`` crash in
    bearing_metrics (every packet dropped, no frame, float-typed empty masks)."""
    from foveatrack.replay import replay

    p, pkg = _one_frame_file(tmp_path)
    cfg = tmp_path / "box.toml"      # an .lvx replay needs a space of interest
    cfg.write_text('[tracker]\n[tracker.space]\nkind = "box"\nmin_xyz = [1.0, -60.0, -5.0]\nmax_xyz = [60.0, 60.0, 40.0]\n')
    cfg = str(cfg)
    data = bytearray(p.read_bytes())
    data[pkg + 1] = 1
    p.write_bytes(bytes(data))
    with pytest.raises(UserError, match=rf"package at byte {pkg}: field version \(byte {pkg + 1}\) = 1"):
        replay(p, cfg)
    write_lvx(tmp_path / "empty.lvx", [], [AVIA])
    res = replay(tmp_path / "empty.lvx", cfg)
    det = res.metrics["detection"]
    assert det["frames"] == 0 and det["frames_with_detection"] == 0 and det["bearing_error_deg"]["rms"] is None


def _read_all(path):
    with LvxReader(path) as r:
        return [len(f.points) for f in r.frames()]


def test_fuzzed_and_truncated_files_give_frames_or_a_user_error(tmp_path):
    """Random byte changes and every 13th cut of a two-frame file: either frames come out or a UserError
    naming the file does; nothing else is raised."""
    frames, _ = make_frames(np.random.default_rng(3), n_frames=2)
    src = tmp_path / "src.lvx"
    write_lvx(src, frames, [HORIZON, MID40])
    data = src.read_bytes()
    p = tmp_path / "f.lvx"
    rng = np.random.default_rng(4)
    outcomes = Counter()
    for k in range(200):
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
        p.write_bytes(bytes(b))
        try:
            _read_all(p)
            outcomes["read"] += 1
        except UserError as exc:
            assert "f.lvx" in str(exc)
            outcomes["refused"] += 1
    assert outcomes["read"] > 0 and outcomes["refused"] > 0
    full = _read_all(src)
    for cut in range(0, len(data), 13):
        p.write_bytes(data[:cut])
        try:
            got = _read_all(p)
        except UserError as exc:
            assert "f.lvx" in str(exc) and cut < 24 + 5 + 2 * 59
            continue
        assert got == full[: len(got)] and len(got) < len(full)
