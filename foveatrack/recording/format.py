"""The recording format: channels, the packed point layout, the records a reader hands out.

See :mod:`foveatrack.recording` for the layout of a file.
"""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "foveatrack-recording"
FORMAT_VERSION = "1"
META_NAME = "foveatrack"
POINTS = "points"
DETECTIONS = "detections"
COMMANDS = "commands"
HEAD = "head"
TRUTH = "truth"
METRICS = "metrics"
STANDARD_CHANNELS = (POINTS, DETECTIONS, COMMANDS, HEAD, TRUTH, METRICS)
MCAP_MAGIC = b"\x89MCAP0\r\n"

# foxglove NumericType (docs.foxglove.dev, "NumericType")
_FOX_TYPES = {"u1": 1, "i1": 2, "u2": 3, "i2": 4, "u4": 5, "i4": 6, "f4": 7, "f8": 8}
_FOX_TO_NP = {v: "<" + k for k, v in _FOX_TYPES.items()}

_POINTCLOUD_SCHEMA = {
    "title": "foxglove.PointCloud",
    "type": "object",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "frame_id": {"type": "string"},
        "pose": {"type": "object"},
        "point_stride": {"type": "integer"},
        "fields": {"type": "array"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "frame_index": {"type": "integer"},
        "t_ns": {"type": "integer"},
    },
}


def _json_schema(name: str) -> dict:
    return {"title": f"foveatrack.{name}", "type": "object", "properties": {"t_ns": {"type": "integer"}}}


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


def packed_point_dtype(xyz_dtype: str = "float64") -> np.dtype:
    """Packed point layout of the ``/points`` channel."""
    f = {"float64": "<f8", "float32": "<f4"}[xyz_dtype]
    return np.dtype([("x", f), ("y", f), ("z", f), ("dt_ns", "<i4"), ("reflectivity", "u1")])


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
    """One recorded message: ``record`` is a dict, or a :class:`PointsFrame` on the points channel."""

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


# ====================================================================================== export
