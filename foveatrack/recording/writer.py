"""Writing a recording: :class:`RecordingWriter` (append-only, chunked per frame, crash-safe)."""

from __future__ import annotations

import abc
import datetime as _dt
import errno
import json
import os
import platform
from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.mm_grid import quantise_to_mm_grid
from foveatrack.recording.format import (CHANNELS_META_NAME, COMMANDS, DETECTIONS, FORMAT, FORMAT_VERSION, HEAD, IMU,
                                         MAX_GRID_MM, META_CRC_KEY, META_NAME, METRICS, POINTS, TRUTH, _to_jsonable,
                                         imu_columns, meta_crc32)
from foveatrack.file_lock import hold as _hold
from foveatrack.recording.foxglove_view import FoxgloveChannels
from foveatrack.recording.pack_kernels import pack_points
from foveatrack.recording.writeback import WritebackPacer


def _sdk_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("foxglove-sdk")
    except PackageNotFoundError:
        return "?"


class RecordingExistsError(UserError):
    """The recording file exists and ``overwrite`` was not given (``path``: that file).  Drivers
    catch it to say how to fix their own configuration (the daemon: ``{time}`` in its path)."""

    def __init__(self, path: Path):
        self.path = path
        what = "an empty file" if path.is_file() and path.stat().st_size == 0 else \
            "a directory" if path.is_dir() else "a file"
        super().__init__(f"recording {path} already exists ({what}); it is never overwritten unless asked: "
                         f"choose another path, move it away, or ask for it to be replaced (--overwrite; "
                         f"a daemon's [recording] overwrite = true)")


class RecordCalls(abc.ABC):
    """The typed calls every recording writer takes, each a :meth:`write` on its channel (shared by
    :class:`RecordingWriter` and :class:`foveatrack.recording.writer_process.RecordingProcess`)."""

    @abc.abstractmethod
    def write(self, channel: str, t_ns: int, record: dict) -> None:
        """Write a JSON record on ``channel`` (``t_ns`` is added to the record)."""

    @abc.abstractmethod
    def write_imu(self, t_ns: int, frame_id: int, t_s, gyro_rad_s, accel_g=None) -> None:
        """The IMU samples fed to the tracker before frame ``frame_id`` (``t_ns`` = its end): ``t_s``
        (n,) [s] as fed, ``gyro_rad_s`` (n, 3) [rad/s], ``accel_g`` (n, 3) [g] where the source has
        one; one ``/imu`` message (:mod:`foveatrack.recording.format`), written after the frame's points."""

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


def _drop_quietly(writer) -> None:
    """Drop a writer's failed SDK writer without the SDK's log line about it ("Failed to close MCAP
    writer: ... attempted another write after a write method failed"): the RecordingWriteError
    raised says what happened, in words."""
    import logging

    log = logging.getLogger("foxglove_py.mcap")
    was, log.disabled = log.disabled, True
    try:
        writer._w = None
    finally:
        log.disabled = was


class RecordingWriteError(UserError):
    """Writing the recording failed part-way (its disk full, an I/O error): the file holds the
    frames written before, readable as it is (the reader takes every complete chunk); nothing more
    is written to it."""

    def __init__(self, path: Path, frames_kept: int, cause: BaseException, begun: bool = True):
        self.path, self.frames_kept, self.cause = path, frames_kept, cause
        full = _disk_full(path, cause)
        self.disk_full = full is not None
        self.why = _why_write_failed(cause, full, path)     # in words ("no space left on its disk ...")
        if not begun:       # its metadata did not fit: the file was removed, nothing was recorded
            super().__init__(f"cannot create recording {path}: {self.why}; nothing was left under its name")
            return
        super().__init__(f"cannot write recording {path}: {self.why}; the "
                         f"{frames_kept} frame(s) written before are kept and readable as they are "
                         f"(foveatrack replay or export {path}); nothing more is recorded")


