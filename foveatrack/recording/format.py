"""The recording format: channels, the packed point layout, the records a reader hands out.

See :mod:`foveatrack.recording` for the layout of a file.
"""

from __future__ import annotations

import base64
import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from foveatrack.mcap_names import MCAP_MAGIC, META_NAME  # noqa: F401  (re-exported: the recording's names)

FORMAT = "foveatrack-recording"
FORMAT_VERSION = "4"
# 1: JSON + base64 points (python mcap writer); 2: Foxglove SDK, protobuf, float64 points;
# 3: as 2, points on the Livox mm grid stored compactly (float32 on a 2^-11 m grid, time in its unit);
# 4: as 3, each /points message within Foxglove's PointCloud schema: the point times as int32
#    ``age_ns`` (frame time - point time, >= 0), the frame index taken from the frame's /detections
READABLE_VERSIONS = ("1", "2", "3", "4")
META_CRC_KEY = "meta_crc32"    # the metadata record's own checksum (recordings made before it have none)


def meta_crc32(md: dict) -> str:
    """The checksum of a metadata record's keys and values (all but its own), as 8 hex digits: one bit
    of the record can turn format version 3 into 2, or change a recorded gain, and MCAP has no CRC
    for a metadata record."""
    import zlib

    body = json.dumps({k: v for k, v in md.items() if k != META_CRC_KEY}, sort_keys=True, ensure_ascii=True)
    return f"{zlib.crc32(body.encode()):08x}"
CHANNELS_META_NAME = "foveatrack_channels"   # channel id -> name tables written as channels appear
POINTS = "points"
DETECTIONS = "detections"
COMMANDS = "commands"
HEAD = "head"
TRUTH = "truth"
# simulation truth of every object of a multi-object scene (drones, birds, trees, stray returns), one
# record per object and frame; written only by scenes with more than one object (sim.recorder)
TRUTH_OBJECTS = "truth_objects"
# every track of the multi-object tracker (issue 28: a [tracker.sky] run), one record per frame; written
# only by such runs, by the simulator and the daemon alike (records.write_tracker_frame)
TRACKS = "tracks"
METRICS = "metrics"
DAEMON_EVENTS = "daemon"     # the daemon's events (tracker_rebased, head_pose_unknown, ...), JSON
IMU = "imu"                  # the IMU samples fed to the tracker before each frame (protobuf ImuSamples)
STANDARD_CHANNELS = (POINTS, DETECTIONS, COMMANDS, HEAD, TRUTH, METRICS)
# drawn for Foxglove from the records (format 2); replay needs none of them
TF = "tf"
SCENE = "scene"
# D and every trajectory's whole (thinned) history, once a second: Foxglove restores only the newest
# message of a topic after a seek, and a live viewer sees only what is sent after it joins
SCENE_KEYFRAME = "scene_keyframe"
LOG = "log"
VIEW_CHANNELS = (TF, SCENE, SCENE_KEYFRAME, LOG)

# foxglove NumericType (docs.foxglove.dev, "NumericType")
_FOX_TYPES = {"u1": 1, "i1": 2, "u2": 3, "i2": 4, "u4": 5, "i4": 6, "f4": 7, "f8": 8}
_FOX_TO_NP = {v: "<" + k for k, v in _FOX_TYPES.items()}

def _obj(title: str, doc: str, props: dict) -> dict:
    return {"title": title, "description": doc, "type": "object",
            "properties": {"t_ns": {"type": "integer", "description": "log time [ns]"}, **props}}


# A field that can be missing is written as JSON null but declared with its one type: Foxglove's
# JSON-schema parser (Studio's, as Lichtblick ships it) takes no union types such as ["number", "null"]
# and leaves every panel of such a channel empty (tests/foxglove_json_schema.py).
_NUM = {"type": "number", "description": "null where there is no value"}
_XYZ = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
        "description": "[x, y, z]; null where there is none"}
