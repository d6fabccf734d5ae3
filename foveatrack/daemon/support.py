"""Daemon helpers: the status line, JSON logs and the recording thread.  No I/O of the lidar or
the head here (the safety gate every command passes is :mod:`foveatrack.gate`, shared by all drivers)."""

from __future__ import annotations

import errno
import json
import os
import math
import queue
import sys
import threading
import time

import numpy as np

from foveatrack.first_failure import StopsAtFirstFailure, close_quietly


# ----------------------------------------------------------------------------------------- logs
class JsonLog(StopsAtFirstFailure):
    """Structured log: one JSON object per line (``t_utc``, ``t_mono_s``, ``event``, fields)."""

    def __init__(self, path: str | None):
        self._fh = None
        self.path = path
        if path:
            from foveatrack.errors import UserError

            try:
                # not through a symlink (a planted link would append to any file the daemon can
                # write); a new log is the owner's alone
                fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
                self._fh = os.fdopen(fd, "a", buffering=1)
            except OSError as exc:
                why = "it is a symbolic link" if exc.errno == errno.ELOOP else exc.strerror
                raise UserError(f"--log {path}: cannot write ({why})") from None
        self._lock = threading.Lock()

    def event(self, event: str, **fields) -> None:
        if self._fh is None:
            return
        import datetime as _dt

        rec = {"t_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds"),
               "t_mono_s": round(time.monotonic(), 6), "event": event, **fields}
        with self._lock:
            # a log on a full disk must not stop the loop (or the STOP of its shutdown)
            self._guarded(self._fh.write, json.dumps(rec, default=_plain) + "\n")

    def close(self) -> None:
        if self._fh is not None:
            close_quietly(self._fh)
            self._fh = None


def _plain(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


class StatusLine(StopsAtFirstFailure):
    """One live line on a terminal (``\\r`` + clear to end of line); silent when not a TTY.

    A write that fails (stderr redirected to a file on a full disk: ENOSPC; a closed pipe) ends the
    writing to that stream, kept in :attr:`error`, and is never raised: the daemon says its warnings
    from the control loop's tick, and a warning about the full disk must not end the tracking."""

    def __init__(self, stream=None, enabled: bool | None = None):
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self._shown = False

    def _write(self, text: str) -> bool:
        return self._guarded(self._emit, text)

    def _emit(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()

    def show(self, text: str) -> None:
        if self.enabled and self._write("\r" + text + "\x1b[K"):
            self._shown = True

    def note(self, text: str) -> None:
        """A line of its own, on a terminal or not (a daemon under systemd or with stderr in a file has
        no status line, and heard of a silent lidar only at its exit): above the status line, which
        the next :meth:`show` draws again."""
        self._write(("\r\x1b[K" if self.enabled and self._shown else "") + text + "\n")
        self._shown = False

    def done(self) -> None:
        if self.enabled and self._shown:
            self._write("\n")
        self._shown = False


def format_status(rate_hz, pts, state, err_pan, err_tilt, latency_ms, drops, head_ok, lidar_note="") -> str:
    """One status line; ``lidar_note`` names what the Livox unit reports as not normal (work state,
    status-code problems), empty when all is well."""
    err = "   -/-   " if err_pan is None else f"{err_pan:+5.1f}/{err_tilt:+5.1f}"
    lat = "-" if latency_ms is None or not math.isfinite(latency_ms) else f"{latency_ms:4.0f}"
    return (f"foveatrack daemon  {rate_hz:4.1f} Hz  {pts:6d} pts/frame  {state:<9}  err {err} deg  "
            f"lat {lat} ms  drops {drops}  head {'ok' if head_ok else 'DOWN'}"
            + (f"  [{lidar_note}]" if lidar_note else ""))


# ----------------------------------------------------------------------------------------- recording
class RecordingThread:
    """Writes to a :class:`foveatrack.recording.RecordingWriter` from its own thread.

    ``submit(fn, *args)`` queues one write job (a callable taking the writer); when the bounded
    queue is full the job is dropped and counted in :attr:`dropped` (the control loop never waits
    for the disk).  ``close()`` writes everything queued, then closes the file.

    Segments (``segment_path``: k -> the file of segment k): the loop sets :attr:`segment`, and every
    job carries the segment it was submitted in; the first job of a new segment moves the writer to
    its file first (:meth:`~foveatrack.recording.RecordingWriter.next_segment`), so a dropped job never
    leaves the records of one segment in another's file.  ``segment_closed()``, where given, is called
    on the writer's thread after each move (the daemon hands the closed segment's freed heap back).
    """

    def __init__(self, writer, max_jobs: int, segment_path=None, overwrite: bool = False, segment_closed=None):
        self.writer = writer
        self.segment = 0
        self._segment_path = segment_path
        self._segment_closed = segment_closed   # called on this thread once a segment's file is complete
        self.overwrite = overwrite
        self.q: queue.Queue = queue.Queue(maxsize=max_jobs)
        self.dropped = 0
        self.written = 0
        self.error: BaseException | None = None
        self.busy_s = 0.0
        self._thread = threading.Thread(target=self._run, name="recording", daemon=True)
        self._thread.start()

    def submit(self, fn, *args) -> bool:
        if self.error is not None:
            self.dropped += 1
            return False
        try:
            self.q.put_nowait((fn, args, self.segment))
            return True
        except queue.Full:
            self.dropped += 1
            return False

    def _run(self) -> None:
        while True:
            job = self.q.get()
            if job is None:
                return
            fn, args, segment = job
            if self.error is not None:
                continue
            t = time.perf_counter()
            try:
                if segment != getattr(self.writer, "segment_index", 0):
                    self.writer.next_segment(self._segment_path(segment), overwrite=self.overwrite, index=segment)
                    if self._segment_closed is not None:
                        self._segment_closed()
                fn(self.writer, *args)
                self.written += 1
            except BaseException as exc:  # noqa: BLE001 - reported by the daemon, recording stops
                self.error = exc
            self.busy_s += time.perf_counter() - t

    def close(self, timeout_s: float = 30.0) -> None:
        self.q.put(None)
        self._thread.join(timeout_s)
        try:
            self.writer.close()
        except Exception as exc:  # noqa: BLE001
            self.error = self.error or exc
