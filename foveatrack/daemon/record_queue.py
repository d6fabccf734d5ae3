"""The daemon's recording: its metadata, the writer behind a queue, the live view, and the jobs the
frame loop hands that queue (one role of :class:`foveatrack.daemon.runtime.Daemon`).

The writer runs in :class:`~foveatrack.daemon.support.RecordingThread` behind a bounded job queue:
the loop never waits on a disk (drops are counted).  A job is a function run on the writer's thread
with the writer first: ``_job_frame`` writes a processed frame as every driver does
(:mod:`foveatrack.recording.records`), ``_job_event`` one of the daemon's events.
"""

from __future__ import annotations

import sys
import time

from foveatrack.daemon.support import RecordingThread
from foveatrack.recording.format import DAEMON_EVENTS
from foveatrack.recording.records import write_record, write_tracker_frame


def _job_frame(w, fid, frame, out, cmd_rec, proc_ms, lat_ms, imu=None):
    """Write one processed frame as every driver does (:mod:`foveatrack.recording.records`); ``imu``:
    the samples fed to the tracker before it (attitude = "gyro"), None otherwise."""
    t_end = write_tracker_frame(w, fid, frame, out, imu)
    if cmd_rec is not None:
        write_record(w, cmd_rec)
    w.write_metric(t_end, "processing_ms", proc_ms, frame_id=fid)
    if lat_ms is not None:
        w.write_metric(t_end, "latency_ms", lat_ms, frame_id=fid)


def _job_event(w, t_ns, rec: dict):
    w.write(DAEMON_EVENTS, t_ns, rec)


