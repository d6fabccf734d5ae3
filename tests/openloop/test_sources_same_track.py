"""The same frames as a numpy folder, a ROS 2 bag (MCAP), a ROS 1 bag (PointCloud2 and Livox
CustomMsg, written by rosbags) and a PCD folder (written by pypcd4) give the same frames and the
same track, to the bit."""

import shutil
from pathlib import Path

import numpy as np
import pytest

import bag_writers as bw
from foveatrack.openloop import track_source
from foveatrack.sources import open_source

FIXTURE = Path(__file__).parent / "mmaud_seq1" / "livox_avia"
TOPIC = "/livox/lidar"


@pytest.fixture(scope="module")
def frames():
    return bw.npy_frames(FIXTURE)


@pytest.fixture(scope="module")
def reference_run():
    src = open_source(FIXTURE)
    return list(src), track_source(open_source(FIXTURE))


def _bits(a):
    return np.ascontiguousarray(a).tobytes()


def _same(run_frames, res, reference_run):
    ref_frames, ref_res = reference_run
    assert len(run_frames) == len(ref_frames)
    for (_, a), (_, b) in zip(run_frames, ref_frames):
        assert a.t_start_s == b.t_start_s and a.t_end_s == b.t_end_s
        assert _bits(a.xyz) == _bits(b.xyz) and _bits(a.t_ns) == _bits(b.t_ns)
    f, g = res.frames, ref_res.frames
    assert g["detected"].sum() >= 9          # the drone is tracked in the fixture's first frames
    for k in ("t_s", "xyz_m", "det_t_s", "det_n_points", "track_id", "detected", "n_points"):
        assert _bits(f[k]) == _bits(g[k]), k
    assert list(f["state"]) == list(g["state"])
    assert res.confirmed == ref_res.confirmed


@pytest.mark.parametrize("kind", ["pointcloud2", "custom"])
@pytest.mark.parametrize("ros1", [False, True], ids=["ros2-mcap", "ros1-bag"])
def test_bag_gives_the_same_track_as_the_numpy_folder(tmp_path, frames, reference_run, kind, ros1):
    path = bw.write_bag(tmp_path / ("b.bag" if ros1 else "b"), frames, kind, ros1=ros1,
                        extra_topics=("/status",))
    run = list(open_source(path, TOPIC))
    _same(run, track_source(open_source(path, TOPIC)), reference_run)
    if not ros1:   # the bag's .mcap file alone reads the same
        mcap = next(path.glob("*.mcap"))
        _same(list(open_source(mcap, TOPIC)), track_source(open_source(mcap, TOPIC)), reference_run)


def test_pointcloud2_float32_fields_read_as_float32(tmp_path, frames, reference_run):
    # the fixture's values are float32-exact, so a float32 layout carries them unchanged too
    path = bw.write_bag(tmp_path / "f32", frames, "pointcloud2", ros1=False, float64=False)
    _same(list(open_source(path, TOPIC)), track_source(open_source(path, TOPIC)), reference_run)


def test_pcd_folder_gives_the_same_track_as_the_numpy_folder(tmp_path, frames, reference_run):
    names = sorted((f.name[:-4] for f in FIXTURE.glob("*.npy")), key=lambda s: bw.ns_from_file_stem(s))
    folder = bw.write_pcd_folder(tmp_path / "pcd", frames, names)
    _same(list(open_source(folder)), track_source(open_source(folder)), reference_run)


def test_pointcloud2_point_times_are_read(tmp_path, frames):
    # Ouster-style integer offsets [ns] from the stamp, in a uint32 field named t
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = bw._stores(False)
    PointField = store.types["sensor_msgs/msg/PointField"]
    ns, xyz = frames[0]
    msg = bw.pointcloud2(store, ns, xyz, False, extra_intensity=False)
    rec = np.zeros(len(xyz), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("t", "<u4")])
    for i, k in enumerate("xyz"):
        rec[k] = xyz[:, i]
    rec["t"] = np.arange(len(xyz)) * 1000
    msg.fields = msg.fields + [PointField(name="t", offset=24, datatype=6, count=1)]
    msg.point_step, msg.data = 28, np.frombuffer(rec.tobytes(), np.uint8)
    path = tmp_path / "times"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection(TOPIC, "sensor_msgs/msg/PointCloud2", typestore=store)
        w.write(c, ns, store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
    (_, fr), = list(open_source(path, TOPIC))
    valid = np.any(xyz != 0, axis=1)
    np.testing.assert_array_equal(fr.t_ns, ns + (np.arange(len(xyz)) * 1000)[valid])


@pytest.mark.parametrize("unit", ["ms", "us", "ns"])
def test_npy_folder_named_in_ms_us_or_ns_gives_the_same_track(tmp_path, frames, reference_run, unit):
    # Files named by an integer time in ms, µs or ns since 1970 (1706255621614239.npy): once an
    # OverflowError from the int64 stamp; the unit is the one the name's digit count gives.
    digits = {"ms": 3, "us": 6, "ns": 9}[unit]
    for f in FIXTURE.glob("*.npy"):
        sec, frac = f.name[:-4].split(".")
        shutil.copy(f, tmp_path / f"{sec}{frac.ljust(9, '0')[:digits]}.npy")
    if unit == "ms":   # the fixture's names are µs: cut to ms, the frames start up to 1 ms earlier
        run = list(open_source(tmp_path))
        assert [a.t_start_s for _, a in run] == [ns // 10**6 * 10**6 * 1e-9 for ns, _ in frames]
        return
    _same(list(open_source(tmp_path)), track_source(open_source(tmp_path)), reference_run)


def test_npy_folder_names_in_two_units_or_past_int64_are_refused(tmp_path):
    from foveatrack.errors import UserError

    f = next(FIXTURE.glob("*.npy"))
    shutil.copy(f, tmp_path / "1706255621.614239.npy")
    shutil.copy(f, tmp_path / "1706255621714191.npy")
    with pytest.raises(UserError, match=r"1706255621714191\.npy: the name reads as µs .* 1706255621\.614239\.npy's as s"):
        open_source(tmp_path)
    for g in tmp_path.iterdir():
        g.unlink()
    shutil.copy(f, tmp_path / "9999999999.npy")      # 2286: past what int64 ns hold
    with pytest.raises(UserError, match=r"9999999999\.npy: the file name is not a time"):
        open_source(tmp_path)
