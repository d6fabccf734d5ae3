"""The real-time daemon: Livox lidar in, Pelco-D out, at the tracker's 10 Hz (paper Appendix D).

Threads and queues::

    receiver thread:  LivoxClient.poll -> (host time, points) -> bounded batch queue (drops counted)
    control loop:     batch queue -> FrameSlicer -> Tracker.process -> CommandGate -> HeadClient
                      (the main thread; a monotonic 10 Hz tick runs the watchdog and the status)
    recording thread: bounded job queue -> RecordingWriter (drops counted; never blocks the loop)

Each frame is processed as soon as it is complete (the first point at or after its end has
arrived), so the loop is paced by the lidar's clock; the monotonic tick keeps the watchdog and the
status line going when the lidar is silent.  If more than ``max_frame_backlog`` frames are waiting
(the loop fell behind, or the lidar came back after a gap) the oldest are skipped and counted
(``frames_skipped``): commands for stale frames would be wrong.

Time.  Point times are the sensor's clock (``t_ns``; no sync: ns since power-on).  Host time of a
sensor time is ``t_sensor + offset`` with ``offset = min over packets (host receive time - time of
the packet's last point)``: the offset at the first packet, lowered whenever a packet arrives
sooner than it predicts.  So the mapping is exact up to the smallest transit delay seen (on loopback
well under 1 ms; on Ethernet ~0.1 ms) and drifts with the sensor's clock error (ppm: 0.1 ms per
100 s at 1 ppm); for long runs sync the lidar (PTP) or restart.  The tracker runs in sensor time:
``send_t_s`` handed to :meth:`Tracker.process` is the host's "now" mapped to sensor time plus the
expected compute time (the median of the last nine), and no earlier than the previous command has
left the serial line (one Pelco frame time later).

Figures recorded per frame (``/metrics``): ``processing_ms`` = from the arrival of the batch that
completed the frame to the command bytes written (slicing, detection, control, encoding, write);
``latency_ms`` = end to end, host time of the frame's last point -> command bytes written.

Safety: a command leaves only through :class:`foveatrack.gate.CommandGate` (speed bytes, turbo, tilt
stops against the reconstructed tilt, stale frames, failed writes; the simulator and replay run the
same gate); the watchdog sends STOP when no lidar packet has
arrived for ``watchdog_s`` (and repeats it every second while silent); SIGINT/SIGTERM stop the
head, close the recording and return 0.  The serial link reconnects by itself
(:class:`gimbal.client.HeadClient`).
"""

from __future__ import annotations

import math
import queue
import signal
import sys
import threading
import time
from collections import Counter, deque
from dataclasses import asdict

import numpy as np

from foveatrack.control import STOP, HeadCommand
from foveatrack.daemon.homing_plan import Bearings, HomingConfirm, HomingPlan, plan_homing
from foveatrack.daemon.pose_guard import PoseGuard
from foveatrack.daemon.receiver import LidarReceiver
from foveatrack.device_config import DaemonConfig
from foveatrack.daemon.support import JsonLog, RecordingThread, StatusLine, format_status
from foveatrack.frames import Frame, FrameSlicer, strip_no_return
from foveatrack.frame_step import FrameStep, StepRecord
from foveatrack.gate import LINK_DOWN, CommandGate
from foveatrack.errors import UserError
from foveatrack.gyro_attitude import ImuFeed
from foveatrack.live_devices import open_devices
from foveatrack.recording.format import DAEMON_EVENTS
from foveatrack.recording.records import CommandRecord, ns, write_record, write_tracker_frame
from foveatrack.reconstruction import rotation_matrix
from foveatrack.tracker import Tracker
from foveatrack.turn_witness import MoveWitness, TurnMismatch

FORMAT_SOURCE = "daemon"
ABS_SET_QUIET_S = 0.3     # line quiet before a Pelco absolute set (the PTS family needs 0.2 s)
PROGRESS_PERIOD_S = 1.0
# a "progress" log event (frames processed, ...) every PROGRESS_PERIOD_S


# ----------------------------------------------------------------------------------------- record jobs
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


class _HeadSink:
    """The daemon's command sink: Pelco bytes through :class:`~foveatrack.live_devices.HeadLink` to the
    serial port; keeps the bytes and the host time of the last write for the command's record."""

    def __init__(self, daemon: "Daemon"):
        self.daemon = daemon
        self.raw: bytes = b""
        self.t_written = math.nan

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        d = self.daemon
        self.raw, ok = d.head.send(cmd, source, send_t_s)   # the journal keeps the send time
        self.t_written = time.monotonic()
        d.counters["commands_written" if ok else "commands_failed"] += 1
        return ok


