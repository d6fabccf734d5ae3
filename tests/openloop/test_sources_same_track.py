"""The same frames as a numpy folder, a ROS 2 bag (MCAP), a ROS 1 bag (PointCloud2 and Livox
CustomMsg, written by rosbags) and a PCD folder (written by pypcd4) give the same frames and the
same track, to the bit."""

import shutil
from pathlib import Path

import numpy as np
import pytest

import bag_writers as bw
from foveatrack.cli import main
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
        assert [a.t_start_s for _, a in run] == [ns // 10**6 * 10**6 / 10**9 for ns, _ in frames]
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


def _timed_bag(path, frames, name, code, datatype, times):
    """A ROS 2 bag of PointCloud2 x, y, z (float32) and a time field ``name`` (numpy ``code``,
    PointField ``datatype``) holding ``times(stamp_ns, n)``."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = bw._stores(False)
    PointField = store.types["sensor_msgs/msg/PointField"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection(TOPIC, "sensor_msgs/msg/PointCloud2", typestore=store)
        for ns, xyz in frames:
            msg = bw.pointcloud2(store, ns, xyz, False, float64=False, extra_intensity=False)
            rec = np.zeros(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), (name, "<" + code)])
            for i, k in enumerate("xyz"):
                rec[k] = xyz[:, i]
            rec[name] = times(ns, len(xyz))
            msg.fields = msg.fields + [PointField(name=name, offset=12, datatype=datatype, count=1)]
            msg.point_step, msg.data = rec.dtype.itemsize, np.frombuffer(rec.tobytes(), np.uint8)
            w.write(c, ns + bw.PERIOD_NS, store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
    return path


def _read(path, rate_hz=10.0):
    from foveatrack.sources.rosbag import BagSource

    said = []
    return [fr for _, fr in BagSource(path, TOPIC, rate_hz, warn=said.append)], said


def _spread(n, span_ns):
    return np.linspace(0, span_ns, n)


@pytest.mark.parametrize("name, code, datatype", [("offset_time", "u4", 6), ("t", "u4", 6)],
                         ids=["livox-offset_time", "ouster-t"])
def test_integer_offsets_of_a_200ms_scan_are_ns_after_the_stamp(tmp_path, frames, name, code, datatype):
    # 5 Hz scans: offsets up to 2e8 ns were read as absolute seconds (det_t_s 100360000.0) and
    # --record failed with "point times must lie within ±2.1 s"
    path = _timed_bag(tmp_path / "b", frames[:4], name, code, datatype, lambda ns, n: _spread(n, 199_000_000))
    got, said = _read(path, 5.0)
    for (ns, xyz), fr in zip(frames, got):
        valid = np.any(xyz != 0, axis=1)
        np.testing.assert_array_equal(fr.t_ns, ns + _spread(len(xyz), 199_000_000).astype(np.uint32).astype(np.int64)[valid])
    assert said == []
    rec = tmp_path / "r.mcap"
    assert main(["track", str(path), "--topic", TOPIC, "--rate-hz", "5", "--record", str(rec)]) == 0


def test_float_offsets_are_seconds_and_float64_timestamps_absolute(tmp_path, frames):
    ns0, xyz0 = frames[0]
    valid = np.any(xyz0 != 0, axis=1)
    off = _spread(len(xyz0), 99_000_000)
    cases = {   # Velodyne time (float32 s after the stamp), Hesai timestamp (float64 s), livox_ros_driver2 (float64 ns)
        "velodyne": ("time", "f4", 7, lambda ns, n: (off * 1e-9).astype(np.float32),
                     ns0 + np.round((off * 1e-9).astype(np.float32).astype(np.float64) * 1e9).astype(np.int64)),
        "hesai": ("timestamp", "f8", 8, lambda ns, n: (ns + off) * 1e-9, np.round((ns0 + off) * 1e-9 * 1e9).astype(np.int64)),
        "livox2": ("timestamp", "f8", 8, lambda ns, n: ns + off, (ns0 + off).astype(np.int64)),
    }
    for case, (name, code, dt, times, want) in cases.items():
        got, said = _read(_timed_bag(tmp_path / case, frames[:1], name, code, dt, times))
        np.testing.assert_array_equal(got[0].t_ns, want[valid], err_msg=case)
        assert said == [], (case, said)


def test_point_times_on_another_clock_are_said_once_and_kept_after_the_stamp(tmp_path, frames):
    # livox_ros_driver2-style absolute ns, 18 s ahead of header.stamp (GPS time against UTC): once
    # passed silently, the detections 18 s off the frames
    off = lambda n: _spread(n, 99_000_000) + 1_000_000          # noqa: E731
    path = _timed_bag(tmp_path / "b", frames[:3], "timestamp", "f8", 8, lambda ns, n: ns + 18_000_000_000 + off(n))
    got, said = _read(path)
    assert len(said) == 1 and TOPIC in said[0] and "message 0" in said[0] and "+18.001 s from header.stamp" in said[0], said
    for (ns, xyz), fr in zip(frames, got):
        valid = np.any(xyz != 0, axis=1)
        held = (ns + 18_000_000_000 + off(len(xyz)))[valid].astype(np.int64)   # float64 ns: to 256 ns
        np.testing.assert_array_equal(fr.t_ns, ns + (held - held.min()))
    rec = tmp_path / "r.mcap"
    assert main(["track", str(path), "--topic", TOPIC, "--record", str(rec)]) == 0


def test_point_times_no_scan_can_span_put_the_points_at_the_stamp_and_say_so(tmp_path, frames):
    # a float32 field of ns (read as seconds by its type): a scan 99e6 s long
    path = _timed_bag(tmp_path / "b", frames[:2], "time", "f4", 7, lambda ns, n: _spread(n, 99_000_000))
    got, said = _read(path)
    assert len(said) == 1 and "time (float32): seconds after header.stamp" in said[0] and "which no scan lasts" in said[0]
    for (ns, _), fr in zip(frames, got):
        assert (fr.t_ns == ns).all()


@pytest.mark.parametrize("data_order", ["<", ">"], ids=["little-endian-data", "big-endian-data"])
def test_a_wrong_is_bigendian_flag_is_said_and_overruled(tmp_path, frames, reference_run, data_order):
    # little-endian floats flagged is_bigendian (a driver's bug) were read as denormals: a "drone"
    # tracked at 1e-38 m and numpy's RuntimeWarning on stderr.  Big-endian data flagged right read
    # as before, unsaid; flagged wrong, each is read in the order its values make sense in.
    import warnings

    from rosbags.rosbag2 import StoragePlugin, Writer

    from foveatrack.sources.rosbag import BagSource

    store = bw._stores(False)
    path = tmp_path / "b"
    for flag in (data_order == "<", data_order == ">"):      # the wrong flag, then the right one
        if path.exists():
            shutil.rmtree(path)
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            c = w.add_connection(TOPIC, "sensor_msgs/msg/PointCloud2", typestore=store)
            for ns, xyz in frames:
                msg = bw.pointcloud2(store, ns, xyz, False, float64=False)
                rec = np.frombuffer(msg.data.tobytes(), np.dtype({"names": ["x", "y", "z", "intensity"],
                                    "formats": ["<f4"] * 4, "offsets": [0, 4, 8, 12], "itemsize": msg.point_step}))
                if data_order == ">":
                    rec = rec.astype(rec.dtype.newbyteorder(">"))
                msg.data, msg.is_bigendian = np.frombuffer(rec.tobytes(), np.uint8), flag
                w.write(c, ns + bw.PERIOD_NS, store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
        said = []
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            run = list(BagSource(path, TOPIC, warn=said.append))
        _same(run, track_source(open_source(path, TOPIC)), reference_run)
        wrong = flag != (data_order == ">")
        assert len(said) == wrong, said
        if wrong:
            assert f"is_bigendian is {flag}" in said[0] and "taken to be wrong" in said[0] and TOPIC in said[0]
