"""Writing a recording: :class:`RecordingWriter` (append-only, chunked per frame, crash-safe)."""

from __future__ import annotations

import base64
import datetime as _dt
import json
import os
import platform
from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.recording.format import (_FOX_TYPES, _POINTCLOUD_SCHEMA, COMMANDS, DETECTIONS, FORMAT,
                                         FORMAT_VERSION, HEAD, META_NAME, METRICS, POINTS, STANDARD_CHANNELS,
                                         TRUTH, _json_schema, _to_jsonable, packed_point_dtype)


class RecordingExistsError(UserError):
    """The recording file exists and ``overwrite`` was not given (``path``: that file).  Drivers
    catch it to say how to fix their own configuration (the daemon: ``{time}`` in its path)."""

    def __init__(self, path: Path):
        self.path = path
        what = "an empty file" if path.is_file() and path.stat().st_size == 0 else \
            "a directory" if path.is_dir() else "a file"
        super().__init__(f"recording {path} already exists ({what}); it is never overwritten unless asked: "
                         f"choose another path, move it away, or pass overwrite=True")


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
            raise RecordingExistsError(self.path)
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
        # The standard channels are defined up front, in the first chunk, and named in the metadata
        # too: a reader then attributes every later chunk's messages even if that chunk is damaged.
        self._channels: dict[str, int] = {}
        for name in STANDARD_CHANNELS:
            self._channel(name)
        self._w.add_metadata(
            META_NAME,
            {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "meta_json": meta_json,
                "channels_json": json.dumps({str(cid): name for name, cid in self._channels.items()}),
                "foveatrack_version": __version__,
                "numpy_version": np.__version__,
                "python_version": platform.python_version(),
                "created_utc": created_utc if created_utc is not None
                else _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            },
        )
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
