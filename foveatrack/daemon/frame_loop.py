"""The daemon's frame loop: lidar batches -> frames -> the one frame step -> the head, with the
sensor clock's epochs and the daemon's own commands (one role of :class:`foveatrack.daemon.runtime.Daemon`).

Each frame is processed as soon as it is complete (the first point at or after its end has
arrived), so the loop is paced by the lidar's clock.  If more than ``max_frame_backlog`` frames are
waiting (the loop fell behind, or the lidar came back after a gap) the oldest are skipped and
counted (``frames_skipped``): commands for stale frames would be wrong.  A new sensor clock (the
stream re-anchored: foveatrack.sensor_time) drops the old clock's frames and carries the tracker
over (:meth:`FrameLoop._new_clock`).  See :mod:`foveatrack.daemon.runtime` for time and figures.
"""

from __future__ import annotations

import math
import queue
import time

import numpy as np

from foveatrack.control import STOP, HeadCommand
from foveatrack.daemon.record_queue import _job_event, _job_frame
from foveatrack.errors import UserError
from foveatrack.frames import Frame, strip_no_return
from foveatrack.frame_step import StepRecord
from foveatrack.gate import LINK_DOWN
from foveatrack.recording.records import CommandRecord, ns, write_record
from foveatrack.reconstruction import rotation_matrix
from foveatrack.turn_witness import TurnMismatch


class _HeadSink:
    """The daemon's command sink: Pelco bytes through :class:`~foveatrack.live_devices.HeadLink` to the
    serial port; keeps the bytes and the host time of the last write for the command's record."""

    def __init__(self, daemon):
        self.daemon = daemon
        self.raw: bytes = b""
        self.t_written = math.nan

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        d = self.daemon
        self.raw, ok = d.head.send(cmd, source, send_t_s)   # the journal keeps the send time
        self.t_written = time.monotonic()
        d.counters["commands_written" if ok else "commands_failed"] += 1
        return ok

    def send_goal(self, axis: str, goal_deg: float, source: str) -> bool:
        """An absolute move (Pelco set-pan 0x4B / set-tilt 0x4D) the gate let through (the homing's)."""
        from gimbal.pelco import encode_set_pan, encode_set_tilt

        d = self.daemon
        h = d.cfg.head
        if axis == "pan":
            raw = encode_set_pan(h.address, goal_deg, h.protocol)
        else:
            raw = encode_set_tilt(h.address, goal_deg, h.protocol, getattr(d.head.client, "tilt_zero", "zenith"))
        self.raw = raw
        ok = d.head.send_raw(raw, source)
        self.t_written = time.monotonic()
        return ok


class FrameLoop:
    """The frames' part of the daemon (a mixin of ``Daemon``; ``pending``: the frames complete and
    not yet processed, with the host time their last batch arrived)."""

    def _take_batches(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for the receiver's batches, take every one waiting and slice them
        into frames (``pending``); beyond ``max_frame_backlog`` the oldest frames are skipped."""
        try:
            item = self.q.get(timeout=timeout_s)
            items = [item]
            while True:
                try:
                    items.append(self.q.get_nowait())
                except queue.Empty:
                    break
        except queue.Empty:
            items = []
        pending = self.pending
        for t_rx, xyz, t_ns, refl, epoch in items:
            if epoch != self.epoch:
                # the sensor clock restarted or jumped (re-anchored by the stream): frames of
                # the old clock are dropped, slicing and the dead reckoning's clock start again
                self.counters["frames_skipped"] += len(pending)
                pending.clear()
                self._new_clock(epoch, int(t_ns[0]) * 1e-9)
            for fr in self.slicer.push(xyz, t_ns, refl):
                pending.append((fr, t_rx))
        while len(pending) > self.cfg.loop.max_frame_backlog:
            pending.popleft()
            self.counters["frames_skipped"] += 1

    def _process_pending(self) -> None:
        while self.pending:
            fr, t_rx = self.pending.popleft()
            self._process(fr, t_rx)
            self.frame_times.append(time.monotonic())

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

    def _process(self, frame: Frame, t_arrival: float) -> None:
        self._next_segment_if_due(t_arrival)      # before any of this frame's commands and records
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
            self.lat_ms.add(lat)
        self.proc_ms.add(proc * 1e3)
        self.counters["frames"] += 1
        self.counters["frames_detected"] += out.detection is not None
        if out.detection is not None:
            self.bearings.saw(frame.t_end_s, out.world_xyz)
        self.last_out, self.last_pts = out, frame.n_points
        self.last_frame_end_s = frame.t_end_s
        self._record(_job_frame, fid, frame, out, rec, proc * 1e3, lat, imu)
