"""Recordings: one crash-safe file format for the simulator and the daemon (MCAP container).

Why MCAP: it is the ROS 2 default log container, append-only and chunked, with per-chunk CRCs and a
summary at the end that a reader does not need.  Everything up to the last *completed chunk* of a
file cut short (kill -9, power loss) is readable, and Foxglove Studio / ``mcap`` CLI open the files.

Layout of a recording (``profile`` "foveatrack", format version 1):

- an MCAP Metadata record ``foveatrack`` written first, with string values ``format`` =
  "foveatrack-recording", ``format_version`` = "1", ``meta_json`` (the writer's ``meta`` dict as JSON:
  scene/config text, seed, ...), ``foveatrack_version``, ``numpy_version``, ``python_version``,
  ``created_utc``.
- channel ``/points`` (schema ``foxglove.PointCloud``, JSON encoding, so Foxglove's 3D panel draws it):
  one message per lidar frame, log time = the frame's ``t_ns``, with the standard fields
  ``timestamp {sec, nsec}``, ``frame_id`` = "lidar", ``pose`` (identity), ``point_stride``,
  ``fields``, ``data`` (base64 of the packed points) plus ``frame_index`` and ``t_ns``.  Packed point
  (little-endian, no padding): x, y, z (float64 by default, float32 with ``points_dtype="float32"``)
  [m, lidar frame X forward, Y left, Z up], ``dt_ns`` int32 (point time − frame ``t_ns``, so
  |dt| < 2.1 s), ``reflectivity`` uint8.  float64 keeps the live values bit-exact for replay.
- JSON channels (schema = a small JSON schema, encoding ``json``), log time = the record's ``t_ns``:
  ``/detections``, ``/commands`` (``raw_hex`` = the bytes sent, ``t_ns`` = send time),
  ``/head`` (head estimates), ``/truth`` (simulation only), ``/metrics``, and any other name given to
  :meth:`RecordingWriter.write`.

Crash safety: records go into the current chunk; the chunk is completed and handed to the OS by
:meth:`RecordingWriter.flush` and automatically when a new frame starts after ``flush_every_frames``
frames (so a chunk holds whole frames with what was written after them).  ``fsync=True`` also
syncs to the disk at each flush.

Not thread-safe: one writer per thread (a daemon writes from one thread or behind a queue).
"""

from __future__ import annotations

import base64
import csv
import datetime as _dt
import json
import os
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from foveatrack.errors import UserError

FORMAT = "foveatrack-recording"
FORMAT_VERSION = "1"
META_NAME = "foveatrack"
POINTS = "points"
DETECTIONS = "detections"
COMMANDS = "commands"
HEAD = "head"
TRUTH = "truth"
METRICS = "metrics"
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


