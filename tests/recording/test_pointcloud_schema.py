"""Every /points message is a valid ``foxglove.PointCloud``, checked with Foxglove's own generated
protobuf class (``foxglove-schemas-protobuf``) on messages read by the official ``mcap`` reader: no
field outside the schema (formats 2 and 3 carried the frame index and the unit of ``dt`` in fields 15
and 16), a ``pose``, and every per-point value a ``PackedElementField`` of ``data``: x, y, z [m],
``age_ns`` (frame time - point time [ns], >= 0: what a user colours by; format 3's ``dt`` was a
negative count of 10 us) and reflectivity.  The frame index a reader gives comes from the frame's
/detections record."""

import numpy as np
import pytest
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from google.protobuf.unknown_fields import UnknownFieldSet
from mcap.reader import make_reader

from foveatrack.livox.protocol import m_to_mm, mm_to_m
from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.recording.records import DetectionRecord, write_record

T0 = 1_700_000_000_000_000_000


def _frames(n_frames=4, n=500, on_grid=True, seed=3):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n_frames):
        t = T0 + (k + 1) * 100_000_000
        xyz = rng.normal(0, 40, (n, 3))
        if on_grid:
            xyz = mm_to_m(m_to_mm(xyz))
        tp = t - 100_000_000 + np.sort(rng.integers(0, 100_000_000, n))   # in [t - 100 ms, t)
        out.append((t, xyz, tp, rng.integers(0, 256, n).astype(np.uint8)))
    return out


def _no_unknown_fields(msg) -> list:
    """The unknown fields of ``msg`` and of every message inside it, as (message type, field number)."""
    bad = [(msg.DESCRIPTOR.full_name, u.field_number) for u in UnknownFieldSet(msg)]
    for fd, value in msg.ListFields():
        if fd.message_type is not None:
            for sub in (value if fd.is_repeated else [value]):
                bad += _no_unknown_fields(sub)
    return bad


@pytest.mark.parametrize("on_grid", [True, False])
def test_every_pointcloud_is_within_foxgloves_schema_and_colours_by_a_non_negative_age(tmp_path, on_grid):
    frames = _frames(on_grid=on_grid)
    p = tmp_path / "r.mcap"
    ids = [5, 6, 8, 9]      # the daemon's frame ids skip where it dropped a frame
    with RecordingWriter(p, {}) as w:
        for k, (t, xyz, tp, refl) in zip(ids, frames):
            w.write_points(t, k, xyz, tp, refl)
            write_record(w, DetectionRecord(t, k, False, state="search"))
    with open(p, "rb") as fh:
        clouds = [(m.log_time, PointCloud.FromString(m.data)) for _s, _c, m in
                  make_reader(fh).iter_messages(topics=["/points"])]
    assert len(clouds) == len(frames)
    for (log_time, pc), (t, xyz, tp, refl) in zip(clouds, frames):
        assert _no_unknown_fields(pc) == []
        assert {fd.name for fd, _v in pc.ListFields()} == {"timestamp", "frame_id", "pose", "point_stride",
                                                            "fields", "data"}
        assert pc.pose.orientation.w == 1.0 and pc.frame_id == "lidar"
        assert pc.timestamp.seconds * 10**9 + pc.timestamp.nanos == t == log_time
        f32 = "<f4" if on_grid else "<f8"
        layout = {f.name: (f.offset, PointCloud.DESCRIPTOR.fields_by_name["fields"].message_type
                           .fields_by_name["type"].enum_type.values_by_number[f.type].name) for f in pc.fields}
        assert list(layout) == ["x", "y", "z", "age_ns", "reflectivity"]
        assert layout["age_ns"][1] == "INT32" and layout["reflectivity"][1] == "UINT8"
        assert {layout[c][1] for c in "xyz"} == {"FLOAT32" if on_grid else "FLOAT64"}
        arr = np.frombuffer(pc.data, np.dtype({"names": list(layout), "formats": [f32] * 3 + ["<i4", "u1"],
                                               "offsets": [v[0] for v in layout.values()],
                                               "itemsize": pc.point_stride}))
        assert arr["age_ns"].min() > 0 and arr["age_ns"].max() <= 100_000_000     # within the 100 ms frame
        assert np.array_equal(t - arr["age_ns"].astype(np.int64), tp)
        assert np.array_equal(arr["reflectivity"], refl)
        v = np.stack([arr["x"], arr["y"], arr["z"]], 1).astype(np.float64)
        assert np.abs(v - xyz).max() <= (0.25e-3 if on_grid else 0.0)          # drawn where the point is
    # and our reader gives the frames to the bit, each with the index of its /detections record
    got = list(RecordingReader(p).points())
    assert [f.frame_index for f in got] == ids
    for f, (t, xyz, tp, refl) in zip(got, frames):
        assert f.t_ns == t and np.array_equal(f.t_ns_points, tp) and np.array_equal(f.reflectivity, refl)
        assert np.array_equal(f.xyz.view(np.int64), xyz.view(np.int64))