_NULLABLE = "; null where there is none"
# The documented custom JSON schemas of the record channels (docs/recordings.md): the fields of
# foveatrack.recording.records, so Foxglove's plot panel offers them by name.
RECORD_SCHEMAS = {
    DETECTIONS: ("foveatrack.Detection", _obj("foveatrack.Detection", "Algorithm 1 on one frame (lidar frame)", {
        "frame_index": {"type": "integer"}, "detected": {"type": "boolean"}, "xyz_m": _XYZ,
        "n_points": {"type": "integer"}, "t_s": _NUM, "az_deg": _NUM, "el_deg": _NUM,
        "state": {"type": "string", "description": "tracker state" + _NULLABLE}, "error_pan_deg": _NUM, "error_tilt_deg": _NUM})),
    HEAD: ("foveatrack.HeadEstimate", _obj("foveatrack.HeadEstimate", "the tracker's dead-reckoned head pose "
                                           "[deg] and reconstructed target [m, world]", {
        "pan_deg": {"type": "number"}, "tilt_deg": {"type": "number"}, "frame_id": {"type": "integer"},
        "sigma_pan_deg": _NUM, "sigma_tilt_deg": _NUM, "world_xyz_m": _XYZ, "world_sigma_m": _NUM})),
    COMMANDS: ("foveatrack.Command", _obj("foveatrack.Command", "a Pelco-D command as written to the head", {
        "raw_hex": {"type": "string"}, "frame_id": {"type": "integer", "description": "the frame it answers" + _NULLABLE}, "source": {"type": "string"},
        "send_t_s": {"type": "number"}, "written": {"type": "boolean"}, "host_written_s": {"type": "number"},
        "pan_dir": {"type": "integer"}, "pan_byte": {"type": "integer"}, "tilt_dir": {"type": "integer"},
        "tilt_byte": {"type": "integer"}, "limited": {"type": "array", "items": {"type": "string"}},
        "tracker_command": {"type": "array", "items": {"type": "integer"}, "description": "the tracker's command before the gate" + _NULLABLE}})),
    TRUTH: ("foveatrack.Truth", _obj("foveatrack.Truth", "simulation truth: head pose [deg], target [m, world]", {
        "frame_id": {"type": "integer"}, "pan_deg": {"type": "number"}, "tilt_deg": {"type": "number"},
        "target_xyz_m": _XYZ, "true_error_deg": _NUM, "points_on_target": {"type": "integer"}})),
    METRICS: ("foveatrack.Metric", _obj("foveatrack.Metric", "a scalar figure of one frame", {
        "name": {"type": "string"}, "value": _NUM, "frame_id": {"type": "integer"}})),
}


# Record channels that only some recordings have: their schema is declared when the first record
# comes (RECORD_SCHEMAS' channels are declared in every recording).
OPTIONAL_RECORD_SCHEMAS = {
    TRUTH_OBJECTS: ("foveatrack.ObjectTruth", _obj("foveatrack.ObjectTruth", "simulation truth of one object at "
                                                   "frame mid [m, world]", {
        "frame_id": {"type": "integer"}, "id": {"type": "string"},
        "class": {"type": "string", "description": "drone, bird, tree or clutter"}, "xyz_m": _XYZ,
        "velocity_m_s": _XYZ, "size_m": {"type": "number"},
        "rays_hit": {"type": "integer", "description": "rays of the frame that hit it, before the effects"}})),
    TRACKS: ("foveatrack.Tracks", _obj("foveatrack.Tracks", "every track of the multi-object tracker after "
                                       "one frame [m, world]", {
        "frame_id": {"type": "integer"},
        "fixated": {"type": "integer", "description": "the track the fovea served this frame" + _NULLABLE},
        "next_target": {"type": "integer", "description": "the track the fovea serves next" + _NULLABLE},
        "pinned": {"type": "integer", "description": "the operator's pinned track" + _NULLABLE},
        "in_fovea": {"type": "array", "items": {"type": "integer"}},
        "n_points": {"type": "integer"}, "n_foreground": {"type": "integer"}, "n_objects": {"type": "integer"},
        "confirmed_now": {"type": "array", "items": {"type": "integer"}},
        "deleted_now": {"type": "array", "items": {"type": "integer"}},
        "tracks": {"type": "array", "items": {"type": "object", "properties": {
            "id": {"type": "integer"}, "confirmed": {"type": "boolean"},
            "label": {"type": "string", "description": "drone, bird, clutter or unknown"},
            "looks_like": {"type": "string", "description": "the classifier's rules this frame, before the label waits"},
            "xyz_m": _XYZ, "velocity_m_s": _XYZ, "hit": {"type": "boolean"}, "in_view": {"type": "boolean"},
            "score": {"type": "number", "description": "threat score (confirmed tracks)" + _NULLABLE}}}}})),
}