def _why(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


class DaemonRecording:
    """The recording's part of the daemon (a mixin of ``Daemon``; its state lives on the daemon:
    ``recorder``, ``recording_path``, ``live``)."""

    def _meta(self) -> dict:
        from foveatrack.recording.run_meta import DaemonOrigin, RecordingMeta

        # what runs (the tracker's configuration with the head's facts, its table, the gate, and the
        # multi-object tracker's effective [tracker.sky] table where it runs: replay rebuilds it), typed
        c = self.cfg
        sky_table = getattr(self.tracker, "sky_table", None)
        return RecordingMeta(self.tracker.config, c.head.facts.tracker_values(), self.table, self.limits,
                             DaemonOrigin(c.path, c.text, c.head, c.lidar), tracker_t0_s=0.0,
                             point_rate_hz=c.lidar.point_rate_hz,
                             sky=None if sky_table is None else sky_table()).to_dict()

    def _open_recording(self) -> None:
        """The recording file, its writer thread and the head's command journal, when the config asks
        for a recording.  Called after the links are open: a path that cannot be used closes them."""
        from foveatrack.errors import UserError
        from foveatrack.recording import RecordingExistsError, RecordingWriter

        c = self.cfg
        path = c.recording_path()
        if path is None:
            return
        r = c.recording
        try:
            c.check_recording_dir()
        except UserError:
            self.client.close()
            self.head.close()
            raise
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            writer = RecordingWriter(path, self._meta(), flush_every_frames=r.flush_every_frames,
                                     compression=r.compression, points_dtype=r.points_dtype, overwrite=r.overwrite,
                                     log_time="host",   # log times: the host's UTC; messages: the Livox clock
                                     writeback_step_bytes=int(r.writeback_mb * 1024 * 1024))
        except (OSError, UserError) as exc:
            self.client.close()
            self.head.close()
            if isinstance(exc, RecordingExistsError):
                raise UserError(c.recording_exists_message(path)) from None
            if isinstance(exc, UserError):
                raise
            raise UserError(f"{c.path} [recording] path: cannot create {path} ({exc.strerror or exc})") from None
        # the recording is written behind a queue: a journal of every frame for the head, written
        # before the frame is, says what a killed daemon's head got (CommandJournal); opened before the
        # writer's thread starts, so a journal that cannot be written leaves nothing running
        from foveatrack.live_devices import CommandJournal, journal_path

        try:
            journal = CommandJournal(journal_path(path))
        except UserError:
            writer.close()
            path.unlink(missing_ok=True)
            self.client.close()
            self.head.close()
            raise
        # a frame is ~6 jobs-worth of records in one job; commands/events are single jobs
        if self.heap_returns_freed:
            # the trim's counters exist before the writer's thread can add to them (a key added
            # there while the loop's thread walks the counters would change their size under it)
            self.counters.update({"heap_trims": 0, "heap_trim_ms": 0.0, "heap_trims_released": 0})
        self.recorder = RecordingThread(writer, r.queue_frames, self._segment_path, r.overwrite,
                                        self._trim_heap if self.heap_returns_freed else None)
        self.recording_path = path
        self.head.journal = journal
        self._segment_t0 = None         # the segment clock starts at the first frame (not while no lidar is seen)

    def _segment_path(self, k: int):
        """The file of the recording's segment ``k`` (the writer's thread moves to it)."""
        from foveatrack.recording.segments import segment_path

        return segment_path(self.recording_path, k)

    def _trim_heap(self) -> None:
        """On the recording's thread, once a segment's file is complete: the heap's free pages go
        back to the system (:func:`foveatrack.daemon.heap.trim_freed_memory`), counted in
        ``heap_trims`` with the time they took in ``heap_trim_ms``."""
        from foveatrack.daemon.heap import trim_freed_memory

        t = time.perf_counter()
        released = trim_freed_memory()
        self.counters["heap_trims"] += 1
        self.counters["heap_trim_ms"] += round((time.perf_counter() - t) * 1e3, 3)
        self.counters["heap_trims_released"] += bool(released)

    def _next_segment_if_due(self, now: float) -> None:
        """At a frame boundary, on the loop's thread: after ``[recording] segment_minutes``, the
        head's command journal moves to the next segment's (the commands of this frame on are
        journaled there) and the jobs submitted from now on go to its file
        (:class:`~foveatrack.daemon.support.RecordingThread`).  A journal that cannot be created
        keeps the current segment (logged; tried again a segment later)."""
        minutes = self.cfg.recording.segment_minutes
        if minutes is None or self.recording_path is None:
            return
        if self._segment_t0 is None:
            self._segment_t0 = now
        if now - self._segment_t0 < minutes * 60.0:
            return
        from foveatrack.errors import UserError
        from foveatrack.live_devices import CommandJournal, journal_path

        self._segment_t0 = now
        k = self.recorder.segment + 1
        path = self._segment_path(k)
        try:
            journal = CommandJournal(journal_path(path))
        except UserError as exc:
            self.log.event("recording_segment_failed", index=k, path=str(path), error=str(exc))
            return
        old, self.head.journal = self.head.journal, journal
        if old is not None:
            old.close()
            if old.error is not None:    # its loss stays said among the run's last lines (output_faults)
                self.__dict__.setdefault("_failed_journals", []).append(old)
        self.recorder.segment = k
        self.log.event("recording_segment", index=k, path=str(path))

    def _forget_unused_recording(self) -> None:
        """A start that failed after the recording was created (a live port in use) removes it and
        its command journal: nothing was written to either yet (the loop and the head's first STOP
        come later, in :meth:`run`), and an empty ``daemon-*.mcap`` per failed start only misleads."""
        if self.recording_path is None:
            return
        from foveatrack.live_devices import journal_path

        for p in (self.recording_path, journal_path(self.recording_path)):
            p.unlink(missing_ok=True)
        self.recording_path = None

    def _open_live(self) -> None:
        """The live view: a second sink of the recording's channels (a writer without a file when
        nothing is recorded), fed by the same recording thread."""
        from foveatrack.recording import RecordingWriter
        from foveatrack.recording.live import LiveServer

        if self.recorder is None:
            self.recorder = RecordingThread(RecordingWriter(None, self._meta(), log_time="host"),
                                            self.cfg.recording.queue_frames)
        try:
            self.live = LiveServer(self.recorder.writer.context, self.live_port, allowed_origins=self.live_origins)
        except Exception:
            self.recorder.close()
            self.client.close()
            self.head.close()
            raise
        self.log.event("live_view", url=self.live.url)
        # on stderr too, as simulate and replay say it: the JSON log is for machines
        print(f"live view on {self.live.url} (Foxglove: Open connection -> Foxglove WebSocket)",
              file=sys.stderr, flush=True)

    def output_faults(self) -> list[tuple[str, str]]:
        """What the run could not write, as ``(output, sentence)``: the recording (its writer's thread
        stopped at the error; its frames before are kept), each command journal (``"journal PATH"``:
        a recording in segments has one per segment, and one closed at a rollover stays said), the
        log.  A full disk
        stops none of them from tracking: each is said once when it happens (:meth:`_watch_outputs`)
        and again among the run's last lines."""
        from foveatrack.errors import UserError

        out = []
        err = None if self.recorder is None else self.recorder.error
        if err is not None:
            what = str(err) if isinstance(err, UserError) else (
                f"the recording {self.recording_path} stopped: {type(err).__name__}: {err}")
            out.append(("recording", f"{what}; tracking goes on"))
        # the journals of earlier segments that failed (closed at a rollover), then the current one:
        # each said by its path (a segment's new journal failing later is another fault)
        journal = getattr(self.head, "journal", None) if getattr(self, "head", None) is not None else None
        for j in [*self.__dict__.get("_failed_journals", ()), journal]:
            if j is not None and j.error is not None:
                out.append((f"journal {j.path}",
                            f"command journal {j.path}: cannot write ({_why(j.error)}): the head still gets every "
                            f"command, but from here on none is journaled ({j.lost} so far), so 'foveatrack "
                            "recover' cannot put back what a killed daemon's recording lacks"))
        if self.log.error is not None:
            out.append(("log", f"--log {self.log.path}: cannot write ({_why(self.log.error)}); "
                               f"from here on no event is logged ({self.log.lost} so far), the run goes on"))
        return out

    def _watch_outputs(self) -> None:
        """On the tick: a recording, journal or log that just failed is said at once on stderr (and
        in the log, while it can be written): a full disk otherwise stopped the recording in silence,
        seen only as a growing drop count."""
        said = self.__dict__.setdefault("_faults_said", set())
        for key, text in self.output_faults():
            if key not in said:     # "recording", "log", "journal PATH": each segment's journal its own
                said.add(key)
                self.status.note(f"foveatrack daemon: WARNING: {text}")
                output, _, path = key.partition(" ")
                self.log.event("output_failed", output=output, error=text, **({"path": path} if path else {}))

    def _record(self, fn, *args):
        if self.recorder is not None:
            self.recorder.submit(fn, *args)
