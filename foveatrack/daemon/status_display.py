"""What the daemon shows while it runs: the status line on a terminal and a ``progress`` event in the
log every second (a killed daemon's log still says how far it got).  One role of
:class:`foveatrack.daemon.runtime.Daemon`."""

from __future__ import annotations

from foveatrack.daemon.support import format_status

PROGRESS_PERIOD_S = 1.0
#: no frame for this long [s]: the status line shows no rate, points or error (not the last frame's)
STALE_STATUS_S = 1.0
# a "progress" log event (frames processed, ...) every PROGRESS_PERIOD_S


class StatusDisplay:
    """The display's part of the daemon (a mixin of ``Daemon``)."""

    def _log_progress(self) -> None:
        """How far the run got, in the log."""
        self.log.event("progress", frames=self.counters["frames"],
                       frames_detected=self.counters["frames_detected"],
                       frames_stale=self.counters["frames_stale"], sensor_t_s=self.last_frame_end_s,
                       commands_written=self.counters["commands_written"], drops=self.drops(),
                       lidar_points=self.rx.points_in)

    def _show_status(self, frame_times, watchdog, now: float | None = None) -> None:
        rate = 0.0
        if len(frame_times) >= 2 and frame_times[-1] > frame_times[0]:
            rate = (len(frame_times) - 1) / (frame_times[-1] - frame_times[0])
        out, pts = self.last_out, getattr(self, "last_pts", 0)
        if now is not None and frame_times and now - frame_times[-1] > STALE_STATUS_S:
            # no frame for a while (the lidar went silent): the last frame's rate, points and error are
            # not the present's (a user watched '10.0 Hz 3381 pts/frame' for 8 s after the lidar died)
            rate, pts, out = 0.0, 0, None
        state = "watchdog" if watchdog else ("no lidar" if out is None else out.state.value)
        if self.pose_state is not None:
            state = {"unknown": "pose unknown", "refused": "head refused"}.get(self.pose_state, "homing")
        elif self.head.refused:
            state = "head refused" 
        self.status.show(format_status(rate, pts, state,
                                       None if out is None else out.error_pan_deg,
                                       None if out is None else out.error_tilt_deg,
                                       self.lat_ms.last, self.drops(), self.head.connected,
                                       ", ".join(self.status_notes())))

    def status_notes(self) -> list[str]:
        """What the status line says besides the figures: the multi-object tracker's tracks (confirmed,
        of them labelled drone, the one the fovea serves, the pinned one), the lidar unit's problems, an
        uncalibrated head, a head device refused, lost lidar packets."""
        notes = []
        sky = getattr(self.tracker, "last_output", None)
        if sky is not None:
            conf = [v for v in sky.sky.tracks if v.confirmed]
            notes.append(f"tracks {len(conf)} ({sum(v.label == 'drone' for v in conf)} drone)"
                         + (f", fovea on {sky.next_target}" if sky.next_target is not None else "")
                         + (f", pinned {sky.pinned}" if sky.pinned is not None else ""))
        if getattr(self, "rx", None) is not None and self.rx.unit_note:
            notes.append(self.rx.unit_note)
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