#: free space under which a failed write is said to be a full disk [bytes] (a chunk is one frame: up
#: to ~1 MB at 480 k points/s, so a chunk that did not fit can leave that much free)
FULL_DISK_BYTES = 16 * 1024 * 1024


def _disk_full(path: Path, exc: BaseException) -> tuple[int | None] | None:
    """Whether a failed write was a full disk: ``(free bytes or None,)`` if so, else None.  The SDK says
    only "I/O error from writing" (the OS's errno stays inside it), so a full disk is told by ENOSPC or
    by the free space of the file system the file is on."""
    err = getattr(exc, "errno", None)
    try:
        st = os.statvfs(path.parent)
        free = st.f_bavail * st.f_frsize
    except OSError:
        free = None
    if err == errno.ENOSPC or (free is not None and free < FULL_DISK_BYTES):
        return (free,)
    return None


def _why_write_failed(exc: BaseException, full: tuple[int | None] | None, path: Path) -> str:
    """In words; ``full``: :func:`_disk_full`'s answer for it."""
    if full is not None:
        free = full[0]
        return "no space left on its disk" + (f" ({free:,} bytes free on the file system of {path.parent})"
                                              if free is not None else "")
    return (exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc) or type(exc).__name__)


def _create_private(path: Path, overwrite: bool, mode: int) -> None:
    """Create the recording's file before the SDK opens it: exclusively (no check-then-open race) and
    not through a symbolic link (with ``overwrite`` a link is replaced, never its target written), with
    ``mode`` (0600 by default: a recording holds the configuration)."""
    if overwrite and (path.is_symlink() or path.is_file()):
        path.unlink()
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), mode)
    except FileExistsError:
        raise RecordingExistsError(path) from None
    except OSError as exc:
        raise UserError(f"cannot create recording {path}: {exc.strerror}") from None
    os.close(fd)


def check_options(path, meta, flush_every_frames, compression, compression_level, points_dtype,
                  overwrite) -> tuple[Path | None, str, int]:
    """Check a writer's options as :class:`RecordingWriter` takes them (a :class:`UserError` names the
    one that is wrong): (the path, the metadata as JSON, the compression level)."""
    if compression not in COMPRESSIONS:
        raise UserError(f"recording compression {compression!r} is not one of {sorted(COMPRESSIONS)}")
    if points_dtype not in ("float64", "float32"):
        raise UserError(f"recording points_dtype {points_dtype!r} is not 'float64' or 'float32'")
    if int(flush_every_frames) < 1:
        raise UserError(f"flush_every_frames must be >= 1, got {flush_every_frames}")
    path = None if path is None else Path(path)
    if path is not None and path.exists() and not overwrite:
        raise RecordingExistsError(path)
    if path is not None and path.is_dir():
        raise UserError(f"cannot create recording {path}: it is a directory")
    try:
        meta_json = json.dumps(meta or {}, default=_to_jsonable, sort_keys=True)
    except TypeError as exc:
        raise UserError(f"recording metadata is not JSON-serialisable: {exc}") from None
    # zstd 1 unless asked: measured against lz4 and zstd 2-6 on fig12 (docs/recordings.md)
    level = int(compression_level) if compression_level is not None else 1 if compression == "zstd" else 0
    return path, meta_json, level


COMPRESSIONS = ("lz4", "zstd", "none")
#: a point's time is stored as int32 ns before its frame's ``t_ns`` (its ``age_ns``): the most a point
#: may lie before the frame's time [ns] (and one ns more after it)
MAX_POINT_AGE_NS = 2**31 - 1


def point_ages_fit(t_ns: int, t_ns_points) -> bool:
    """Whether every point time lies within what a frame recorded at ``t_ns`` holds (the rule
    :meth:`RecordingWriter.write_points` refuses by; ``track --record`` asks it first, to say so in
    words)."""
    tp = np.asarray(t_ns_points, dtype=np.int64).reshape(-1)
    return not tp.size or (t_ns - int(tp.min()) <= MAX_POINT_AGE_NS and t_ns - int(tp.max()) >= -MAX_POINT_AGE_NS - 1)