def json_schema_of(name: str) -> tuple[str, dict]:
    """The (schema name, JSON schema) of a record channel: the documented one, or for a channel without
    one (the daemon's events, a later version's channel) an object with its log time, which Foxglove's
    parser accepts (a bare ``{"type": "object"}`` without properties it does not)."""
    if name in RECORD_SCHEMAS:
        return RECORD_SCHEMAS[name]
    if name in OPTIONAL_RECORD_SCHEMAS:
        return OPTIONAL_RECORD_SCHEMAS[name]
    return f"foveatrack.{name}", {"title": f"foveatrack.{name}", "type": "object",
                                  "properties": {"t_ns": {"type": "integer", "description": "log time [ns]"}}}


def _to_jsonable(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (bytes, bytearray, memoryview)):
        return bytes(x).hex()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"cannot record a {type(x).__name__} in JSON")


@functools.lru_cache(maxsize=None)     # built once per layout: a dtype costs ~10 us, a frame's packing ~20
def packed_point_dtype(xyz_dtype: str = "float64") -> np.dtype:
    """Packed point layout of the ``/points`` channel (format 4): x, y, z [m], ``age_ns`` (frame time
    ``t_ns`` - point time [ns]: >= 0 for a frame's points, which precede its end; what Foxglove colours
    by), reflectivity."""
    f = {"float64": "<f8", "float32": "<f4"}[xyz_dtype]
    return np.dtype([("x", f), ("y", f), ("z", f), ("age_ns", "<i4"), ("reflectivity", "u1")])


# ------------------------------------------------------------------ format 3: points on the mm grid
# A Livox reports Cartesian points in int32 mm (the simulator too: sim/sensor.py), which the client
# turns into float64 metres with foveatrack.livox.protocol.mm_to_m.  Such a point's mm value k is
# stored as the float32 multiple of 2^-11 m nearest to k/1000 m: within 0.25 mm of the point, so
# Foxglove draws it where it is, and k = rint(1000 v) exactly (|1000 v - k| <= 1000/2048/2 < 0.5),
# whence the reader's mm_to_m(k) is the original float64 bits.  A multiple of 2^-11 has 11 fewer
# significant bits than k/1000, which the chunk compressor turns into ~15 % fewer bytes (measured,
# docs/recordings.md).  Exact while m = rint(2048 v) fits float32's 24-bit mantissa: |k| < MAX_GRID_MM.
GRID_PER_M = 2048.0
MAX_GRID_MM = 8_192_000        # |x| < 8192 m; a frame with a point past it is stored as float64


def mm_grid_f32(xyz_m: np.ndarray) -> np.ndarray | None:
    """The float32 grid values of points on the mm grid, or None when a point is off the grid (not
    a float64 the client could have decoded) or past ``MAX_GRID_MM``.  xyz_m: (n, 3) float64 [m]."""
    from foveatrack.mm_grid import m_to_mm, mm_to_m

    with np.errstate(invalid="ignore"):      # NaN: off the grid (the check below says so)
        mm = m_to_mm(xyz_m)
    if mm.size and (np.abs(mm).max() >= MAX_GRID_MM or not np.array_equal(mm_to_m(mm), xyz_m)):
        return None
    return (np.rint(xyz_m * GRID_PER_M) / GRID_PER_M).astype(np.float32)


def mm_grid_to_m(v: np.ndarray) -> np.ndarray:
    """float32 grid values -> the float64 metres they stand for (the client's own operation)."""
    from foveatrack.mm_grid import mm_to_m

    return mm_to_m(np.rint(v.astype(np.float64) * 1000.0).astype(np.int32))


def pack_points_numpy(xyz: np.ndarray, age_ns: np.ndarray, reflectivity: np.ndarray) -> np.ndarray:
    """The packed points of a frame (numpy twin of :func:`foveatrack.recording.pack_kernels.pack_points`,
    which the writer uses): float32 on the mm grid when the frame is on it, float64 otherwise.
    ``age_ns``: frame time - point time [ns], within int32 (the caller checks)."""
    grid = mm_grid_f32(xyz)
    out = np.empty(len(age_ns), packed_point_dtype("float64" if grid is None else "float32"))
    src = xyz if grid is None else grid
    out["x"], out["y"], out["z"] = src[:, 0], src[:, 1], src[:, 2]
    out["age_ns"] = age_ns
    out["reflectivity"] = reflectivity
    return out


