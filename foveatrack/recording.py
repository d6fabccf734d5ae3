"""Recordings: one crash-safe file format for the simulator and the daemon (MCAP container).

Why MCAP: it is the ROS 2 default log container, append-only and chunked, with per-chunk CRCs and a
summary at the end that a reader does not need.  Everything up to the last *completed chunk* of a
file cut short (kill -9, power loss) is readable, and Foxglove Studio / ``mcap`` CLI open the files.

Layout of a recording (``profile`` "foveatrack", format version 1):

- an MCAP Metadata record ``foveatrack`` written first, with string values ``format`` =
  "foveatrack-recording", ``format_version`` = "1", ``meta_json`` (the writer's ``meta`` dict as JSON:
  scene/config text, seed, ...), ``channels_json`` (channel id -> name of the standard channels, which
  are defined up front; absent in older files), ``foveatrack_version``, ``numpy_version``,
  ``python_version``, ``created_utc``.
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

Damage: each chunk carries a CRC of its records and is followed by a message index.  The reader
skips a damaged chunk (bad CRC, garbage over it or over its length field), finds the next chunk
whose header holds together and whose CRC verifies by scanning the bytes, reads on, and reports
each skipped stretch (:class:`Damage`: bytes, why, messages lost per channel from the index).

Not thread-safe: one writer per thread (a daemon writes from one thread or behind a queue).
"""

from __future__ import annotations

import base64
import csv
import datetime as _dt
import json
import mmap
import os
import platform
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from foveatrack import mcap_walk as mw
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


@dataclass(frozen=True)
class Damage:
    """One stretch of a recording the reader skipped.

    start_byte, end_byte : the bytes ``[start_byte, end_byte)`` that were skipped
    reason : what was wrong at ``start_byte`` (a chunk's CRC, an unreadable record, ...)
    cut_short : the stretch is an incomplete last record: the file ends inside it
    lost : messages lost per channel, from the message index the writer put after each chunk
        (None when no index of the lost data survived, e.g. a cut-short tail)
    lost_exact : ``lost`` is the whole of what the stretch held; False: at least that much
    lost_t_ns : (first, last) log time of the lost messages when known [ns]
    frames_before : lidar frames read before the stretch
    """

    start_byte: int
    end_byte: int
    reason: str
    cut_short: bool = False
    lost: dict[str, int] | None = None
    lost_exact: bool = False
    lost_t_ns: tuple[int, int] | None = None
    frames_before: int = 0

    @property
    def frames_lost(self) -> int | None:
        """Lidar frames lost in the stretch (a lower bound unless ``lost_exact``), None if unknown."""
        return None if self.lost is None else self.lost.get(POINTS, 0)

    def describe(self) -> str:
        """One line: which bytes, why, and what was lost."""
        where = f"bytes {self.start_byte}-{self.end_byte}"
        if self.cut_short:
            what = f"file cut short at byte {self.start_byte}: {self.reason} ({where})"
        else:
            what = f"skipped {where} ({self.end_byte - self.start_byte} bytes): {self.reason}"
        if self.lost is None:
            what += "; the messages in it are lost" if self.cut_short else \
                "; what it held is unknown (no index of it survived)"
        elif not self.lost:
            what += "; no messages lost (index bytes only)" if self.lost_exact else \
                "; no lost messages are known (no index of a damaged chunk survived)"
        else:
            n_f = self.lost.get(POINTS, 0)
            n_o = sum(self.lost.values()) - n_f
            exact = "" if self.lost_exact else "at least "
            what += (f"; {exact}{n_f} frame{'' if n_f == 1 else 's'} and {n_o} other record{'' if n_o == 1 else 's'}"
                     f" lost ({', '.join(f'{k} {v}' for k, v in sorted(self.lost.items()))})")
        if self.lost_t_ns is not None:
            t0, t1 = self.lost_t_ns
            what += f", log time {t0 / 1e9:.3f} s" if t0 == t1 else f", log times {t0 / 1e9:.3f}-{t1 / 1e9:.3f} s"
        return what