class RecordingWriter:
    """Write a recording; use as a context manager (``close()`` on exit, also after an exception).

    path : file to create (``.mcap`` suggested); an existing file is an error unless ``overwrite``
    meta : dict, JSON-serialisable (scene/config text, seed, parameters, ...)
    flush_every_frames : int >= 1, complete a chunk every this many point frames
    compression : "lz4" (default, fast), "zstd" (smaller, slower) or "none"
    points_dtype : "float64" (bit-exact replay) or "float32" (compact)
    fsync : also fsync the file at each flush
    """

    def __init__(
        self,
        path: str | os.PathLike,
        meta: dict | None = None,
        flush_every_frames: int = 1,
        compression: str = "lz4",
        points_dtype: str = "float64",
        fsync: bool = False,
        overwrite: bool = False,
        created_utc: str | None = None,
    ):
        # created_utc: None stamps the wall-clock time; the simulator passes a fixed text so that
        # one scene and seed give the same file to the bit.
        from mcap.writer import CompressionType, Writer

        comp = {"lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD, "none": CompressionType.NONE}
        if compression not in comp:
            raise UserError(f"recording compression {compression!r} is not one of {sorted(comp)}")
        if points_dtype not in ("float64", "float32"):
            raise UserError(f"recording points_dtype {points_dtype!r} is not 'float64' or 'float32'")
        if int(flush_every_frames) < 1:
            raise UserError(f"flush_every_frames must be >= 1, got {flush_every_frames}")
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise UserError(f"recording {self.path} already exists; choose another path or remove it")
        try:
            meta_json = json.dumps(meta or {}, default=_to_jsonable, sort_keys=True)
        except TypeError as exc:
            raise UserError(f"recording metadata is not JSON-serialisable: {exc}") from None
        try:
            self._fh = open(self.path, "wb")
        except OSError as exc:
            raise UserError(f"cannot create recording {self.path}: {exc.strerror}") from None
        self.flush_every_frames = int(flush_every_frames)
        self.fsync = fsync
        self._pdtype = packed_point_dtype(points_dtype)
        self._xyz_dtype = points_dtype
        self._w = Writer(self._fh, chunk_size=64 << 20, compression=comp[compression])
        from foveatrack import __version__

        self._w.start(profile="foveatrack", library=f"foveatrack {__version__}")
        self._w.add_metadata(
            META_NAME,
            {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "meta_json": meta_json,
                "foveatrack_version": __version__,
                "numpy_version": np.__version__,
                "python_version": platform.python_version(),
                "created_utc": created_utc if created_utc is not None
                else _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            },
        )
        self._channels: dict[str, int] = {}
        self._frames_since_flush = 0
        self._seq = 0
        self.frames_written = 0
        self.messages_written = 0
        self._closed = False
        self.flush()

    # ------------------------------------------------------------------ channels

    def _channel(self, name: str) -> int:
        cid = self._channels.get(name)
        if cid is None:
            if name == POINTS:
                sid = self._w.register_schema("foxglove.PointCloud", "jsonschema", json.dumps(_POINTCLOUD_SCHEMA).encode())
            else:
                sid = self._w.register_schema(f"foveatrack.{name}", "jsonschema", json.dumps(_json_schema(name)).encode())
            cid = self._w.register_channel("/" + name, "json", sid)
            self._channels[name] = cid
        return cid

    def _add(self, name: str, t_ns: int, payload: bytes) -> None:
        if self._closed:
            raise ValueError("recording is closed")
        t_ns = int(t_ns)
        if t_ns < 0:
            raise ValueError(f"t_ns must be >= 0 (MCAP log time), got {t_ns}")
        cid = self._channel(name)
        self._seq += 1
        self._w.add_message(cid, log_time=t_ns, data=payload, publish_time=t_ns, sequence=self._seq & 0xFFFFFFFF)
        self.messages_written += 1

    # ------------------------------------------------------------------ writing

    def write(self, channel: str, t_ns: int, record: dict) -> None:
        """Write a JSON record on ``channel`` (``t_ns`` is added to the record)."""
        if channel == POINTS:
            raise ValueError("use write_points for the points channel")
        if not channel or "/" in channel:
            raise ValueError(f"bad channel name {channel!r}")
        rec = {"t_ns": int(t_ns), **record}
        self._add(channel, t_ns, json.dumps(rec, default=_to_jsonable).encode())

    def write_points(
        self,
        t_ns: int,
        frame_id: int,
        xyz: np.ndarray,
        t_ns_points: np.ndarray,
        reflectivity: np.ndarray | None = None,
    ) -> None:
        """One lidar frame: xyz (n,3) [m] lidar frame, per-point times [ns], reflectivity u8.

        Starts a new chunk first if ``flush_every_frames`` frames are pending.
        """
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        n = xyz.shape[0]
        tp = np.asarray(t_ns_points, dtype=np.int64).reshape(-1)
        refl = np.zeros(n, np.uint8) if reflectivity is None else np.asarray(reflectivity).reshape(-1)
        if tp.shape[0] != n or refl.shape[0] != n:
            raise ValueError(f"xyz has {n} points but t_ns_points {tp.shape[0]} and reflectivity {refl.shape[0]}")
        if self._frames_since_flush >= self.flush_every_frames:
            self.flush()
        dt = tp - int(t_ns)
        if n and (dt.min() < -(2**31) or dt.max() >= 2**31):
            raise ValueError("point times must lie within ±2.1 s of the frame t_ns")
        arr = np.empty(n, self._pdtype)
        arr["x"], arr["y"], arr["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        arr["dt_ns"] = dt
        arr["reflectivity"] = refl
        fields = [
            {"name": name, "offset": int(off), "type": _FOX_TYPES[dt_.str[1:]]}
            for name, (dt_, off) in self._pdtype.fields.items()
        ]
        t_ns = int(t_ns)
        rec = {
            "timestamp": {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000},
            "frame_id": "lidar",
            "pose": {"position": {"x": 0, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
            "point_stride": self._pdtype.itemsize,
            "fields": fields,
            "frame_index": int(frame_id),
            "t_ns": t_ns,
        }
        # splice the base64 text in: json.dumps would scan the whole (escape-free) string again
        head = json.dumps(rec).encode()
        self._add(POINTS, t_ns, head[:-1] + b', "data": "' + base64.b64encode(arr.tobytes()) + b'"}')
        self.frames_written += 1
        self._frames_since_flush += 1

    def write_detection(
        self, t_ns: int, frame_id: int, detected: bool, xyz_m=None, n_points: int = 0, **extra
    ) -> None:
        """Detector output of a frame: target centre xyz_m [m, lidar frame] or None."""
        self.write(DETECTIONS, t_ns, {"frame_index": int(frame_id), "detected": bool(detected),
                                      "xyz_m": None if xyz_m is None else np.asarray(xyz_m, float).tolist(),
                                      "n_points": int(n_points), **extra})

    def write_command(self, t_ns: int, raw: bytes, **extra) -> None:
        """A command sent to the head: ``raw`` bytes as written, ``t_ns`` = the time they were written."""
        self.write(COMMANDS, t_ns, {"raw_hex": bytes(raw).hex(), **extra})

    def write_head_estimate(self, t_ns: int, pan_deg: float, tilt_deg: float, **extra) -> None:
        """The head pose the tracker believes at ``t_ns`` (pan + = left, tilt + = up) [deg]."""
        self.write(HEAD, t_ns, {"pan_deg": float(pan_deg), "tilt_deg": float(tilt_deg), **extra})

    def write_truth(self, t_ns: int, **fields) -> None:
        """Simulation truth at ``t_ns`` (e.g. target_xyz_m, pan_deg, tilt_deg)."""
        self.write(TRUTH, t_ns, fields)

    def write_metric(self, t_ns: int, name: str, value: float, **extra) -> None:
        """A scalar figure (processing time, latency, drop counts, ...)."""
        self.write(METRICS, t_ns, {"name": str(name), "value": value, **extra})

    # ------------------------------------------------------------------ lifecycle

    def flush(self) -> None:
        """Complete the current chunk and hand it to the OS (and the disk if ``fsync``)."""
        if self._closed:
            return
        self._w.flush()
        self._fh.flush()
        if self.fsync:
            os.fsync(self._fh.fileno())
        self._frames_since_flush = 0

    def close(self) -> None:
        """Write the last chunk and the summary; the file is then complete."""
        if self._closed:
            return
        try:
            self._w.finish()
            self._fh.flush()
            if self.fsync:
                os.fsync(self._fh.fileno())
        finally:
            self._closed = True
            self._fh.close()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ====================================================================================== reading


class RecordingReader:
    """Read a recording, also one cut short (everything up to the last completed chunk).

    ``meta`` (the writer's meta dict), ``info`` (format and versions); :meth:`messages` iterates
    in file order; after a full iteration ``complete`` says whether the data section ended properly
    (the writer was closed) and ``problem`` says where and why reading stopped early otherwise.
    Raises UserError naming the file if it is not a foveatrack recording.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        if not self.path.is_file():
            raise UserError(f"recording {self.path} does not exist or is not a file")
        self.size = self.path.stat().st_size
        with open(self.path, "rb") as fh:
            head = fh.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            what = "is empty" if self.size == 0 else "does not start with the MCAP magic"
            if 0 < self.size < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(head):
                what = f"is cut short after {self.size} bytes, before its metadata"
            raise UserError(f"{self.path} is not a foveatrack recording: the file {what}")
        self.info: dict[str, str] = {}
        self.meta: dict = {}
        self.complete: bool | None = None
        self.problem: str | None = None
        for _kind, _obj in self._records(stop_after_meta=True):
            break
        if not self.info:
            raise UserError(
                f"{self.path} is not a foveatrack recording: no complete '{META_NAME}' metadata record"
                f"{' (' + self.problem + ')' if self.problem else ''}"
            )

    def _records(self, stop_after_meta: bool = False) -> Iterator[tuple[str, Any]]:
        from mcap.records import Channel, DataEnd, Message as McapMessage, Metadata
        from mcap.stream_reader import StreamReader

        self.problem = None
        self.complete = False
        channels: dict[int, str] = {}
        with open(self.path, "rb") as fh:
            reader = StreamReader(fh, validate_crcs=True, record_size_limit=max(self.size, 1))
            it = iter(reader.records)
            while True:
                try:
                    rec = next(it)
                except StopIteration:
                    self.complete = True
                    return
                except Exception as exc:  # noqa: BLE001 - any damage ends reading here, cleanly
                    self.problem = (
                        f"stopped at byte {fh.tell()} of {self.size}: "
                        f"{type(exc).__name__}{': ' + str(exc) if str(exc) else ''} (file cut short or damaged)"
                    )
                    return
                if isinstance(rec, Metadata) and rec.name == META_NAME and not self.info:
                    self._set_meta(rec.metadata)
                    if stop_after_meta:
                        yield "meta", None
                        return
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec.topic.lstrip("/")
                elif isinstance(rec, DataEnd):
                    # the data section ended properly; the summary after it holds nothing we need
                    self.complete = True
                    return
                elif isinstance(rec, McapMessage):
                    name = channels.get(rec.channel_id)
                    if name is None:
                        continue
                    yield "message", (name, rec)

    def _set_meta(self, md: dict[str, str]) -> None:
        if md.get("format") != FORMAT:
            raise UserError(f"{self.path} is an MCAP file but not a foveatrack recording (format {md.get('format')!r})")
        if md.get("format_version") != FORMAT_VERSION:
            raise UserError(
                f"{self.path} has recording format version {md.get('format_version')!r}; "
                f"this foveatrack reads version {FORMAT_VERSION}"
            )
        self.info = dict(md)
        try:
            self.meta = json.loads(md.get("meta_json", "{}"))
        except ValueError:
            raise UserError(f"{self.path}: its metadata JSON is damaged") from None

    def messages(self, channels: Iterable[str] | str | None = None) -> Iterator[Message]:
        """Messages in file order, optionally only those of ``channels`` (names without '/')."""
        want = {channels} if isinstance(channels, str) else None if channels is None else set(channels)
        for kind, obj in self._records():
            if kind != "message":
                continue
            name, rec = obj
            if want is not None and name not in want:
                continue
            try:
                record = _decode_points(rec.data) if name == POINTS else json.loads(rec.data)
            except (ValueError, KeyError, TypeError) as exc:
                raise UserError(f"{self.path}: a {name} message at t_ns={rec.log_time} is damaged: {exc}") from None
            yield Message(name, int(rec.log_time), record)

    def points(self) -> Iterator[PointsFrame]:
        """The lidar frames, in order."""
        for m in self.messages(POINTS):
            yield m.record

    def records(self, channel: str) -> list[dict]:
        """All JSON records of one channel."""
        return [m.record for m in self.messages(channel)]

    def channels(self) -> dict[str, int]:
        """Message count per channel (reads the whole file)."""
        out: dict[str, int] = {}
        for kind, obj in self._records():
            if kind == "message":
                out[obj[0]] = out.get(obj[0], 0) + 1
        return out


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


def _out_kind(out_path: Path) -> str:
    suf = out_path.suffix.lower()
    if suf not in (".csv", ".npz"):
        raise UserError(f"export to {out_path}: the file name must end in .csv or .npz")
    return suf[1:]


def export_points(recording: str | os.PathLike, out_path: str | os.PathLike) -> int:
    """Write all recorded points to CSV or NPZ (by suffix); returns the number of points.

    Columns / arrays: frame_index, frame_t_ns, t_ns, x_m, y_m, z_m, reflectivity (lidar frame).
    """
    out_path = Path(out_path)
    kind = _out_kind(out_path)
    frames = list(RecordingReader(recording).points())
    if frames:
        cols = {
            "frame_index": np.concatenate([np.full(len(f), f.frame_index, np.int64) for f in frames]),
            "frame_t_ns": np.concatenate([np.full(len(f), f.t_ns, np.int64) for f in frames]),
            "t_ns": np.concatenate([f.t_ns_points for f in frames]),
            "x_m": np.concatenate([f.xyz[:, 0] for f in frames]),
            "y_m": np.concatenate([f.xyz[:, 1] for f in frames]),
            "z_m": np.concatenate([f.xyz[:, 2] for f in frames]),
            "reflectivity": np.concatenate([f.reflectivity for f in frames]),
        }
    else:
        cols = {k: np.zeros(0) for k in ("frame_index", "frame_t_ns", "t_ns", "x_m", "y_m", "z_m", "reflectivity")}
    n = len(cols["t_ns"])
    if kind == "npz":
        np.savez_compressed(out_path, **cols)
    else:
        with open(out_path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols.keys())
            for row in zip(*(c.tolist() for c in cols.values())):
                w.writerow(row)
    return n


def _flatten(rec: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in rec.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        elif isinstance(v, list) and all(isinstance(e, (int, float)) or e is None for e in v):
            for i, e in enumerate(v):
                out[f"{key}[{i}]"] = e
        else:
            out[key] = v
    return out


def export_trajectory(
    recording: str | os.PathLike,
    out_path: str | os.PathLike,
    channels: Iterable[str] = (DETECTIONS, HEAD, TRUTH, COMMANDS),
) -> int:
    """Write the time series of ``channels`` to CSV or NPZ (by suffix); returns the row count.

    Records are flattened (``xyz_m`` → ``xyz_m[0..2]``, nested dicts → ``a.b``).  CSV: one row per
    record with columns ``channel, t_ns`` and the union of the fields (blank where absent).  NPZ: one
    array per ``<channel>.<field>`` (NaN / "" where a record lacks the field).
    """
    out_path = Path(out_path)
    kind = _out_kind(out_path)
    channels = tuple(channels)
    rows = [(m.channel, _flatten(m.record)) for m in RecordingReader(recording).messages(channels)]
    if kind == "csv":
        keys: list[str] = []
        for _, r in rows:
            keys.extend(k for k in r if k not in keys)
        keys = ["t_ns"] + [k for k in keys if k != "t_ns"]
        with open(out_path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["channel", *keys])
            for ch, r in rows:
                w.writerow([ch, *("" if r.get(k) is None else r.get(k) for k in keys)])
    else:
        arrays: dict[str, np.ndarray] = {}
        for ch in channels:
            recs = [r for c, r in rows if c == ch]
            keys = []
            for r in recs:
                keys.extend(k for k in r if k not in keys)
            for k in keys:
                vals = [r.get(k) for r in recs]
                if all(isinstance(v, (int, float, bool)) for v in vals):
                    arrays[f"{ch}.{k}"] = np.array(vals)
                elif all(isinstance(v, (int, float, bool)) or v is None for v in vals):
                    arrays[f"{ch}.{k}"] = np.array([np.nan if v is None else v for v in vals], dtype=float)
                else:
                    arrays[f"{ch}.{k}"] = np.array(["" if v is None else str(v) for v in vals])
        np.savez_compressed(out_path, **arrays)
    return len(rows)


__all__ = [
    "RecordingWriter",
    "RecordingReader",
    "PointsFrame",
    "Message",
    "export_points",
    "export_trajectory",
    "packed_point_dtype",
]