@dataclass(frozen=True, eq=False)
class PointsFrame:
    """One recorded lidar frame.  xyz (n,3) [m] lidar frame; t_ns_points (n,) int64; reflectivity u8."""

    t_ns: int
    frame_index: int
    xyz: np.ndarray
    t_ns_points: np.ndarray
    reflectivity: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns_points.shape[0])


@dataclass(frozen=True)
class Message:
    """One recorded message: ``record`` is a dict, a :class:`PointsFrame` on the points channel, an
    :class:`ImuSamples` on the IMU channel."""

    channel: str
    t_ns: int
    record: Any


def _decode_points(data: bytes) -> PointsFrame:
    rec = json.loads(data)
    stride = int(rec["point_stride"])
    dt = np.dtype(
        {
            "names": [f["name"] for f in rec["fields"]],
            "formats": [_FOX_TO_NP[int(f["type"])] for f in rec["fields"]],
            "offsets": [int(f["offset"]) for f in rec["fields"]],
            "itemsize": stride,
        }
    )
    raw = base64.b64decode(rec["data"])
    if len(raw) % stride:
        raise ValueError(f"point data of {len(raw)} bytes is not a whole number of {stride}-byte points")
    arr = np.frombuffer(raw, dtype=dt)
    t_ns = int(rec["t_ns"])
    xyz = np.stack([arr["x"], arr["y"], arr["z"]], axis=1).astype(np.float64)
    return PointsFrame(t_ns, int(rec["frame_index"]), xyz, arr["dt_ns"].astype(np.int64) + t_ns,
                       arr["reflectivity"].astype(np.uint8))





# ------------------------------------------------------------------ formats 2-4: protobuf foxglove.PointCloud
# foxglove.PointCloud (https://docs.foxglove.dev/docs/visualization/message-schemas/point-cloud):
# 1 timestamp {1 seconds, 2 nanos}, 2 frame_id, 3 pose, 4 point_stride (fixed32), 5 fields (repeated
# {1 name, 2 offset fixed32, 3 type enum}), 6 data.  Format 4 writes these fields and no other.
# Formats 2 and 3 also wrote two varints the schema does not define (decoders skip them): field 15,
# the frame index, and field 16 (format 3), the unit of their ``dt`` field [ns] (absent: 1).
LEGACY_FRAME_INDEX_FIELD = 15
LEGACY_DT_UNIT_FIELD = 16


def _varint(v: int) -> bytes:
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


@functools.lru_cache(maxsize=None)     # one per layout: the SDK's encoding of it costs ~15 us a frame
def _cloud_tail(dtype: np.dtype) -> bytes:
    """Fields 2-5 of a PointCloud of packed points of ``dtype`` as the Foxglove SDK encodes them:
    frame ``lidar``, pose identity (the points are in frame ``lidar``), the stride and the fields."""
    from foxglove.messages import PackedElementField, PackedElementFieldNumericType as NT, PointCloud, Pose
    from foxglove.messages import Quaternion, Vector3

    types = {"<f8": NT.Float64, "<f4": NT.Float32, "<i4": NT.Int32, "<i2": NT.Int16, "|u1": NT.Uint8}
    fields = [PackedElementField(name=name, offset=int(off), type=types[dt_.str])
              for name, (dt_, off) in dtype.fields.items()]
    pose = Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
    return PointCloud(frame_id="lidar", pose=pose, point_stride=dtype.itemsize, fields=fields).encode()