class RecordingReader:
    """Read a recording, also one cut short or damaged: nothing that was recorded and is intact is lost.

    ``meta`` (the writer's meta dict), ``info`` (format and versions); :meth:`messages` iterates
    in file order.  After a full iteration: ``complete`` says whether the data section ended properly
    (the writer was closed); ``damage`` lists each stretch of bytes skipped (:class:`Damage`: byte range,
    why, which messages were lost) and ``problem`` sums them up in one line (None if nothing was skipped).

    A damaged chunk (CRC mismatch, garbage over it, its length field included) is skipped and reading
    resumes at the next chunk whose header holds together and whose CRC verifies -- found by scanning
    the bytes, not by trusting a length that may itself be damaged.  Messages of a channel whose
    definition was in a damaged chunk are attributed by the channel table the writer puts in the
    metadata (or the file's summary, for recordings written before it did); messages of a channel
    that no intact record names are counted in ``problem``.
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
        self.damage: list[Damage] = []
        self.unattributed: dict[int, int] = {}
        self._meta_channels: dict[int, str] = {}
        self._summary: tuple[int, int] | None = None
        self._channels_read: dict[int, str] = {}
        self._summary_channels: dict[int, str] | None = None
        for _ in self._records(stop_after_meta=True):
            break
        if not self.info:
            raise UserError(
                f"{self.path} is not a foveatrack recording: no complete '{META_NAME}' metadata record"
                f"{' (' + self.problem + ')' if self.problem else ''}"
            )

    # ------------------------------------------------------------------ reporting

    @property
    def problem(self) -> str | None:
        """One line saying what was skipped (None: nothing)."""
        parts = [d.describe() for d in self.damage]
        if self.unattributed:
            n = sum(self.unattributed.values())
            parts.append(f"{n} message(s) of channel id(s) {sorted(self.unattributed)} skipped: their channel "
                         f"was defined in a damaged chunk")
        if not parts and self.complete is False:
            parts.append(f"the file ends at byte {self.size} without its end-of-data record: the writer was not "
                         f"closed (cut short, e.g. kill -9 or power loss); every whole chunk before it was read")
        return "; ".join(parts) if parts else None

    # ------------------------------------------------------------------ walking the file

    def _records(self, stop_after_meta: bool = False) -> Iterator[tuple[str, int, bytes]]:
        """Yield (channel name, log time [ns], payload) in file order, skipping damage (see class doc)."""
        self.complete = False
        self.damage = []
        self.unattributed = {}
        size = self.size
        with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            data_end = self._data_end_pos(mm)
            channels: dict[int, str] = {}
            self._channels_read = channels
            frames = 0
            pos = len(MCAP_MAGIC)
            prev_ok = prev_times = None   # opcode of the last record read intact; the last intact chunk's times
            while True:
                if pos == size:
                    return
                if pos == data_end:
                    self.complete = True
                    return
                try:
                    if size - pos < mw.REC.size:
                        raise mw.BadRecord(f"{size - pos} stray byte(s) after the last whole record")
                    op, length = mw.REC.unpack_from(mm, pos)
                    body = pos + mw.REC.size
                    end = body + length
                    if op not in mw.TOP_LEVEL_OPS:
                        raise mw.BadRecord(f"no MCAP record starts there (opcode 0x{op:02x})")
                    if end > size:
                        raise mw.BadRecord(f"a record whose length field ({length} bytes) runs past the end of the file")
                    if op == mw.OP_CHUNK:
                        recs = mw.chunk_records(mm, pos, length)
                    elif op == mw.OP_MINDEX:
                        mw.message_index(mm, body, length)
                        recs = ()
                    elif op == mw.OP_DATA_END:
                        if length != 4:
                            raise mw.BadRecord("a damaged end-of-data record")
                        self.complete = True
                        return
                    elif op == mw.OP_FOOTER:
                        raise mw.BadRecord("a footer where data was expected")
                    elif op == mw.OP_METADATA:
                        recs = ((op, mw.metadata(mm[body:end])),)
                    elif op in (mw.OP_MESSAGE, mw.OP_CHANNEL):
                        if op == mw.OP_MESSAGE and length < mw.MSG_HEAD.size:
                            raise mw.BadRecord("a damaged message record")
                        recs = ((op, memoryview(mm[body:end])),)
                    else:
                        recs = ()
                except mw.BadRecord as exc:
                    if stop_after_meta and not self.info:
                        self.damage.append(Damage(pos, size, str(exc)))
                        return
                    resume, found = self._resync(mm, pos, data_end)
                    self.damage.append(self._account(mm, pos, resume, str(exc), prev_ok, prev_times, frames, found))
                    prev_ok = prev_times = None
                    if resume is None:
                        return
                    pos = resume
                    continue
                for rop, content in recs:
                    if rop == mw.OP_MESSAGE:
                        cid, _seq, log_time, _pub = mw.MSG_HEAD.unpack_from(content, 0)
                        name = channels.get(cid) or self._fallback_channel(cid)
                        if name is None:
                            self.unattributed[cid] = self.unattributed.get(cid, 0) + 1
                            continue
                        if name == POINTS:
                            frames += 1
                        yield name, log_time, bytes(content[mw.MSG_HEAD.size:])
                    elif rop == mw.OP_CHANNEL:
                        cid, topic = mw.channel(content)
                        channels[cid] = topic
                    elif rop == mw.OP_METADATA and not self.info and content[0] == META_NAME:
                        self._set_meta(content[1])
                        if stop_after_meta:
                            self.complete = None     # not known until a full walk
                            yield "", 0, b""
                            return
                if op == mw.OP_CHUNK:
                    prev_times = mw.chunk_times(mm, pos, size)
                prev_ok = op
                pos = end

    def _data_end_pos(self, mm) -> int | None:
        """Where the end-of-data record sits, from the footer of a closed file (None: no valid footer)."""
        size = self.size
        f = size - len(MCAP_MAGIC) - mw.FOOTER_SIZE
        if f < len(MCAP_MAGIC) or mm[size - len(MCAP_MAGIC):] != MCAP_MAGIC:
            return None
        op, length = mw.REC.unpack_from(mm, f)
        if op != mw.OP_FOOTER or length != 20:
            return None
        summary_start, _summary_offset_start, summary_crc = struct.unpack_from("<QQI", mm, f + 9)
        if summary_start:
            if not len(MCAP_MAGIC) < summary_start <= f or zlib.crc32(mm[summary_start:f + 9 + 16]) != summary_crc:
                return None
            de = summary_start - mw.DATA_END_SIZE
        else:
            de = f - mw.DATA_END_SIZE
        if de < len(MCAP_MAGIC) or mw.REC.unpack_from(mm, de) != (mw.OP_DATA_END, 4):
            return None
        if summary_start:
            self._summary = (summary_start, f)
        return de

    def _fallback_channel(self, cid: int) -> str | None:
        """The name of a channel whose definition was not read (it was in a damaged chunk)."""
        name = self._channels_read.get(cid) or self._meta_channels.get(cid)
        if name is not None:
            return name
        if self._summary_channels is None:
            self._summary_channels = self._read_summary_channels()
        return self._summary_channels.get(cid)

    def _read_summary_channels(self) -> dict[int, str]:
        out: dict[int, str] = {}
        span = self._summary
        if span is None:
            return out
        with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            pos, stop = span
            while pos + mw.REC.size <= stop:
                op, length = mw.REC.unpack_from(mm, pos)
                end = pos + mw.REC.size + length
                if end > stop:
                    break
                if op == mw.OP_CHANNEL:
                    cid, topic = mw.channel(mm[pos + mw.REC.size:end])
                    out[cid] = topic
                pos = end
        return out

    def _resync(self, mm, pos: int, data_end: int | None) -> tuple[int | None, list[int]]:
        """The next place to read on from after damage at ``pos``: the first chunk after it whose
        header holds together and whose CRC verifies, else the end-of-data record (closed file),
        else None.  Also returns the positions of chunks after ``pos`` whose header holds together
        but whose contents do not (damaged chunks in the stretch)."""
        stop = self.size if data_end is None else data_end
        found: list[int] = []
        p = pos
        while True:
            p = mm.find(b"\x06", p, stop)
            if p < 0:
                return data_end, found
            length = mw.chunk_length(mm, p, stop)
            if length is not None:
                try:
                    mw.chunk_records(mm, p, length)
                    if p > pos:
                        return p, found
                except mw.BadRecord:
                    pass
                found.append(p)
            p += 1

    def _account(self, mm, pos, resume, reason, prev_ok, prev_times, frames, found) -> Damage:
        """What the skipped stretch ``[pos, resume)`` held, from the message index the writer put after
        each chunk: exact for a damaged chunk whose header holds (its index starts where it ends), a
        lower bound when the stretch starts with bytes that do not hold together (the index found
        just before the next readable record); index records of the intact chunk before the stretch
        (their times lie in its time range) are not counted as lost."""
        size = self.size
        end = size if resume is None else resume
        heads = sorted({p for p in found if pos <= p < end})
        bounds = ([] if heads and heads[0] == pos else [pos]) + heads + [end]
        lost: dict[int, int] | None = None
        times: list[int] = []
        exact = True

        in_intact_index = False

        def add(chain, skip=None):
            nonlocal lost, in_intact_index
            lost = {} if lost is None else lost
            for cid, ts in chain:
                if skip is not None and ts and all(skip[0] <= t <= skip[1] for t in ts):
                    in_intact_index = True
                    continue
                lost[cid] = lost.get(cid, 0) + len(ts)
                times.extend(ts)

        for s, e in zip(bounds, bounds[1:]):
            if s in heads:                      # a damaged chunk whose header holds together
                after = s + mw.REC.size + mw.U64.unpack_from(mm, s + 1)[0]
                chain = mw.index_chain(mm, after, e)
                if chain is not None:
                    add(chain)
                    continue
                exact = False
                chain = mw.index_chain_ending_at(mm, after, e)
            else:                               # bytes that do not hold together
                exact = False
                chain = mw.index_chain_ending_at(mm, s, e)
            if chain:
                add(chain, prev_times if s == pos and prev_ok in (mw.OP_CHUNK, mw.OP_MINDEX) else None)
        cut_short = resume is None and mw.record_runs_past(mm, pos, size)
        if cut_short:
            if mm[pos] == mw.OP_MINDEX and prev_ok in (mw.OP_CHUNK, mw.OP_MINDEX):
                reason, lost, exact = "its last record, a message index of the chunk before it, is incomplete", {}, True
            else:
                reason = "its last record is incomplete"
                t = mw.chunk_times(mm, pos, size)
                if t is not None:
                    times.extend(t)
        elif resume is None:
            reason += "; no readable chunk after it"
        if in_intact_index and not cut_short:
            reason += " (in the message index of the intact chunk before it)"
        names: dict[str, int] | None = None
        if lost is not None:
            names = {}
            for cid, n in lost.items():
                name = self._fallback_channel(cid) or f"channel id {cid}"
                names[name] = names.get(name, 0) + n
        return Damage(pos, end, reason, cut_short, names, exact and lost is not None,
                      (min(times), max(times)) if times else None, frames)

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
            self._meta_channels = {int(k): v for k, v in json.loads(md.get("channels_json", "{}")).items()}
        except (ValueError, AttributeError):
            raise UserError(f"{self.path}: its metadata JSON is damaged") from None

    # ------------------------------------------------------------------ public reading

    def messages(self, channels: Iterable[str] | str | None = None) -> Iterator[Message]:
        """Messages in file order, optionally only those of ``channels`` (names without '/')."""
        want = {channels} if isinstance(channels, str) else None if channels is None else set(channels)
        for name, log_time, data in self._records():
            if want is not None and name not in want:
                continue
            try:
                record = _decode_points(data) if name == POINTS else json.loads(data)
            except (ValueError, KeyError, TypeError) as exc:
                raise UserError(f"{self.path}: a {name} message at t_ns={log_time} is damaged: {exc}") from None
            yield Message(name, int(log_time), record)

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
        for name, _t, _d in self._records():
            out[name] = out.get(name, 0) + 1
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
    "RecordingExistsError",
    "Damage",
    "PointsFrame",
    "Message",
    "export_points",
    "export_trajectory",
    "packed_point_dtype",
]