def test_frames_without_a_detection_are_numbered_on_from_the_last(tmp_path):
    # a file of points alone (a benchmark, an exported scan): 0, 1, 2 ...; a frame takes the index
    # of the first detection after it (of any time), and the next frame without one numbers on
    frames = _frames(n_frames=6, n=3)
    p = tmp_path / "r.mcap"
    with RecordingWriter(p, {}) as w:
        for k, (t, xyz, tp, refl) in enumerate(frames):
            w.write_points(t, 100 + k, xyz, tp, refl)
            if k == 2:
                write_record(w, DetectionRecord(t, 7, False))
            if k == 4:
                w.write_metric(t, "processing_ms", 1.0)
                write_record(w, DetectionRecord(t + 1000, 50, False))
                write_record(w, DetectionRecord(t + 2000, 60, False))
    r = RecordingReader(p)
    assert [f.frame_index for f in r.points()] == [0, 1, 7, 8, 50, 51]
    # every message comes once, in file order, whether the detections are asked for or not
    assert [m.channel for m in r.messages()] == (["points"] * 3 + ["detections"] + ["points"] * 2 +
                                                 ["metrics", "detections", "detections", "points"])
    assert [m.record.frame_index for m in r.messages("points")] == [0, 1, 7, 8, 50, 51]
    assert [m.record["frame_index"] for m in r.messages("detections")] == [7, 50, 60]
    assert [m.record["name"] for m in r.messages(["metrics"])] == ["processing_ms"]


@pytest.mark.parametrize("t_ns", [0, 7, 1_000_000_000, T0 + 123_456_789, (2**32 - 1) * 10**9 + 999_999_999])
@pytest.mark.parametrize("n", [0, 1, 300])
@pytest.mark.parametrize("xyz_dtype", ["float32", "float64"])
def test_our_encoding_is_the_sdks(t_ns, n, xyz_dtype):
    # the message is assembled from a template made once per layout; the SDK's own encoder of the
    # whole message gives the same bytes
    from foxglove.messages import PackedElementField, PackedElementFieldNumericType as NT
    from foxglove.messages import PointCloud as SdkPointCloud, Pose, Quaternion, Timestamp, Vector3

    from foveatrack.recording.format import encode_points_pb, packed_point_dtype

    packed = np.zeros(n, packed_point_dtype(xyz_dtype))
    rng = np.random.default_rng(n)
    packed["x"] = rng.normal(0, 10, n)
    packed["age_ns"] = rng.integers(0, 10**8, n)
    f = NT.Float32 if xyz_dtype == "float32" else NT.Float64
    fields = [PackedElementField(name=c, offset=o, type=ty) for c, o, ty in
              (("x", 0, f), ("y", packed.dtype.fields["y"][1], f), ("z", packed.dtype.fields["z"][1], f),
               ("age_ns", packed.dtype.fields["age_ns"][1], NT.Int32),
               ("reflectivity", packed.dtype.fields["reflectivity"][1], NT.Uint8))]
    sdk = SdkPointCloud(timestamp=Timestamp(t_ns // 10**9, t_ns % 10**9), frame_id="lidar",
                        pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0),
                                  orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                        point_stride=packed.dtype.itemsize, fields=fields, data=packed.tobytes()).encode()
    assert encode_points_pb(t_ns, packed) == sdk
