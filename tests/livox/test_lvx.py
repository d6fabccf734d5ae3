"""Livox Viewer .lvx v1.1 reader, checked against files written with the packet encoder."""

import struct

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