# a recording's pages go to the disk and out of the cache every 32 MB (foveatrack.recording.writeback;
# 0: left to the kernel)
WRITEBACK_STEP_BYTES = 32 * 1024 * 1024
# json.dumps(rec, default=_to_jsonable) to the byte, without building an encoder per record (~5 us each)
_RECORD_JSON = json.JSONEncoder(default=_to_jsonable)


class RecordingWriter(RecordCalls):
    """Write a recording with the Foxglove SDK on the caller's thread; use as a context manager
    (``close()`` on exit, also after an exception).  Not thread-safe.
    :class:`foveatrack.recording.writer_process.RecordingProcess` takes the same calls and writes the
    same file from a child process.

    path : file to create (``.mcap`` suggested); an existing file is an error unless ``overwrite``.
        None: no file (the messages go only to the sinks of :attr:`context`, e.g. the live view)
    meta : dict, JSON-serialisable (scene/config text, seed, parameters, ...)
    flush_every_frames : int >= 1, complete a chunk every this many point frames
    compression : "zstd" (default), "lz4" or "none"; compression_level : the compressor's level (None:
        1 for zstd, the compressor's default otherwise; 0: the compressor's default).  zstd 1: points
        on the mm grid compress to ~12 B/point (fig12: 12.3 MB) for about the CPU of lz4 (15.3 MB);
        zstd 3 saves 5 % more for 1.7x the CPU (docs/recordings.md)
    points_dtype : "float64" (default, exact): a frame whose points are on the Livox mm grid (what a
        Livox's Cartesian data types and the simulator give) is stored compactly and exactly (float32 on
        a 2^-11 m grid, format 3), any other frame as float64.  "float32": every frame compact, points
        off the grid rounded to the nearest mm (at most 0.5 mm)
    fsync : also fsync the file at each flush
    file_mode : the new file's permissions (default 0600: a recording holds the configuration; 0o644 to share)
    created_utc : None stamps the wall-clock time; the simulator passes a fixed text so that one
        scene and seed give the same file to the bit
    log_time : the MCAP log time of each message (what Foxglove's timeline shows), in UTC: an int
        offset [ns] added to the message's ``t_ns`` (the simulator: its scene's ``start_utc``), or
        "host" for the host's clock when the message is written (the daemon).  Every message keeps its
        own ``t_ns`` (the sensor's or simulator's clock), which is what a reader and replay use;
        0 (default) logs ``t_ns`` itself; a callable ``t_ns -> log time`` whose ``name`` is what the
        metadata says (a recording rewritten with its own log times: :mod:`foveatrack.daemon.recover`)
    segment_index : this file's place in a run split into segments (0: the first, or the only file;
        :meth:`next_segment` numbers the later ones; ``recover`` keeps a segment's)
    """

    def __init__(
        self,
        path: str | os.PathLike | None,
        meta: dict | None = None,
        flush_every_frames: int = 1,
        compression: str = "zstd",
        compression_level: int | None = None,
        points_dtype: str = "float64",
        fsync: bool = False,
        overwrite: bool = False,
        created_utc: str | None = None,
        file_mode: int = 0o600,
        log_time=0,
        segment_index: int = 0,
        writeback_step_bytes: int = WRITEBACK_STEP_BYTES,
    ):
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self.path, meta_json, level = check_options(path, meta, flush_every_frames, compression,
                                                    compression_level, points_dtype, overwrite)
        self.flush_every_frames = int(flush_every_frames)
        self.fsync = fsync
        self._xyz_dtype = points_dtype
        self.view = FoxgloveChannels(json.loads(meta_json), points_dtype, log_time)
        self.context = self.view.context
        self._w = None
        from foveatrack import __version__

        if self.path is not None:
            # chunk_size None: a chunk ends only at flush(), so a chunk holds whole frames; the SDK
            # writes the Schema and Channel records in the chunk of each channel's first message
            comp = {"lz4": MCAPCompression.Lz4, "zstd": MCAPCompression.Zstd, "none": None}[compression]
            self._opts = MCAPWriteOptions(compression=comp, profile="foveatrack", chunk_size=None,
                                          compression_threads=0, compression_level=level)
            self._file_mode = file_mode
            self._writeback_step = int(writeback_step_bytes)
            self._pacer = None
            self._open_file(self.path, overwrite)
            md = {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "meta_json": meta_json,
                "foveatrack_version": __version__,
                "numpy_version": np.__version__,
                "python_version": platform.python_version(),
                "writer": f"foxglove-sdk {_sdk_version()}",
                "created_utc": created_utc if created_utc is not None
                else _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                "chunk_crcs": "required",      # the SDK writes every chunk's CRC: a 0 there is damage
                "log_time": (log_time.name if callable(log_time) else "host_utc" if log_time == "host"
                             else f"t_ns+{int(log_time)}"),
            }
            if segment_index:
                md["segment_index"] = str(int(segment_index))
            self._md = md
        self.write_error: RecordingWriteError | None = None    # the write that failed, if one did
        self.frames_kept = 0      # frames in complete chunks handed to the OS (what a reader gets), over the run
        self._frames_before_file = 0     # of those, the ones in the earlier segments' files (next_segment)
        self.segment_index = int(segment_index)
        self._tabled = 0
        self._frames_since_flush = 0
        self.frames_written = 0
        self.messages_written = 0
        self._closed = False
        try:
            if self._w is not None:
                self._write_meta(self._md)
            self.flush()
        except BaseException as exc:
            self._abandon()         # no writer half made: its file's lock and the SDK's writer go now
            if isinstance(exc, RecordingWriteError) and self.path is not None:
                # the file made above (exclusively, ours) holds nothing a reader could take: an empty
                # file left on a full disk was then called a recording whose "0 frame(s)" were kept
                self.path.unlink(missing_ok=True)
                raise RecordingWriteError(self.path, 0, exc.cause, begun=False) from None
            raise

    def _open_file(self, path: Path, overwrite: bool) -> None:
        import foxglove

        _create_private(path, overwrite, self._file_mode)
        self._release()
        self._lock_fd = _hold(path)
        try:
            self._w = foxglove.open_mcap(path, allow_overwrite=True, context=self.context,
                                         writer_options=self._opts)
        except Exception as exc:  # noqa: BLE001 - the SDK raises its own error types for I/O
            self._release()
            raise UserError(f"cannot create recording {path}: {exc}") from None
        if self._pacer is not None:
            self._pacer.close()
        self._pacer = WritebackPacer(path, self._writeback_step) if self._writeback_step > 0 else None

    def _write_meta(self, md: dict) -> None:
        md = dict(md)
        md[META_CRC_KEY] = meta_crc32(md)
        self._sdk(self._w.write_metadata, META_NAME, md)

    def _sdk(self, call, *args):
        """One call that writes to the file (the SDK's, an fsync): a failure -- a full disk, an I/O
        error -- is a :class:`RecordingWriteError` naming the file and what it keeps; the file is
        then written no more (a later call raises the same)."""
        if self.write_error is not None:
            raise self.write_error
        try:
            return call(*args)
        except (RuntimeError, OSError) as exc:   # the SDK's FoxgloveError is a RuntimeError
            # the frames the current file keeps: the error names that file (a segment's, not the run's)
            self.write_error = RecordingWriteError(self.path, self.frames_kept - self._frames_before_file, exc)
        # the failed SDK writer goes now, while the interpreter runs: kept (by this frame's ``call``
        # in the error's traceback, or the writer itself) to the interpreter's exit, its drop panicked
        call = args = None
        _drop_quietly(self)
        raise self.write_error

    def _abandon(self) -> None:
        """Let go of the file without writing more: the SDK's writer is dropped here, while the
        interpreter runs (one that failed, dropped at the interpreter's exit, panicked there), and
        the lock released."""
        self._closed = True
        self._w = None
        self._release()
        if getattr(self, "_pacer", None) is not None:
            self._pacer.close()

    def next_segment(self, path: str | os.PathLike, overwrite: bool = False, index: int | None = None) -> None:
        """Complete the current file (its last chunk, summary and footer) and go on in a new one at
        ``path``, at a frame boundary (call it before the next frame's records).  Each segment is a
        complete recording with the run's metadata and ``segment_index`` 1, 2, ... (the first file
        has none); the MCAP writer keeps an index entry per chunk until its file closes (~250 B a
        frame, ~10 MB an hour), so a run of any length holds at most one segment's.  ``index``: the
        new segment's (default the next; a driver whose jobs for a segment were all dropped skips it).  The Foxglove
        channels stay (the live view does not notice); the new file gets its own channel table and
        D at its first head estimate (its first keyframe)."""
        if self._closed or self._w is None:
            raise ValueError("recording is closed" if self._closed else "a writer without a file has no segments")
        path = Path(path)
        self.view.end_frame()          # what of the last frame still waits goes in the old file
        self._sdk(self._w.close)
        self._w = None
        if self.fsync:
            self._sdk(_fsync, self.path)
        self._open_file(path, overwrite)
        self.path = path
        # the old file, closed whole, keeps every frame written so far: the new one's count starts here
        self.frames_kept = self._frames_before_file = self.frames_written
        self.segment_index = self.segment_index + 1 if index is None else int(index)
        self._md["segment_index"] = str(self.segment_index)
        try:
            self._write_meta(self._md)
            self._tabled = 0
            self.view.new_file()
            self._frames_since_flush = 0
            self.flush()
        except RecordingWriteError as exc:
            # as __init__ does for the first file: the new one (exclusively ours) holds nothing a reader
            # could take; left, it was described as a recording whose frames were kept
            self._w = None             # (the failed SDK writer is gone already: _sdk)
            self._release()
            path.unlink(missing_ok=True)
            # every later call raises this, as after any failed write; close() lets the writer go
            self.write_error = RecordingWriteError(path, 0, exc.cause, begun=False)
            raise self.write_error from None

    # ------------------------------------------------------------------ channels

    def _add(self, name: str, t_ns: int) -> int:
        if self._closed:
            raise ValueError("recording is closed")
        if self.write_error is not None:
            raise self.write_error
        t_ns = int(t_ns)
        if t_ns < 0:
            raise ValueError(f"t_ns must be >= 0 (MCAP log time), got {t_ns}")
        self.messages_written += 1
        return t_ns

    def _channel_table(self) -> None:
        """Name the MCAP channel ids in a metadata record between chunks whenever new channels
        appeared: a reader then attributes the messages of a chunk whose Channel record was lost in
        a damaged chunk.  The SDK numbers channels 1, 2, ... in the order of their first message
        (checked against the file's summary in tests/recording/test_foxglove.py)."""
        order = self.view.first_log_order
        if self._w is None or len(order) == self._tabled:
            return
        self._tabled = len(order)
        self._sdk(self._w.write_metadata, CHANNELS_META_NAME, {"channels_json": json.dumps(
            {str(i + 1): name for i, name in enumerate(order)})})

    # ------------------------------------------------------------------ writing

    def write(self, channel: str, t_ns: int, record: dict) -> None:
        """Write a JSON record on ``channel`` (``t_ns`` is added to the record)."""
        if channel in (POINTS, IMU):
            raise ValueError(f"use write_{channel} for the {channel} channel")
        if not channel or "/" in channel:
            raise ValueError(f"bad channel name {channel!r}")
        t_ns = self._add(channel, t_ns)
        rec = {"t_ns": t_ns, **record}
        self.view.log_json(channel, t_ns, _RECORD_JSON.encode(rec).encode(), rec)

    def write_points(
        self,
        t_ns: int,
        frame_id: int,
        xyz: np.ndarray,
        t_ns_points: np.ndarray,
        reflectivity: np.ndarray | None = None,
    ) -> None:
        """One lidar frame: xyz (n,3) [m] lidar frame, per-point times [ns], reflectivity u8.
        ``frame_id`` is not stored with the points (format 4: a reader takes it from the frame's
        /detections record, which every driver writes after them).

        Starts a new chunk first if ``flush_every_frames`` frames are pending.
        """
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        n = xyz.shape[0]
        tp = np.asarray(t_ns_points, dtype=np.int64).reshape(-1)
        refl = np.zeros(n, np.uint8) if reflectivity is None else np.asarray(reflectivity).reshape(-1)
        if tp.shape[0] != n or refl.shape[0] != n:
            raise ValueError(f"xyz has {n} points but t_ns_points {tp.shape[0]} and reflectivity {refl.shape[0]}")
        self.view.end_frame()     # what of the last frame still waits goes in its chunk
        if self._frames_since_flush >= self.flush_every_frames:
            self.flush()
        t_ns = int(t_ns)
        if not point_ages_fit(t_ns, tp):
            raise ValueError("point times must lie within ±2.1 s of the frame t_ns")
        # x, y, z: on the mm grid (a Livox's Cartesian output, the simulator's) compact and exact,
        # otherwise float64 (exact); "float32" forces the grid, rounding to the nearest mm
        if self._xyz_dtype == "float32":
            xyz = quantise_to_mm_grid(xyz)
        arr = pack_points(xyz, t_ns, tp, refl)
        if self._xyz_dtype == "float32" and arr.dtype["x"] != np.float32:
            raise ValueError(f"a point lies {MAX_GRID_MM / 1000:.0f} m or more from the lidar: past what "
                             f"points_dtype='float32' stores; record with 'float64'")
        t_ns = self._add(POINTS, t_ns)
        self.view.log_points(t_ns, arr)
        self.frames_written += 1
        self._frames_since_flush += 1

    def write_imu(self, t_ns: int, frame_id: int, t_s, gyro_rad_s, accel_g=None) -> None:
        t, g, a = imu_columns(t_s, gyro_rad_s, accel_g)
        t_ns = self._add(IMU, t_ns)
        self.view.log_imu(t_ns, frame_id, t, g, a)

    # ------------------------------------------------------------------ lifecycle

    def flush(self) -> None:
        """Complete the current chunk and hand it to the OS (and the disk if ``fsync``)."""
        if self._closed:
            return
        if self.write_error is not None:
            raise self.write_error
        self._frames_since_flush = 0
        if self._w is None:
            return
        self._sdk(self._w.flush)
        self._channel_table()
        if self.fsync:
            self._sdk(_fsync, self.path)
        self.frames_kept = self.frames_written
        if self._pacer is not None:
            self._sdk(self._pacer.after_flush)

    def close(self) -> None:
        """Write the last chunk and the summary; the file is then complete."""
        if self._closed:
            return
        try:
            self.view.finish()      # the last head estimate's transforms, if they still wait
            # after a failed write the file is left as it is (its SDK writer is gone)
            if self._w is not None:
                self._sdk(self._w.close)
                if self.fsync:
                    self._sdk(_fsync, self.path)
        finally:
            self._abandon()

    def _release(self) -> None:
        """Let go of the file's lock (:func:`_hold`): the file is complete, or the next segment's is taken."""
        fd, self._lock_fd = getattr(self, "_lock_fd", None), None
        if fd is not None:
            os.close(fd)

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ====================================================================================== reading


def _fsync(path) -> None:
    """Sync a written file to the disk (the writer's ``fsync=True``)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
