"""The head's link and pose: link events, a pose made unknown by a lost link, the homing that makes it
known again, and the tracker rebased on the new pose (one role of :class:`foveatrack.daemon.runtime.Daemon`).

``pose_state``: None (known), "unknown" (the link was lost: a head that lost power comes back at its
power-on pose and reports none; or the start, with ``[head] on_start = "home"``), "homing" (absolute
moves under way, ``[head] on_reconnect = "home"`` or ``on_start = "home"``),
"refused" (another head behind the link: :mod:`foveatrack.daemon.pose_guard`).  No frame is tracked
while it is not None.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace

from foveatrack.daemon.homing_plan import HomingConfirm, HomingSteps, plan_homing
from foveatrack.daemon.record_queue import _job_event
from foveatrack.recording.records import ns
from foveatrack.turn_witness import MoveWitness

ABS_SET_QUIET_S = 0.3     # line quiet before a Pelco absolute set (the PTS family needs 0.2 s)


@dataclass
class LinkSeen:
    """What the link's events were last logged from: up/down, and the port locked by or refused to
    another process (logged again at most every 10 s while the count grows)."""
    head_up: bool
    locked: int = 0
    lock_log: float = -math.inf
    refusals: int = 0
    refusal_log: float = -math.inf


class HeadPose:
    """The head's part of the daemon (a mixin of ``Daemon``; its state: ``pose_state``,
    ``_home_steps``, ``link_seen``)."""

    def _watch_head_link(self, now: float) -> None:
        """The 10 Hz tick's look at the head's link: its events in the log, and a link lost and back
        makes the pose unknown and homes the head as ``[head] on_reconnect`` says."""
        c, seen = self.cfg, self.link_seen
        locked = getattr(self.head.stats, "open_locked", 0)
        if locked != seen.locked:
            # another process took the head's port while its link was down: never written to
            if seen.locked == 0 or now - seen.lock_log >= 10.0:
                self.log.event("head_locked", port=c.head.port, reason=self.head.client.last_open_error,
                               attempts=locked)
                seen.lock_log = now
            seen.locked = locked
        refusals = self.head.stats.open_refusals
        if refusals != seen.refusals:
            # another device holds the head's path: never written to (foveatrack.serial_identity)
            if seen.refusals == 0 or now - seen.refusal_log >= 10.0:
                self.log.event("head_refused", reason=self.head.client.last_open_error, refusals=refusals)
                seen.refusal_log = now
            seen.refusals = refusals
        if self.head.connected != seen.head_up:
            head_up = seen.head_up = self.head.connected
            self.counters["head_link_up" if head_up else "head_link_down"] += 1
            self.log.event("head_connected" if head_up else "head_disconnected", stats=asdict(self.head.stats))
            # "keep" trusts the dead reckoning over a lost link, but a pose already unknown (a homing
            # under way, at start or after a failed write) is homed again once the link is back
            if (c.head.on_reconnect != "keep" or self.pose_state is not None) and self.pose_state != "refused":
                if not head_up and self.pose_state is None:
                    self._pose_unknown(now, "link_lost")
                elif head_up:
                    if self.pose_state is None:     # lost and back between two ticks
                        self._pose_unknown(now, "link_lost")
                    self.pose_guard.link_back(self)   # is it our head? (pose_guard: identity)
                    self._reconnected(time.monotonic())   # (the query took a while: the homing's quiet line counts from now)
        if self.pose_state is not None:
            self._pose_tick(now)

    def _pose_unknown(self, now: float, why: str, policy: str | None = None) -> None:
        """The head's link was lost (or a homing write failed, or the run starts with ``[head] on_start
        = "home"``): from now its pose is unknown (one that lost power comes back at its power-on pose;
        the head reports none).  No frame is tracked until :meth:`_reconnected` has done what
        ``policy`` says ("stop", "home"; default ``[head] on_reconnect``)."""
        h = self.cfg.head
        self._home_policy = h.on_reconnect if policy is None else policy
        self.pose_state = "unknown"
        self._home_steps = HomingSteps()
        self.counters["head_pose_unknown"] += 1
        self.log.event("head_pose_unknown", why=why, on_reconnect=self._home_policy, frames=self.counters["frames"])
        self._record(_job_event, ns(self.sensor_now_s(now) or 0.0),
                     {"event": "head_pose_unknown", "why": why, "on_reconnect": self._home_policy})

    def _reconnected(self, now: float) -> None:
        """The link is back (its first frame was STOP), or the run starts: home the head if the pose's
        policy says so (:meth:`_pose_unknown`)."""
        h = self.cfg.head
        self.head.stop()
        self._home_steps = HomingSteps()
        self._homing_t0 = now
        if self._home_policy == "home":
            # the target's last trusted bearing first, else home; the worst-case wait to that goal
            # (foveatrack.daemon.homing_plan); with a pose check, detections after the last check that
            # vouched for the pose are not trusted
            g = self.pose_guard
            trusted = None if g.check is None else (g.trusted_until_s if g.trusted_until_s is not None else -math.inf)
            quiet, confirmable = ABS_SET_QUIET_S, g.check is not None
            plan = self._homing = plan_homing(h, self.bearings, self.sensor_now_s(now), trusted, g.identity_pending,
                                              setup_s=2 * quiet, wait_ends_early=confirmable)
            self._homing_confirm = HomingConfirm() if confirmable else None
            self.log.event("head_homing_plan", **plan.as_event())
            # an absolute set is obeyed only after a quiet line: nothing else is written meanwhile, and
            # each step's gap counts from the previous write as it happened, not as it was planned (a
            # late 10 Hz tick once left the tilt set 0.205 s after the pan set; the head ignored it);
            # the goals go through the one step, whose gate keeps the tilt inside the stops (_pose_tick)
            self._home_steps = HomingSteps([(quiet, "pan", plan.pan_deg), (quiet, "tilt", plan.tilt_deg),
                                            (plan.wait_s, "done", None)], now)     # after the STOP

    def _pose_tick(self, now: float) -> None:
        h = self.cfg.head
        if self.pose_state == "refused":    # another head behind the link: nothing is written to it
            return
        if not self.head.connected or self._home_policy == "stop":
            # STOP every second: while the link is down each try is the reopen, so the first frame a
            # reopened link carries is STOP; with "stop" it holds the head until the daemon restarts
            if now - getattr(self, "_last_unknown_stop", -math.inf) >= 1.0:
                self._last_unknown_stop = now
                self.head.stop()
            return
        confirmed = self.pose_state == "homing" and self._homing_confirm is not None and self._homing_confirm.confirmed
        while (due := self._home_steps.pop_due(now, confirmed)) is not None:
            step, goal_deg = due
            plan = self._homing
            if step in ("pan", "tilt"):
                rec = self.step.own_goal(step, goal_deg, "homing")
                if not rec.reached_head:
                    self.log.event("head_homing_failed", step=step, limited=list(rec.limited))
                    # again once the link is back, as the pose's policy says (a start's homing under
                    # on_reconnect = "keep" stayed unknown for good when it took that policy)
                    return self._pose_unknown(now, "homing_write_failed", policy=self._home_policy)
                self._home_steps.written(now)    # (the tick's time: the write follows it within the tick)
                # the goal the gate let through is where the head goes: the wait's checks and the
                # tracker rebased at the end use it
                plan = self._homing = replace(plan, **{f"{step}_deg": rec.goal_deg})
                self.pose_state = "homing"
                extra = {"asked_deg": rec.asked_deg, "limited": list(rec.limited)} if rec.limited else {}
                self.log.event("head_homing", axis=step, home_deg=[plan.pan_deg, plan.tilt_deg], goal=plan.goal,
                               worst_case_s=round(plan.worst_case_s, 3), **extra)
            else:
                t_s = self.sensor_now_s(now)
                pan, tilt = plan.pan_deg, plan.tilt_deg
                if confirmed:
                    self.log.event("head_homing_confirmed", by="pose_check",
                                   waited_s=round(now - (self._homing_t0 or now), 3), wait_s=plan.wait_s)
                # before the lidar's first packet (a homing at start) the sensor clock is unknown: the
                # tracker starts at 0, and the record says so (replay rebases at the same instant)
                t0 = t_s if t_s is not None else 0.0
                self._rebase_tracker(t0, pan, tilt)
                self.pose_state = None
                self.counters["head_homed"] += 1
                self.log.event("head_homed", pan_deg=pan, tilt_deg=tilt, t0_s=t0, frames=self.counters["frames"])
                self._record(_job_event, ns(t0), {"event": "tracker_rebased", "reason": "head_homed",
                                                  "t0_s": t0, "pan_deg": pan, "tilt_deg": tilt})

    def _rebase_tracker(self, t0_s: float, pan_deg: float, tilt_deg: float) -> None:
        """A fresh tracker whose dead reckoning starts at ``(pan_deg, tilt_deg)`` at sensor time ``t0_s``."""
        self.step.rebase(self.tracker.rebased(t0_s, pan_deg, tilt_deg))   # replay repeats it from the event
        if self.witness is not None:
            self.witness = MoveWitness(self.table)
        if self.imu_feed is not None:
            self.imu_feed.restart(t0_s)
        self._last_send_t = -math.inf
        self.pose_guard.rebased(t0_s)