def encode_points_pb(t_ns: int, packed: np.ndarray) -> bytes:
    """One frame as a foxglove.PointCloud (protobuf, format 4), the bytes the SDK's
    ``PointCloud(...).encode()`` gives (tests/recording/test_pointcloud_schema.py): field 1 (the
    frame's time) made here, fields 2-5 the layout's (:func:`_cloud_tail`), then the point data
    (field 6), appended so that it is copied once.  ``packed``: an array of :func:`packed_point_dtype`."""
    t_ns = int(t_ns)
    sec, nsec = divmod(t_ns, 1_000_000_000)
    ts = (b"\x08" + _varint(sec) if sec else b"") + (b"\x10" + _varint(nsec) if nsec else b"")
    data = memoryview(np.ascontiguousarray(packed)).cast("B")
    tail = _cloud_tail(packed.dtype)
    if not data.nbytes:             # proto3: an empty bytes field is not written
        return b"".join((b"\x0a", _varint(len(ts)), ts, tail))
    return b"".join((b"\x0a", _varint(len(ts)), ts, tail, b"\x32", _varint(data.nbytes), data))


def _pb_fields(buf, i: int = 0, n: int | None = None):
    """(field number, wire type, value) of a protobuf message: int for varint/fixed, memoryview for bytes."""
    n = len(buf) if n is None else n
    while i < n:
        key, i = _read_varint(buf, i)
        fno, wt = key >> 3, key & 7
        if wt == 0:
            v, i = _read_varint(buf, i)
        elif wt == 2:
            ln, i = _read_varint(buf, i)
            if i + ln > n:
                raise ValueError("a length-delimited protobuf field runs past the message")
            v, i = buf[i:i + ln], i + ln
        elif wt == 5:
            v, i = int.from_bytes(buf[i:i + 4], "little"), i + 4
        elif wt == 1:
            v, i = int.from_bytes(buf[i:i + 8], "little"), i + 8
        else:
            raise ValueError(f"protobuf wire type {wt} is not expected in a foxglove.PointCloud")
        yield fno, wt, v


def _read_varint(buf, i: int) -> tuple[int, int]:
    v = shift = 0
    while True:
        if i >= len(buf) or shift > 63:
            raise ValueError("a protobuf varint runs past the message")
        b = buf[i]
        i += 1
        v |= (b & 0x7F) << shift
        if not b & 0x80:
            return v, i
        shift += 7


def _cloud_fields(data: bytes) -> tuple[int, np.ndarray, dict[int, int]]:
    """(time [ns], the packed points, the varints of fields 15 and 16 if present) of a PointCloud."""
    mv = memoryview(data)
    sec = nsec = 0
    stride = 0
    fields: list[tuple[str, int, int]] = []
    raw = b""
    extra: dict[int, int] = {}
    for fno, _wt, v in _pb_fields(mv):
        if fno == 1:
            for f2, _w2, v2 in _pb_fields(v):
                if f2 == 1:
                    sec = v2
                elif f2 == 2:
                    nsec = v2
        elif fno == 4:
            stride = v
        elif fno == 5:
            name, off, typ = "", 0, 0
            for f2, _w2, v2 in _pb_fields(v):
                if f2 == 1:
                    name = bytes(v2).decode()
                elif f2 == 2:
                    off = v2
                elif f2 == 3:
                    typ = v2
            fields.append((name, off, typ))
        elif fno == 6:
            raw = v
        elif fno in (LEGACY_FRAME_INDEX_FIELD, LEGACY_DT_UNIT_FIELD):
            extra[fno] = v
    if not stride or len(raw) % stride:
        raise ValueError(f"point data of {len(raw)} bytes is not a whole number of {stride}-byte points")
    dt = np.dtype({"names": [f[0] for f in fields], "formats": [_FOX_TO_NP[f[2]] for f in fields],
                   "offsets": [f[1] for f in fields], "itemsize": stride})
    return sec * 1_000_000_000 + nsec, np.frombuffer(raw, dtype=dt), extra


def _cloud_xyz(arr: np.ndarray, mm_grid: bool) -> np.ndarray:
    xyz = np.stack([arr["x"], arr["y"], arr["z"]], axis=1)
    return mm_grid_to_m(xyz) if mm_grid and xyz.dtype == np.float32 else xyz.astype(np.float64)


def decode_points_v4(data: bytes) -> PointsFrame:
    """A /points message of format 4.  Its frame index is not in it: ``frame_index`` is -1 here, and
    the reader takes it from the frame's /detections record (:func:`foveatrack.recording.reader.with_frame_index`)."""
    t_ns, arr, _ = _cloud_fields(data)
    if "age_ns" not in arr.dtype.names:
        raise ValueError("a format-4 point cloud without its age_ns field")
    return PointsFrame(t_ns, -1, _cloud_xyz(arr, True), t_ns - arr["age_ns"].astype(np.int64),
                       arr["reflectivity"].astype(np.uint8))


