"""The daemon's side of the pose check (:mod:`foveatrack.pose_check`, issue 26): when it runs, and what
the daemon does with each result.

* Start: the first ``map_frames`` frames (1 s at 10 Hz by default) build the background map at the
  start pose (``[head] pan0_deg/tilt0_deg``: the head was homed), the head held (STOP at start); they
  are not tracked (counted as ``frames_mapping``).
* Then before a frame is tracked (at most one check per ``period_s``; before, so that a frame whose
  background says the pose is wrong steers nothing, and a correction serves the frame it came from):

  - ``ok`` with an offset of at least ``min_correction_deg``: the dead reckoning is moved by
    ``correction_gain`` of it from the frame's start on (:meth:`foveatrack.tracker.Tracker.correct_pose`),
    counted in ``pose_corrections``, and recorded as a ``pose_corrected`` event, before the frame's
    records (replay repeats it after the previous frame: the same place);
  - ``mismatch``: ``pose_mismatch`` in the log and the recording, the frame is not tracked, then the
    head's pose is unknown
    (``head_pose_unknown`` with ``why = "pose_check"``): no frame is tracked, the head is stopped, and
    re-homed where ``[head] on_reconnect = "home"``; otherwise it is held until the daemon restarts.
  - the speed table's witness (:class:`foveatrack.pose_check.ScaleWitness`) warns once when the
    background says the table is another unit's.

The map is kept across a homing or a new lidar clock: the world did not move.
"""

from __future__ import annotations

from foveatrack.control import STOP
from foveatrack.pose_check import PoseCheck
from foveatrack.recording.records import ns, write_record


class PoseGuard:
    """Holds the daemon's :class:`~foveatrack.pose_check.PoseCheck` (None when ``[pose_check]`` is off)."""

    def __init__(self, config):
        pc = config.pose_check
        self.check = PoseCheck(pc, config.tracker.lidar_offset_m) if pc.enabled else None
        self.warnings: list[str] = []

    def compile(self) -> None:
        """Compile (or load from numba's cache) the kernel before data flows."""
        if self.check is not None:
            import numpy as np

            from foveatrack.pose_check import BackgroundMap, match_counts

            match_counts(np.ones((1, 3)), 0.0, 0.0, [0.0], [0.0], BackgroundMap(self.check.cfg.cell_deg), 0.1, 0.01)

    def before_frame(self, d, frame, now: float) -> bool:
        """Map or check ``frame`` before it is tracked; True when it must not be tracked (it went into
        the start map, or its background says the pose is wrong)."""
        if self.check is None:
            return False
        if not self.check.mapped:
            pan, tilt = d.tracker.recon.angles_at(frame.t_end_s)[:2]
            self.check.map_frame(frame.xyz, pan, tilt)
            d.counters["frames_mapping"] += 1
            if self.check.mapped:
                d.log.event("pose_map", frames=self.check.map.frames, cells=self.check.map.cells_mapped,
                            pan_deg=pan, tilt_deg=tilt)
                # (not on the first tracked frame: replay hands on an event after the frame before it)
                self.check.next_check_s = frame.t_end_s + self.check.cfg.period_s
            return True
        return self._check(d, frame, now)

    def rebased(self) -> None:
        if self.check is not None:
            self.check.rebased()

    def _check(self, d, frame, now: float) -> bool:
        """Check a frame; correct the drift, or take the pose as unknown (module docstring)."""
        from foveatrack.daemon.runtime import _job_event

        res = self.check.on_frame(frame.xyz, frame.t_ns, frame.t_start_s, frame.t_end_s, d.tracker.recon.angles_at)
        if res is None:
            return False
        d.counters[f"pose_checks_{res.kind}"] += 1
        if res.kind == "ok":
            dp, dt = self.check.correction(res)
            t_s = frame.t_start_s
            if (dp or dt) and d.tracker.correct_pose(t_s, dp, dt):
                d.counters["pose_corrections"] += 1
                ev = {"event": "pose_corrected", "t_s": t_s, "dpan_deg": dp, "dtilt_deg": dt}
                d._record(_job_event, ns(t_s), ev)     # before the frame's records: replay, after the one before
                d.log.event("pose_corrected", t_s=t_s, dpan_deg=round(dp, 4), dtilt_deg=round(dt, 4),
                            offset_pan_deg=round(res.dpan_deg, 3), offset_tilt_deg=round(res.dtilt_deg, 3),
                            match=round(res.match, 3))
            warn = self.check.witness.warning()
            if warn:
                self.warnings.append(warn)
                d.log.event("warning", message=warn, table_error_rel=self.check.witness.table_error_rel)
            return False
        if res.kind == "mismatch":
            ev = res.as_event()
            d.log.event("pose_mismatch", t_s=frame.t_end_s, **ev)
            d._record(_job_event, ns(frame.t_end_s), {"event": "pose_mismatch", "t_s": frame.t_end_s, **ev})
            d._pose_unknown(now, "pose_check")
            h = d.cfg.head
            if h.on_reconnect == "home" and d.head.connected:
                d._reconnected(now)          # STOP, then the absolute moves home (its _pose_tick)
            elif h.on_reconnect == "keep":
                # held: nothing else stops the head while its pose is unknown on a live link
                t_s = d._send_time(max(d.sensor_now_s(now) or frame.t_end_s, frame.t_end_s))
                d.tracker.command_sent(t_s, STOP)
                rec, _ = d._send(STOP, "pose_check", t_s)
                d._record(write_record, rec)
            d.counters["frames_pose_unknown"] += 1
            return True
        return False