class Daemon:
    """One run of the daemon (see module docstring).  ``run()`` returns the exit status (0).

    config : DaemonConfig; log_path : JSON-lines log (overrides ``[daemon] log``);
    status : show the status line (None = if stderr is a TTY); duration_s : stop after this long
    """

    def __init__(self, config: DaemonConfig, log_path: str | None = None, status: bool | None = None,
                 duration_s: float | None = None, install_signals: bool = True, live_port: int | None = None,
                 live_origins=()):
        self.cfg = config
        self.live_port = live_port      # serve the recording's channels on ws://127.0.0.1:PORT
        self.live_origins = tuple(live_origins)    # origins of web pages also let read it (--live-origin)
        self.live = None
        self.log = JsonLog(log_path or config.loop.log)
        self.status = StatusLine(enabled=status)
        self.duration_s = duration_s
        self.install_signals = install_signals
        self.stop_ev = threading.Event()
        h = config.head
        self.limits = h.limits
        self.gate = CommandGate(self.limits)
        self.table = config.speed_table()
        self.sink = _HeadSink(self)
        # The one frame step: tracker -> gate -> serial port; a failed write leaves the head on its
        # last command and the gate tells the dead reckoning (seen without it: ~9 deg of pan while a
        # head was unplugged).
        self.step = FrameStep(Tracker(config.tracker, self.table), self.gate, self.sink)
        # attitude = "gyro": the lidar's IMU samples, held until the frame they precede
        self.imu_feed = ImuFeed() if config.tracker.attitude == "gyro" else None
        # ... and the same gyro witnesses every move of the head against its command (a slipping gear,
        # a wrong speed table, another head on the port stop the run: foveatrack.turn_witness)
        self.witness = MoveWitness(self.table) if self.imu_feed is not None else None
        self.slicer = FrameSlicer(config.tracker.rate_hz)
        self.counters: Counter = Counter(frames_stale=0)
        self.proc_ms: list[float] = []
        self.lat_ms: list[float] = []
        self.frame_id = 0
        self.last_out = None
        self._compute_s: deque = deque([0.002], maxlen=9)   # recent compute times [s]
        self._last_send_t = -math.inf
        self.recorder: RecordingThread | None = None
        self.recording_path = None
        self.epoch = 0                      # the sensor clock's epoch (foveatrack.sensor_time)
        self.pose_state: str | None = None  # None (known), "unknown", "homing" (after a head reconnect)
        self._home_steps: list = []         # (host time, step) of the homing under way
        self.last_frame_end_s: float | None = None
        self.pose_guard = PoseGuard(config)   # the head's pose against the background ([pose_check])
        self.bearings = Bearings()          # where the target was last seen: a homing goes there first
        self._homing: HomingPlan | None = None
        self._homing_confirm: HomingConfirm | None = None
        self._homing_t0: float | None = None

    @property
    def tracker(self) -> Tracker:
        return self.step.controller

    # -------------------------------------------------------------------------------- setup
    def _meta(self) -> dict:
        c = self.cfg
        return {"source": FORMAT_SOURCE, "config_path": c.path, "config_text": c.text,
                "tracker_table": dict(c.tracker_table), "tracker_overrides": c.tracker_overrides,
                "tracker_t0_s": 0.0, "speed_table": self.table.to_dict(), "rate_hz": c.tracker.rate_hz,
                "tracker_effective": c.tracker.effective(),   # the configuration that runs, every setting
                "point_rate_hz": c.lidar.point_rate_hz, "head": asdict(c.head), "lidar": asdict(c.lidar),
                "limits": asdict(self.limits)}

    def _open(self):
        from foveatrack.errors import UserError
        from foveatrack.recording import RecordingExistsError, RecordingWriter

        # Links first, the recording last: a port that cannot be used fails the start before a
        # recording file exists (an empty one was left behind for every failed start).
        c = self.cfg
        self.head, self.client = open_devices(c)
        # the bound ports (config 0 = any), kept: the client's sockets are closed at shutdown
        self.host_ports = {"cmd": self.client.cmd_port, "data": self.client.data_port,
                           "broadcast": self.client.broadcast_port}
        path = c.recording_path()
        if path is not None:
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
                                         log_time="host")   # log times: the host's UTC; messages: the Livox clock
            except (OSError, UserError) as exc:
                self.client.close()
                self.head.close()
                if isinstance(exc, RecordingExistsError):
                    why = ("two starts within the same second gave the same '{time}' name; start again a "
                           "second later" if "{time}" in r.path else
                           "put '{time}' in it for a new file per start (e.g. path = \"runs/{time}.mcap\")")
                    raise UserError(f"{c.path} [recording] path: {path} already exists and is never overwritten "
                                    f"unless asked; {why}, or set overwrite = true in [recording] to replace it"
                                    ) from None
                if isinstance(exc, UserError):
                    raise
                raise UserError(f"{c.path} [recording] path: cannot create {path} ({exc.strerror or exc})") from None
            # a frame is ~6 jobs-worth of records in one job; commands/events are single jobs
            self.recorder = RecordingThread(writer, r.queue_frames)
            self.recording_path = path
            # the recording is written behind a queue: a journal of every frame for the head, written
            # before the frame is, says what a killed daemon's head got (CommandJournal)
            from foveatrack.live_devices import CommandJournal

            self.head.journal = CommandJournal(path.with_name(path.name + ".commands.jsonl"))
        if self.live_port is not None:
            try:
                self._open_live()
            except Exception:
                self._forget_unused_recording()
                raise
        self.q: queue.Queue = queue.Queue(maxsize=c.loop.batch_queue)
        self.rx = LidarReceiver(self.client, self.q, self.stop_ev)
        self.rx.want_imu = self.imu_feed is not None
        # IMU packets are held only for a tracker that takes its attitude from them (issue 26: every
        # packet of a Horizon was kept otherwise, ~1 MB/min)
        self.client.decoder.keep_imu = self.rx.want_imu

    def _forget_unused_recording(self) -> None:
        """A start that failed after the recording was created (a live port in use) removes it and
        its command journal: nothing was written to either yet (the loop and the head's first STOP
        come later, in :meth:`run`), and an empty ``daemon-*.mcap`` per failed start only misleads."""
        if self.recording_path is None:
            return
        for p in (self.recording_path, self.recording_path.with_name(self.recording_path.name + ".commands.jsonl")):
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

    # -------------------------------------------------------------------------------- helpers
    def sensor_now_s(self, mono: float | None = None) -> float | None:
        off = self.rx.offset_s
        if off is None:
            return None
        return (time.monotonic() if mono is None else mono) - off

    def _send_time(self, t_s: float) -> float:
        """``t_s`` [sensor s], but not before the previous command has left the wire.

        The serial line sends one Pelco frame at a time (7.29 ms at 9600 baud): commands written
        back to back (a backlog burst, a STOP right after a frame) reach the head one frame time
        apart, and the dead reckoning must see them so, in time order.
        """
        t_s = max(t_s, self._last_send_t + self.cfg.head.frame_time_s)
        self._last_send_t = t_s
        return t_s

    def _command_record(self, rec: StepRecord, source: str, fid=None) -> CommandRecord:
        """The recording's record of a command the step wrote (the tracker's when the gate changed it)."""
        cmd, t = rec.command, rec.proposed
        return CommandRecord(ns(rec.send_t_s), self.sink.raw, cmd.pan_dir, cmd.pan_byte, cmd.tilt_dir, cmd.tilt_byte,
                             frame_id=fid, source=source, send_t_s=float(rec.send_t_s), written=rec.reached_head,
                             host_written_s=self.sink.t_written, limited=rec.limited,
                             tracker_command=None if rec.output is None else (t.pan_dir, t.pan_byte, t.tilt_dir,
                                                                              t.tilt_byte))

    def _send_own(self, cmd: HeadCommand, source: str, send_t_s: float) -> None:
        """A command of the daemon's own (watchdog, shutdown, a new sensor clock), through the step,
        recorded."""
        rec = self.step.own_command(send_t_s, cmd, source)
        if self.witness is not None:
            self.witness.command(send_t_s, rec.head_command)
        self._record(write_record, self._command_record(rec, source))

    def _witness(self, frame: Frame, imu: tuple, step: StepRecord) -> None:
        """The frame's gyro samples, then the command the head runs from the send time, to the witness;
        a head that turned far from its commands ends the run (the head is stopped on the way out)."""
        t, g, accel = imu
        up = None
        if accel is None:     # no accelerometer readings: up from the dead reckoning's pose
            up = rotation_matrix(*self.tracker.recon.angles_at(frame.t_mid_s)[:2])[2]
        try:
            self.witness.samples(t, g, accel, up_guess=up)
        except TurnMismatch as exc:
            self.log.event("turn_mismatch", message=str(exc), frames=self.counters["frames"])
            raise UserError(f"{exc}; the head was stopped ([head] port {self.cfg.head.port!r})") from None
        self.witness.command(step.send_t_s, step.head_command)

    def _take_imu(self, t_end_s: float) -> tuple:
        """The gyro samples before this frame's end (of this clock only), which the step feeds to the
        tracker first; returns them, with the accelerometer's where the lidar sent it."""
        rx_imu = getattr(self.rx, "imu", None)
        while rx_imu:
            t_ns, gyro, epoch, *acc = rx_imu.popleft()
            if epoch == self.epoch:
                self.imu_feed.push(t_ns, gyro, acc[0] if acc else None)
        t, g, accel = self.imu_feed.release(t_end_s)
        self.counters["imu_samples"] = self.imu_feed.samples_fed
        self.counters["imu_samples_bad_time"] = self.imu_feed.bad_time
        if self.counters["frames"] == 20 and self.imu_feed.samples_in == 0:
            self.log.event("warning", message="[tracker] attitude = \"gyro\" but no IMU samples from the lidar "
                           "after 20 frames: the head's angles come from the commands alone (a Mid-40 has no "
                           "IMU; a Horizon, Avia or Tele-15 streams it at 200 Hz unless its IMU push is off)")
        return t, g, accel

    def _new_clock(self, epoch: int, t0_s: float) -> None:
        """Carry the tracker over to a new sensor clock starting at ``t0_s`` [s].

        The head is stopped (on the old clock, after the last command it got), the dead reckoning's
        pose once stopped becomes the new tracker's start pose at ``t0_s``: the tracker's state and
        its filters restart, the head's pose is kept."""
        old = self.tracker
        t_stop = self._send_time(max(self._last_send_t, self.last_frame_end_s or -math.inf))
        if not math.isfinite(t_stop):
            t_stop = 0.0
        if not old.last_command.is_stop:
            self._send_own(STOP, "clock_jump", t_stop)
        pan, tilt, _, _ = old.recon.angles_at(t_stop + 5.0)    # decelerated long since
        self._rebase_tracker(t0_s, pan, tilt)
        self.slicer.reset()
        self.bearings.clear()      # times of the old clock
        self.epoch = epoch
        self.counters["clock_epochs"] += 1
        self.log.event("tracker_rebased", reason="clock_jump", epoch=epoch, t0_s=t0_s, pan_deg=pan, tilt_deg=tilt,
                       frames=self.counters["frames"])
        self._record(_job_event, ns(t0_s), {"event": "tracker_rebased", "reason": "clock_jump", "epoch": epoch,
                                            "t0_s": t0_s, "pan_deg": pan, "tilt_deg": tilt})

    def _pose_unknown(self, now: float, why: str) -> None:
        """The head's link was lost (or a homing write failed): from now its pose is unknown (one that
        lost power comes back at its power-on pose; the head reports none).  No frame is tracked until
        :meth:`_reconnected` has done what ``[head] on_reconnect`` says."""
        h = self.cfg.head
        self.pose_state = "unknown"
        self._home_steps = []
        self.counters["head_pose_unknown"] += 1
        self.log.event("head_pose_unknown", why=why, on_reconnect=h.on_reconnect, frames=self.counters["frames"])
        self._record(_job_event, ns(self.sensor_now_s(now) or 0.0),
                     {"event": "head_pose_unknown", "why": why, "on_reconnect": h.on_reconnect})

    def _reconnected(self, now: float) -> None:
        """The link is back (its first frame was STOP): home the head if the config says so."""
        h = self.cfg.head
        self.head.stop()
        self._home_steps = []
        self._homing_t0 = now
        if h.on_reconnect == "home":
            from gimbal.pelco import encode_set_pan, encode_set_tilt

            # the target's last trusted bearing first, else home; the worst-case wait to that goal
            # (foveatrack.daemon.homing_plan); with a pose check, detections after its last "ok" are not trusted
            g = self.pose_guard
            trusted = None if g.check is None else (g.last_ok_t_s if g.last_ok_t_s is not None else -math.inf)
            plan = self._homing = plan_homing(h, self.bearings, self.sensor_now_s(now), trusted, g.identity_pending)
            self._homing_confirm = HomingConfirm() if g.check is not None else None
            self.log.event("head_homing_plan", **plan.as_event())
            pan, tilt = plan.pan_deg, plan.tilt_deg
            tz = getattr(self.head.client, "tilt_zero", "zenith")
            quiet = ABS_SET_QUIET_S
            # an absolute set is obeyed only after a quiet line: nothing else is written meanwhile
            self._home_steps = [(now + quiet, "pan", encode_set_pan(h.address, pan, h.protocol)),
                                (now + 2 * quiet, "tilt", encode_set_tilt(h.address, tilt, h.protocol, tz)),
                                (now + 2 * quiet + plan.wait_s, "done", None)]

    def _pose_tick(self, now: float) -> None:
        h = self.cfg.head
        if self.pose_state == "refused":    # another head behind the link: nothing is written to it
            return
        if not self.head.connected or h.on_reconnect == "stop":
            # STOP every second: while the link is down each try is the reopen, so the first frame a
            # reopened link carries is STOP; with "stop" it holds the head until the daemon restarts
            if now - getattr(self, "_last_unknown_stop", -math.inf) >= 1.0:
                self._last_unknown_stop = now
                self.head.stop()
            return
        confirmed = self.pose_state == "homing" and self._homing_confirm is not None and self._homing_confirm.confirmed
        while self._home_steps and (now >= self._home_steps[0][0] or (confirmed and self._home_steps[0][1] == "done")):
            _, step, raw = self._home_steps.pop(0)
            plan = self._homing
            if step in ("pan", "tilt"):
                if not self.head.send_raw(raw, "homing"):
                    self.log.event("head_homing_failed", step=step)
                    return self._pose_unknown(now, "homing_write_failed")   # again once the link is back
                self.pose_state = "homing"
                self.log.event("head_homing", axis=step, home_deg=[plan.pan_deg, plan.tilt_deg], goal=plan.goal,
                               worst_case_s=round(plan.worst_case_s, 3))
            else:
                t_s = self.sensor_now_s(now)
                pan, tilt = plan.pan_deg, plan.tilt_deg
                if confirmed:
                    self.log.event("head_homing_confirmed", by="pose_check",
                                   waited_s=round(now - (self._homing_t0 or now), 3), wait_s=plan.wait_s)
                self._rebase_tracker(t_s if t_s is not None else 0.0, pan, tilt)
                self.pose_state = None
                self.counters["head_homed"] += 1
                self.log.event("head_homed", pan_deg=pan, tilt_deg=tilt, t0_s=t_s, frames=self.counters["frames"])
                self._record(_job_event, ns(t_s or 0.0), {"event": "tracker_rebased", "reason": "head_homed",
                                                          "t0_s": t_s, "pan_deg": pan, "tilt_deg": tilt})

    def _rebase_tracker(self, t0_s: float, pan_deg: float, tilt_deg: float) -> None:
        """A fresh tracker whose dead reckoning starts at ``(pan_deg, tilt_deg)`` at sensor time ``t0_s``."""
        self.step.rebase(self.tracker.rebased(t0_s, pan_deg, tilt_deg))   # replay repeats it from the event
        if self.witness is not None:
            self.witness = MoveWitness(self.table)
        if self.imu_feed is not None:
            self.imu_feed.restart(t0_s)
        self._last_send_t = -math.inf
        self.pose_guard.rebased()

    def _record(self, fn, *args):
        if self.recorder is not None:
            self.recorder.submit(fn, *args)

    # -------------------------------------------------------------------------------- the frame
    def _process(self, frame: Frame, t_arrival: float) -> None:
        if self.pose_state is not None:
            # the head's pose is unknown (it reconnected): no bearing can be turned into a command; while
            # it is homing, the background may show it arrived (foveatrack.daemon.homing_plan)
            if self.pose_state == "homing" and self._homing_confirm is not None and self._home_steps:
                self._homing_confirm.feed(self.pose_guard.check.at_pose(
                    strip_no_return(frame).xyz, self._homing.pan_deg, self._homing.tilt_deg))
            self.counters["frames_pose_unknown"] += 1
            self.last_pts = frame.n_points
            return
        t_begin = time.monotonic()
        frame = strip_no_return(frame)
        if self.pose_guard.before_frame(self, frame, t_begin):   # mapped, or its background disagrees
            self.last_pts = frame.n_points
            return
        now_s = self.sensor_now_s()
        send_t = self._send_time((frame.t_end_s if now_s is None else max(now_s, frame.t_end_s))
                                 + float(np.median(self._compute_s)))
        imu = self._take_imu(frame.t_end_s) if self.imu_feed is not None else None
        fid = self.frame_id
        self.frame_id += 1
        # A frame this old steers nothing: its bearing is stale, and while the loop is catching up
        # (a stall, a start-up burst) the clock offset may still be settling, which would misplace
        # the command in the dead reckoning.  STOP is sent and recorded instead (replay repeats it).
        stale = now_s is not None and now_s - frame.t_end_s > self.cfg.loop.stale_frame_s
        reconnect_unknown = self.cfg.head.on_reconnect != "keep"
        was_up = self.head.connected
        # whatever a reopened link carries first is STOP: from then on the head's pose is unknown
        step = self.step(frame, send_t, imu=None if imu is None else [imu[:2]], stale=stale,
                         stop_why=(LINK_DOWN,) if not was_up and reconnect_unknown else ())
        out = step.output
        rec, t_written = self._command_record(step, "tracker", fid), self.sink.t_written
        if self.witness is not None:
            self._witness(frame, imu, step)
        self.counters["frames_stale"] += stale
        if step.limited:
            self.counters["commands_limited"] += 1
        if was_up and not self.head.connected and reconnect_unknown and self.pose_state is None:
            self._pose_unknown(t_written, "link_lost")
        proc = t_written - t_arrival
        # The send-time prediction learns the compute time only, robustly (median of the last 9): a
        # frame that waited in a backlog, or one slow first frame, would otherwise push the later
        # commands' dead-reckoned times ahead of their real ones (seen: 0.2 s, 0.5 deg of tilt).
        self._compute_s.append(t_written - t_begin)
        lat = None
        if self.rx.offset_s is not None:
            t_last = frame.t_ns[-1] * 1e-9 if frame.n_points else frame.t_end_s
            lat = (t_written - (t_last + self.rx.offset_s)) * 1e3
            self.lat_ms.append(lat)
        self.proc_ms.append(proc * 1e3)
        self.counters["frames"] += 1
        self.counters["frames_detected"] += out.detection is not None
        if out.detection is not None:
            self.bearings.saw(frame.t_end_s, out.world_xyz)
        self.last_out, self.last_pts = out, frame.n_points
        self.last_frame_end_s = frame.t_end_s
        self._record(_job_frame, fid, frame, out, rec, proc * 1e3, lat, imu)

    # -------------------------------------------------------------------------------- the loop
    def run(self) -> int:
        from foveatrack.detection import compile_all

        compile_all()   # before data flows: a first-call compile would stall the first frame
        self.pose_guard.compile()
        self._open()
        old = {}
        if self.install_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, lambda *_: self.stop_ev.set())
        c = self.cfg
        self.log.event("start", config=c.path, recording=str(self.recording_path) if self.recording_path else None,
                       lidar=asdict(c.lidar), head_port=c.head.port, head_open=self.head.connected,
                       rate_hz=c.tracker.rate_hz,
                       host_ports=self.host_ports)
        for w in c.warnings():
            self.log.event("warning", message=w)
        self.head.stop()
        if self.recording_path is not None:   # a killed run's recording here: completed from its journal
            from foveatrack.daemon.recover import recover_directory

            recover_directory(self.recording_path.parent, self.log.event, exclude=[self.recording_path])
        self.rx.start()
        period = 1.0 / c.tracker.rate_hz
        t_start = time.monotonic()
        next_tick = t_start + period
        next_status = t_start
        next_progress = t_start + PROGRESS_PERIOD_S
        watchdog_tripped = False
        last_watchdog_stop = -1e9
        head_up = self.head.connected
        last_refusals, last_refusal_log = 0, -math.inf
        last_locked, last_lock_log = 0, -math.inf
        lidar_up = False
        frame_times = deque(maxlen=50)
        pending: deque = deque()
        try:
            while not self.stop_ev.is_set():
                if self.duration_s is not None and time.monotonic() - t_start >= self.duration_s:
                    break
                if self.rx.error is not None:
                    raise self.rx.error
                try:
                    item = self.q.get(timeout=max(0.0, next_tick - time.monotonic()))
                    items = [item]
                    while True:
                        try:
                            items.append(self.q.get_nowait())
                        except queue.Empty:
                            break
                except queue.Empty:
                    items = []
                for t_rx, xyz, t_ns, refl, epoch in items:
                    if epoch != self.epoch:
                        # the sensor clock restarted or jumped (re-anchored by the stream): frames of
                        # the old clock are dropped, slicing and the dead reckoning's clock start again
                        self.counters["frames_skipped"] += len(pending)
                        pending.clear()
                        self._new_clock(epoch, int(t_ns[0]) * 1e-9)
                    for fr in self.slicer.push(xyz, t_ns, refl):
                        pending.append((fr, t_rx))
                while len(pending) > c.loop.max_frame_backlog:
                    pending.popleft()
                    self.counters["frames_skipped"] += 1
                while pending:
                    fr, t_rx = pending.popleft()
                    self._process(fr, t_rx)
                    frame_times.append(time.monotonic())
                now = time.monotonic()
                if now < next_tick:
                    continue
                # ---- the 10 Hz tick: watchdog, link events, status
                next_tick += period
                if next_tick < now:
                    self.counters["ticks_late"] += 1
                    next_tick = now + period
                while not self.rx.unit_events.empty():   # the unit's state, status, refusals, link losses
                    ev = dict(self.rx.unit_events.get_nowait())
                    self.log.event("lidar_" + ev.pop("event"), **ev)
                last_pkt = self.rx.last_packet_mono
                silent = last_pkt is None or now - last_pkt > c.loop.watchdog_s
                if last_pkt is not None and not lidar_up:
                    lidar_up = True
                    self.log.event("lidar_data", offset_s=self.rx.offset_s, device=self.client.device_broadcast_code)
                if silent and lidar_up and not watchdog_tripped:
                    watchdog_tripped = True
                    self.counters["watchdog_trips"] += 1
                    self.log.event("watchdog_stop", silent_s=now - last_pkt)
                if (silent and (watchdog_tripped or last_pkt is None) and now - last_watchdog_stop >= 1.0
                        and self.pose_state is None):
                    last_watchdog_stop = now
                    t_s = self.sensor_now_s(now)
                    if t_s is not None and watchdog_tripped:
                        self._send_own(STOP, "watchdog", self._send_time(t_s))
                    else:
                        self.head.stop()
                if not silent and watchdog_tripped:
                    watchdog_tripped = False
                    self.log.event("lidar_resumed")
                locked = getattr(self.head.stats, "open_locked", 0)
                if locked != last_locked:
                    # another process took the head's port while its link was down: never written to
                    if last_locked == 0 or now - last_lock_log >= 10.0:
                        self.log.event("head_locked", port=c.head.port, reason=self.head.client.last_open_error,
                                       attempts=locked)
                        last_lock_log = now
                    last_locked = locked
                refusals = self.head.stats.open_refusals
                if refusals != last_refusals:
                    # another device holds the head's path: never written to (foveatrack.serial_identity)
                    if last_refusals == 0 or now - last_refusal_log >= 10.0:
                        self.log.event("head_refused", reason=self.head.client.last_open_error, refusals=refusals)
                        last_refusal_log = now
                    last_refusals = refusals
                if self.head.connected != head_up:
                    head_up = self.head.connected
                    self.counters["head_link_up" if head_up else "head_link_down"] += 1
                    self.log.event("head_connected" if head_up else "head_disconnected", stats=asdict(self.head.stats))
                    if c.head.on_reconnect != "keep" and self.pose_state != "refused":
                        if not head_up and self.pose_state is None:
                            self._pose_unknown(now, "link_lost")
                        elif head_up:
                            if self.pose_state is None:     # lost and back between two ticks
                                self._pose_unknown(now, "link_lost")
                            self.pose_guard.link_back(self)   # is it our head? (pose_guard: identity)
                            self._reconnected(time.monotonic())   # (the query took a while: the homing's quiet line counts from now)
                if self.pose_state is not None:
                    self._pose_tick(now)
                if now >= next_progress:
                    # how far the run got, in the log every second: a killed daemon's log still says so
                    next_progress = now + PROGRESS_PERIOD_S
                    self.log.event("progress", frames=self.counters["frames"],
                                   frames_detected=self.counters["frames_detected"],
                                   frames_stale=self.counters["frames_stale"], sensor_t_s=self.last_frame_end_s,
                                   commands_written=self.counters["commands_written"], drops=self.drops(),
                                   lidar_points=self.rx.points_in)
                if now >= next_status:
                    next_status = now + c.loop.status_period_s
                    self._show_status(frame_times, watchdog_tripped)
        finally:
            self._shutdown(old)
        return 0

    def stats(self) -> dict:
        """All counters in one flat dict (loop, lidar, head, recording)."""
        d = dict(self.counters)
        rx = getattr(self, "rx", None)
        if rx is not None:
            d.update({f"lidar_{k}": v for k, v in rx.counters.items()})
            d["queue_dropped_batches"] = rx.dropped_batches
            d["queue_dropped_points"] = rx.dropped_points
            if rx.first_t_ns is not None and rate_known(self):
                span = (rx.last_t_ns - rx.first_t_ns + rx.span_done_ns) * 1e-9
                expected = span * self.client.decoder.point_rate_hz
                if expected > 0:
                    d["lidar_points_missing_pct"] = round(max(0.0, 100.0 * (1 - rx.points_in / expected)), 3)
                d["lidar_lost_pct"] = round(self.lost_pct() or 0.0, 3)
        if getattr(self, "head", None) is not None:
            d.update({f"head_{k}": v for k, v in asdict(self.head.stats).items()})
        d["slicer_late_points"] = self.slicer.late_points
        if self.recorder is not None:
            d["recording_dropped"] = self.recorder.dropped
            d["recording_jobs"] = self.recorder.written
        for name, xs in (("processing_ms", self.proc_ms), ("latency_ms", self.lat_ms)):
            if xs:
                a = np.asarray(xs)
                d[f"{name}_p50"] = round(float(np.percentile(a, 50)), 3)
                d[f"{name}_p99"] = round(float(np.percentile(a, 99)), 3)
                d[f"{name}_max"] = round(float(a.max()), 3)
        return d

    def problems(self) -> list[str]:
        """What went wrong in the run, in words for the final stderr lines (empty when nothing did).

        A run that received nothing from the lidar otherwise ended on "0 frames" with the reason
        only in the log's counters (e.g. a mistyped ``sensor_ip``: every datagram was dropped as
        ``lidar_foreign_source``)."""
        out = []
        rx = getattr(self, "rx", None)
        if rx is not None and rx.last_packet_mono is None:
            L = self.cfg.lidar
            hp = self.host_ports
            ports = f"data port {hp['data']}, command port {hp['cmd']}" + (
                f", broadcasts on port {hp['broadcast']}" if hp["broadcast"] is not None else "")
            msg = f"no lidar data arrived from [lidar] sensor_ip {L.sensor_ip} ({ports})"
            foreign = sorted(self.client.foreign_addresses)
            if foreign:
                msg += (f"; {rx.counters.get('foreign_source', 0)} datagrams from {', '.join(foreign)} were dropped: "
                        "is sensor_ip the lidar's address?")
            else:
                msg += (f"; nothing arrived at all: is the lidar on and on this network, and host_ip {L.host_ip} "
                        "this host's address on it?")
            out.append(msg)
        failed = self.counters.get("commands_failed", 0)
        if failed:
            total = failed + self.counters.get("commands_written", 0)
            out.append(f"{failed} of {total} head commands were not written to [head] port {self.cfg.head.port!r} "
                       "(see head_* counters in the log)")
        return out

    @property
    def no_lidar_data(self) -> bool:
        """True when the run never received a lidar packet (the CLI exits non-zero)."""
        rx = getattr(self, "rx", None)
        return rx is not None and rx.last_packet_mono is None

    def drops(self) -> int:
        rx = self.rx
        c = rx.counters
        return (c.get("dropped_total", 0) + rx.dropped_batches + self.counters["frames_skipped"]
                + (self.recorder.dropped if self.recorder else 0))

    def _show_status(self, frame_times, watchdog) -> None:
        rate = 0.0
        if len(frame_times) >= 2 and frame_times[-1] > frame_times[0]:
            rate = (len(frame_times) - 1) / (frame_times[-1] - frame_times[0])
        out = self.last_out
        state = "watchdog" if watchdog else ("no lidar" if out is None else out.state.value)
        if self.pose_state is not None:
            state = {"unknown": "pose unknown", "refused": "head refused"}.get(self.pose_state, "homing")
        elif self.head.refused:
            state = "head refused" 
        self.status.show(format_status(rate, getattr(self, "last_pts", 0), state,
                                       None if out is None else out.error_pan_deg,
                                       None if out is None else out.error_tilt_deg,
                                       self.lat_ms[-1] if self.lat_ms else None, self.drops(), self.head.connected,
                                       ", ".join(self.status_notes())))

    def status_notes(self) -> list[str]:
        """What the status line says besides the figures: the lidar unit's problems, an uncalibrated
        head, a head device refused, lost lidar packets."""
        notes = [self.rx.unit_note] if getattr(self, "rx", None) is not None and self.rx.unit_note else []
        if self.cfg.head.speed_table == "nominal":
            notes.append("head UNCALIBRATED (nominal speed table)")
        if self.pose_guard.warnings:
            notes.append("head speed table off (background)")
        if getattr(self, "head", None) is not None and self.head.refused:
            notes.append("head path holds another device: refused")
        lost = self.lost_pct()
        if lost:
            notes.append(f"lidar lost {self.rx.counters.get('lost_slots', 0)} points ({lost:.1f} %)")
        return notes

    def lost_pct(self) -> float | None:
        """Lidar points lost on the way [%]: the slots missing inside the stream (by time, as a
        sequence number) against the slots the stream spanned."""
        rx = getattr(self, "rx", None)
        if rx is None or rx.first_t_ns is None or not rate_known(self):
            return None
        span_slots = (rx.last_t_ns - rx.first_t_ns + rx.span_done_ns) * 1e-9 * self.client.decoder.point_rate_hz
        lost = rx.counters.get("lost_slots", 0)
        return 100.0 * lost / span_slots if span_slots > 0 and lost else None

    def _shutdown(self, old_handlers) -> None:
        self.stop_ev.set()
        t_s = self.sensor_now_s()
        if self.pose_state == "refused":     # another head behind the link: not even a STOP
            pass
        elif t_s is not None:
            t_s = self._send_time(t_s)
            self._send_own(STOP, "shutdown", t_s)
        else:
            self.head.stop()
        self.rx.join(2.0)
        self.client.close()
        self.head.close()
        stats = self.stats()
        if self.recorder is not None:
            self._record(_job_event, ns(t_s or 0.0), {"event": "stop", "stats": stats})
            self.recorder.close()
            stats["recording_dropped"] = self.recorder.dropped
            if self.recorder.error is not None:
                self.log.event("recording_error", error=repr(self.recorder.error))
        if self.live is not None:
            self.live.stop()
        self.status.done()
        self.log.event("stop", stats=stats, recording=str(self.recording_path) if self.recording_path else None)
        self.log.close()
        self.final_stats = stats
        for sig, h in old_handlers.items():
            signal.signal(sig, h)


def rate_known(d: Daemon) -> bool:
    return getattr(d, "client", None) is not None and d.client.decoder.point_rate_hz > 0
