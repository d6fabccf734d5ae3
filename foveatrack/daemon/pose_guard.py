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

Identity of a link that reappears (issue 26: a link re-created to another head was followed, and
drove it).  The path's device identity (:mod:`foveatrack.serial_identity`) accepts a re-created link
(a restarted head server, udev's by-id link of a replugged adapter), so the head behind it must answer
as ours before it is driven:

* its Pelco address: a position query answered from our address (a head with feedback) is logged as
  ``head_identity`` with ``by = "address"`` and the pose it reports; the paper's head never answers;
* the pose check: our lidar sits on our head, so once the homing has moved the head behind the link, the
  background must say the lidar is at home.  The first conclusive check of a frame begun after the
  homing decides: ``ok`` on both axes (pan and tilt observable) -> ``head_identity``
  (``by = "pose_check"``, verified); ``mismatch`` -> ``head_identity_refused``
  (another head moved, ours did not): the daemon writes nothing more to the link (no STOP, no homing)
  until it is restarted with the right head on the link.  Until a check decides, no frame is tracked
  (``frames_identity_pending``): nothing is written to a head whose identity is open.

Without ``[pose_check]`` and without an answer, ``head_identity`` says ``verified = false`` and why.
"""

from __future__ import annotations

from foveatrack.control import STOP
from foveatrack.pose_check import PoseCheck
from foveatrack.recording.records import ns


class PoseGuard:
    """Holds the daemon's :class:`~foveatrack.pose_check.PoseCheck` (None when ``[pose_check]`` is off)."""

    def __init__(self, config):
        pc = config.pose_check
        self.check = PoseCheck(pc, config.tracker.lidar_offset_m) if pc.enabled else None
        self.warnings: list[str] = []
        self.identity_pending = False   # a link came back: the first conclusive check after homing decides
        # the frame end of the last check that vouched for the pose (PoseCheckResult.vouches) [sensor s]:
        # a homing trusts no detection after it
        self.trusted_until_s: float | None = None

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
        if self._check(d, frame, now):
            return True
        if self.identity_pending:
            # a link that reappeared is used only once the background has said whose head it is: until
            # a check decides, frames are not tracked (a frame begun before the homing's end is not
            # checked, and tracking it had already turned the other head by 28 deg before the refusal)
            d.counters["frames_identity_pending"] += 1
            return True
        return False

    def link_back(self, d) -> None:
        """The head's link reappeared: ask the head behind it for its position (answers prove our Pelco
        address), and leave the rest to the pose check after the homing (module docstring)."""
        h = d.cfg.head
        pose = None
        query = getattr(d.head.client, "query_position", None)
        if query is not None:
            pose = query()
        if pose is not None:
            d.log.event("head_identity", verified=True, by="address", address=h.address, port=h.port,
                        pan_deg=pose[0], tilt_deg=pose[1])
        self.identity_pending = self.check is not None
        if self.check is None and pose is None:
            d.log.event("head_identity", verified=False, port=h.port, address=h.address,
                        why="no answer to a position query (the paper's head never answers) and no [pose_check] "
                            "to see the head move the lidar: the head behind the link is driven unverified")

    def rebased(self, t0_s: float) -> None:
        if self.check is not None:
            self.check.rebased(t0_s)

    def _check(self, d, frame, now: float) -> bool:
        """Check a frame; correct the drift, or take the pose as unknown (module docstring)."""
        from foveatrack.daemon.record_queue import _job_event

        res = self.check.on_frame(frame.xyz, frame.t_ns, frame.t_start_s, frame.t_end_s, d.tracker.recon.angles_at)
        if res is None:
            return False
        d.counters[f"pose_checks_{res.kind}"] += 1
        # an "ok" that could not see pan (or tilt) says nothing of that axis: it does not verify a head
        if self.identity_pending and (res.kind == "mismatch" or (
                res.kind == "ok" and res.pan_observable and res.tilt_observable)):
            self.identity_pending = False
            if res.kind == "mismatch":
                return self._refuse(d, frame, res, now)
            d.log.event("head_identity", verified=True, by="pose_check", port=d.cfg.head.port,
                        dpan_deg=round(res.dpan_deg, 3), dtilt_deg=round(res.dtilt_deg, 3))
        if res.kind == "ok":
            if res.vouches():
                self.trusted_until_s = frame.t_end_s
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
                d._send_own(STOP, "pose_check", t_s)     # through the one step, recorded
            d.counters["frames_pose_unknown"] += 1
            return True
        return False

    def _refuse(self, d, frame, res, now: float) -> bool:
        """The head behind a reappeared link moved, but our lidar did not: another head.  Nothing more is
        written to the link (the daemon's pose state "refused")."""
        from foveatrack.daemon.record_queue import _job_event

        h = d.cfg.head
        plan = getattr(d, "_homing", None)     # where the homing drove it (foveatrack.daemon.homing_plan)
        goal = list(h.home_deg) if plan is None else [round(plan.pan_deg, 2), round(plan.tilt_deg, 2)]
        why = (f"[head] port {h.port} reappeared and was homed to {goal} deg, but the lidar's background "
               f"puts the lidar {res.dpan_deg:+.1f} deg pan / {res.dtilt_deg:+.1f} deg tilt from there (match "
               f"{res.match:.2f}): the head behind the link is not the one the lidar sits on; nothing more is "
               "written to it; restart the daemon once the right head is on the link")
        d.pose_state = "refused"
        d.counters["head_identity_refused"] += 1
        d.counters["frames_pose_unknown"] += 1
        d.log.event("head_identity_refused", port=h.port, why=why, frames_sent=d.head.stats.frames_sent,
                    **res.as_event())
        d._record(_job_event, ns(frame.t_end_s), {"event": "head_identity_refused", "why": why})
        d.status.note(f"foveatrack daemon: {why}")     # on the tick: a failed stderr must not end it
        return True