def decode_points_legacy_v2_v3(data: bytes, mm_grid: bool = False) -> PointsFrame:
    """A /points message of format 2 or 3 (``mm_grid``: format 3, where float32 x, y, z are mm-grid
    values, :func:`mm_grid_to_m`; in format 2 they were plain float32): the frame index in field 15,
    point times as ``dt_ns`` (format 2) or ``dt`` in the unit of field 16 (format 3), from the frame time."""
    t_ns, arr, extra = _cloud_fields(data)
    dt_unit = extra.get(LEGACY_DT_UNIT_FIELD, 1)
    frame_index = extra.get(LEGACY_FRAME_INDEX_FIELD, -1)
    dt_ns = arr["dt"].astype(np.int64) * dt_unit if "dt" in arr.dtype.names else arr["dt_ns"].astype(np.int64)
    return PointsFrame(t_ns, frame_index, _cloud_xyz(arr, mm_grid), dt_ns + t_ns, arr["reflectivity"].astype(np.uint8))


# ------------------------------------------------------------------ /imu: the tracker's IMU samples
# One message a frame (a 200 Hz IMU gives ~20 samples in a 100 ms frame), protobuf ``foveatrack.ImuSamples``
# (proto3; the schema below, hand-encoded so that the writer needs no protobuf library):
#
#     message ImuSamples {
#       uint64 t_ns = 1;                  // log time: the end of the frame the samples precede [ns]
#       int64 frame_id = 2;
#       repeated double t_s = 3;          // each sample's time on the tracker's clock [s], as fed
#       repeated double gyro_x_rad_s = 4;  repeated double gyro_y_rad_s = 5;  repeated double gyro_z_rad_s = 6;
#       repeated double accel_x_g = 7;  repeated double accel_y_g = 8;  repeated double accel_z_g = 9;
#     }
#
# Repeated doubles are packed (little-endian float64s), so a batch is written as the arrays' own
# bytes (~7 us a frame, against ~80 us for the same in JSON) and read back to the bit.  ``t_s`` are the
# floats the driver gave ``Tracker.on_imu`` (the daemon's are the sensor's ns x 1e-9, the simulator's
# k / rate_hz): kept as they were, so replay feeds the same bits.  Accel (IMU frame, [g] as a Livox
# sends it) only where the source has one: absent (empty) from the simulator's head gyro.
IMU_SCHEMA_NAME = "foveatrack.ImuSamples"
IMU_COLUMNS = ("t_s", "gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s", "accel_x_g", "accel_y_g", "accel_z_g")
_IMU_FIRST_COLUMN = 3


def _pb_len(field_no: int, payload: bytes) -> bytes:
    return _varint(field_no << 3 | 2) + _varint(len(payload)) + payload


def _imu_descriptor() -> bytes:
    """The FileDescriptorSet of ``foveatrack.ImuSamples`` (google/protobuf/descriptor.proto:
    FileDescriptorProto 1 name, 2 package, 4 message_type, 12 syntax; DescriptorProto 1 name, 2 field;
    FieldDescriptorProto 1 name, 3 number, 4 label (1 optional, 3 repeated), 5 type (1 double, 3 int64,
    4 uint64), 10 json_name)."""
    def field(name: str, number: int, label: int, typ: int) -> bytes:
        camel = name.split("_")[0] + "".join(w.capitalize() for w in name.split("_")[1:])
        return _pb_len(2, _pb_len(1, name.encode()) + bytes([3 << 3]) + _varint(number) + bytes([4 << 3, label])
                       + bytes([5 << 3, typ]) + _pb_len(10, camel.encode()))
    fields = field("t_ns", 1, 1, 4) + field("frame_id", 2, 1, 3) + b"".join(
        field(name, _IMU_FIRST_COLUMN + i, 3, 1) for i, name in enumerate(IMU_COLUMNS))
    message = _pb_len(1, b"ImuSamples") + fields
    file = (_pb_len(1, b"foveatrack/ImuSamples.proto") + _pb_len(2, b"foveatrack") + _pb_len(4, message)
            + _pb_len(12, b"proto3"))
    return _pb_len(1, file)


