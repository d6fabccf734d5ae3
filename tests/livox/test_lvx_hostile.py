"""Hostile .lvx files (issue 32): a wild package timestamp is a one-line error naming the package and
the field, or a warning with the counts of what was dropped; never a traceback, never silent loss."""

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import LvxDevice, read_lvx, write_lvx

AVIA = LvxDevice("3JEDK1B00100961", "", 2, 7, False, 0, 0, 0, 0, 0, 0)


def _file(tmp_path, n_frames=1, name="p.lvx"):
    frames = []
    for k in range(n_frames):
        pk = P.encode_data_packets(np.full((96, 3), 5.0), np.full(96, 9), 10**9 + k * 50_000_000, 240_000.0,
                                   data_type=2)
        frames.append([(2, pk[0])])
    write_lvx(tmp_path / name, frames, [AVIA])
    return tmp_path / name, 24 + 5 + 59 + 24   # first package


def test_a_timestamp_beyond_int64_is_a_packet_error_not_a_wrap():
    pk = bytearray(P.encode_data_packets(np.full((96, 3), 5.0), np.full(96, 9), 10**9, 240_000.0, data_type=2)[0])
    pk[10:18] = (0x7FFF_FFFF_FFFF_FFFF).to_bytes(8, "little")
    arr = np.frombuffer(bytes(pk), dtype=P.packet_dtype(2))
    with pytest.raises(P.PacketError, match="beyond any sensor clock"):
        P.decode_packets_array(arr, 240_000.0)


def _box_config(tmp_path) -> str:
    """An .lvx carries no tracker configuration, and replay refuses one without a space of interest."""
    cfg = tmp_path / "box.toml"
    cfg.write_text('[tracker]\n[tracker.space]\nkind = "box"\nmin_xyz = [1.0, -60.0, -5.0]\nmax_xyz = [60.0, 60.0, 40.0]\n')
    return str(cfg)


def test_a_package_stamped_0x7fff_is_named_in_the_lvx_and_in_replay(tmp_path):
    from foveatrack.replay import replay

    p, pkg = _file(tmp_path)
    data = bytearray(p.read_bytes())
    data[pkg + 11:pkg + 19] = (0x7FFF_FFFF_FFFF_FF00).to_bytes(8, "little")
    p.write_bytes(bytes(data))
    with pytest.raises(UserError, match=rf"package at byte {pkg}: field timestamp \(byte {pkg + 11}\)"):
        list(read_lvx(p))
    with pytest.raises(UserError, match="beyond any sensor clock"):
        replay(p, _box_config(tmp_path))


RATE_HZ = 24_000.0     # a slow point rate keeps the file small: 96 points per 4 ms packet


def _stream_file(tmp_path, seconds=3.1, late_package=None, name="s.lvx"):
    """An .lvx of ``seconds`` of points in 50 ms frames; ``late_package`` = (k, dt_ns): package k's
    timestamp moved ``dt_ns`` later."""
    n = int(seconds * RATE_HZ)
    rng = np.random.default_rng(3)
    xyz = np.column_stack([rng.uniform(5, 30, n), rng.uniform(-5, 5, n), rng.uniform(-2, 2, n)])
    pks = P.encode_data_packets(xyz, np.full(n, 20), 10**9, RATE_HZ, data_type=2)
    per_frame = int(0.05 * RATE_HZ) // 96
    if late_package is not None:
        k, dt_ns = late_package
        pk = bytearray(pks[k])
        pk[10:18] = (int.from_bytes(pk[10:18], "little") + dt_ns).to_bytes(8, "little")
        pks[k] = bytes(pk)
    frames = [[(2, pk) for pk in pks[i:i + per_frame]] for i in range(0, len(pks), per_frame)]
    write_lvx(tmp_path / name, frames, [AVIA])
    return tmp_path / name


def test_one_package_stamped_18_minutes_late_is_dropped_counted_and_the_rest_replayed(tmp_path):
    """It made the slicer restart 18 minutes on, and every point after it was "late": 9 frames of 31,
    rc 0, no word of it.  Now the package is dropped as a wrong time (counted, named in a warning) and
    every other frame is replayed as without it."""
    from foveatrack.replay import format_report, replay

    cfg = _box_config(tmp_path)
    good = replay(_stream_file(tmp_path, name="good.lvx"), cfg)
    bad = replay(_stream_file(tmp_path, late_package=(300, 18 * 60 * 10**9), name="late.lvx"), cfg)
    n = len(good.frames["t_end_s"])
    assert n >= 30
    assert len(bad.frames["t_end_s"]) == n
    assert np.array_equal(bad.frames["t_end_s"], good.frames["t_end_s"])
    lost = good.frames["n_points"].sum() - bad.frames["n_points"].sum()
    c = bad.comparison
    assert c["lvx_time"]["bad_time_points"] == 96 and lost <= 96
    warn = [ln for ln in format_report(bad).splitlines() if "WARNING" in ln]
    assert len(warn) == 1 and "96 points" in warn[0]
    assert "WARNING" not in format_report(good)