IMU_DESCRIPTOR = _imu_descriptor()


@dataclass(frozen=True, eq=False)
class ImuSamples:
    """The IMU samples fed to the tracker before frame ``frame_id`` (``t_ns`` = its end [ns]): ``t_s``
    (n,) float64 [s] as fed, ``gyro_rad_s`` (n, 3) [rad/s] and ``accel_g`` (n, 3) [g] or None, in the
    IMU's frame."""

    t_ns: int
    frame_id: int
    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_g: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def imu_columns(t_s, gyro_rad_s, accel_g=None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The samples as the channel stores them: t_s (n,), gyro (n, 3), accel (n, 3) or None, float64;
    a ValueError names a shape that does not fit."""
    t = np.asarray(t_s, np.float64).reshape(-1)
    g = np.asarray(gyro_rad_s, np.float64).reshape(-1, 3) if np.size(gyro_rad_s) else np.empty((0, 3))
    a = None if accel_g is None else (np.asarray(accel_g, np.float64).reshape(-1, 3) if np.size(accel_g)
                                      else np.empty((0, 3)))
    if g.shape[0] != t.shape[0] or (a is not None and a.shape[0] != t.shape[0]):
        raise ValueError(f"{t.shape[0]} IMU sample times but {g.shape[0]} gyro samples"
                         + ("" if a is None else f" and {a.shape[0]} accel samples"))
    return t, g, a


def encode_imu_pb(t_ns: int, frame_id: int, t_s: np.ndarray, gyro_rad_s: np.ndarray,
                  accel_g: np.ndarray | None = None) -> bytes:
    """One frame's samples as a ``foveatrack.ImuSamples`` message (arrays as :func:`imu_columns` gives
    them); an empty column is left out (proto3's rule for an empty repeated field)."""
    cols = [t_s, *np.ascontiguousarray(gyro_rad_s.T)]
    if accel_g is not None:
        cols += [*np.ascontiguousarray(accel_g.T)]
    parts = [bytes([1 << 3]), _varint(int(t_ns)), bytes([2 << 3]), _varint(int(frame_id) & (2**64 - 1))]
    if t_s.size:
        parts += [_pb_len(_IMU_FIRST_COLUMN + i, c.astype("<f8", copy=False).tobytes()) for i, c in enumerate(cols)]
    return b"".join(parts)


def decode_imu_pb(data: bytes) -> ImuSamples:
    """An ``/imu`` message (also one whose columns came unpacked, one double a field, as a protobuf
    encoder may write them)."""
    t_ns = frame_id = 0
    cols: dict[int, list] = {}
    for fno, wt, v in _pb_fields(memoryview(data)):
        if fno == 1:
            t_ns = v
        elif fno == 2:
            frame_id = v - 2**64 if v >= 2**63 else v
        elif _IMU_FIRST_COLUMN <= fno < _IMU_FIRST_COLUMN + len(IMU_COLUMNS):
            if wt == 2:
                if len(v) % 8:
                    raise ValueError(f"an IMU column of {len(v)} bytes is not a whole number of doubles")
                cols.setdefault(fno, []).append(np.frombuffer(v, "<f8"))
            elif wt == 1:
                cols.setdefault(fno, []).append(np.frombuffer(v.to_bytes(8, "little"), "<f8"))
    arr = [np.concatenate(cols[_IMU_FIRST_COLUMN + i]).astype(np.float64) if _IMU_FIRST_COLUMN + i in cols
           else np.empty(0) for i in range(len(IMU_COLUMNS))]
    n = arr[0].shape[0]
    if any(c.shape[0] != n for c in arr[1:4]) or any(c.shape[0] not in (0, n) for c in arr[4:]) or \
            (n and any(c.shape[0] != arr[4].shape[0] for c in arr[5:])):
        raise ValueError(f"the IMU columns have different lengths ({', '.join(str(c.shape[0]) for c in arr)})")
    accel = np.stack(arr[4:], axis=1) if n and arr[4].shape[0] else None
    return ImuSamples(int(t_ns), int(frame_id), arr[0], np.stack(arr[1:4], axis=1).reshape(-1, 3), accel)
