"""Where a head whose pose is unknown is driven, and how long the daemon stays blind (issue 26).

After a head comes back on its link (or the background said its pose is wrong) with ``[head]
on_reconnect = "home"``, the daemon writes Pelco absolute moves (0x4B/0x4D) and tracks nothing until
the head can be taken to be there.  Before this module it drove to ``home_pan_deg/home_tilt_deg``
and waited the worst case from anywhere (58 s for the shipped example), and the UAV had often left
the home view by then (issue 26: 0 of 160 frames detected afterwards).  Now:

* **where** (:func:`plan_homing`): the target's last known bearing, where the tracker last saw it
  (:class:`Bearings`: the world position of each detection as bearing angles), if it is no older than
  ``BEARING_MAX_AGE_S`` of sensor time and the head's pose was trusted then (a pose check that later
  said "mismatch" voids the detections after the last check that vouched for the pose, "ok" within
  1 deg: they were placed with a wrong pose), carried on at its rate over the last ``RATE_SPAN_S`` of detections (at most
  ``MAX_EXTRAPOLATION_DEG``: a UAV crossing at 2.4 deg/s is 18 deg on after a 7.7 s head restart,
  out of a Mid-40's view from where it was last seen) to the moment tracking resumes: the absolute
  sets' quiet line, and the blind wait too unless a pose check may end it early (carried on only to
  the plan's time, a UAV crossing at 2 deg/s was 10-12 deg off when a 3.6 s homing ended, at the
  rim of the view, and the paper's controller, which stops on every empty frame, took over 7 s to
  catch it); else home.  Home too when the homing must
  prove the head behind a reappeared link is ours (the pose check must see the lidar move: a goal
  where it already points proves nothing).  The goal is not clamped here: the daemon writes it through
  the one frame step (:meth:`foveatrack.frame_step.FrameStep.own_goal`), whose gate keeps the tilt
  ``tilt_margin_deg`` inside the stops (:meth:`foveatrack.gate.Limits.clamp_tilt_goal`, the same rule as
  for speed commands) and says why it moved it; pan is wrapped to [-180, 180) here.
* **how long** (worst case): the head's pose is unknown (the PTS-303H reports none, and
  /work/shared/facts/gimbal-pelco.md states no power-on pose; a link cut while the head kept its
  power leaves it wherever its latched motion took it), so the wait is what the move to *this* goal
  may take from anywhere: 180 deg of pan at ``pan_speed_max_deg_s`` plus the tilt from the farther
  stop to the goal tilt at ``tilt_speed_max_deg_s``, + 1 s of ramps and dead time (the axes summed:
  the tilt set is written after the pan set).  ``home_wait_s`` in the config replaces it.  The
  shipped example: 12 + 30 + 1 = 43 s to tilt 0 (before: 12 + 45 + 1 = 58 s, the whole tilt range).
* **ending it early**: with ``[pose_check]`` on, every frame during the wait is registered against
  the background map at the goal pose (:class:`HomingConfirm`); ``CONFIRM_CHECKS`` conclusive checks
  in a row that put the head within ``CONFIRM_DEG`` of the goal, agreeing with each other within
  ``CONFIRM_REST_DEG`` (at rest, not passing through), end the wait at once.
* **when** (:class:`HomingSteps`): each write a quiet line after the previous one *as it was made*
  (the head ignores an absolute set that follows another frame too closely).

Pure: no I/O, no clock; the daemon (:meth:`foveatrack.daemon.runtime.Daemon._reconnected`,
``_pose_tick``) calls it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

BEARING_MAX_AGE_S = 30.0   # a bearing older than this [s of sensor time] is not searched first
RATE_SPAN_S = 1.0          # the bearing's rate is fitted over the detections of this last span [s]
MAX_EXTRAPOLATION_DEG = 30.0   # the bearing is carried on at its rate by at most this much [deg]
CONFIRM_CHECKS = 6         # conclusive pose checks in a row at the goal that end the wait (0.5 s at 10 Hz)
CONFIRM_DEG = 1.5          # |offset| from the goal each must be within [deg]
CONFIRM_REST_DEG = 0.3     # and they must agree within this [deg]: the head at rest there (a tilt set
                           # moves at 2 deg/s: 1 deg over the six; three checks within 0.5 deg once
                           # ended a wait 1 deg short of the goal, the head still on its way)
RAMP_S = 1.0               # ramps and dead time added to the travel time [s]


def bearing_deg(world_xyz) -> tuple[float, float]:
    """(pan, tilt) [deg] pointing the lidar axis at world point ``world_xyz`` (pan + = left, tilt + = up;
    :func:`foveatrack.reconstruction.rotation_matrix`: the axis is (cos p cos t, sin p cos t, sin t))."""
    x, y, z = (float(v) for v in world_xyz)
    return math.degrees(math.atan2(y, x)), math.degrees(math.atan2(z, math.hypot(x, y)))


@dataclass(frozen=True)
class Bearing:
    t_s: float          # sensor time of the detection [s]
    pan_deg: float
    tilt_deg: float


class Bearings:
    """The bearings of the last detections (a few seconds' worth), newest last."""

    def __init__(self, keep: int = 100):
        self._b: deque = deque(maxlen=keep)

    def saw(self, t_s: float, world_xyz) -> None:
        """A detection at sensor time ``t_s`` placed at ``world_xyz`` [m] (None: nothing)."""
        if world_xyz is None or not math.isfinite(t_s):
            return
        pan, tilt = bearing_deg(world_xyz)
        if math.isfinite(pan) and math.isfinite(tilt):
            self._b.append(Bearing(t_s, pan, tilt))

    def last(self, trusted_until_s: float | None = None) -> Bearing | None:
        """The newest bearing at or before ``trusted_until_s`` (None: any)."""
        for b in reversed(self._b):
            if trusted_until_s is None or b.t_s <= trusted_until_s:
                return b
        return None

    def rate_deg_s(self, last: Bearing) -> tuple[float, float]:
        """(pan, tilt) rate [deg/s] of the bearings over the ``RATE_SPAN_S`` up to ``last`` (least
        squares; 0 with fewer than 3 detections spanning half of it)."""
        pts = [b for b in self._b if last.t_s - RATE_SPAN_S <= b.t_s <= last.t_s]
        if len(pts) < 3 or pts[-1].t_s - pts[0].t_s < 0.5 * RATE_SPAN_S:
            return 0.0, 0.0
        t = [b.t_s - last.t_s for b in pts]
        tm = sum(t) / len(t)
        den = sum((x - tm) ** 2 for x in t)
        out = []
        for get in (lambda b: last.pan_deg + ((b.pan_deg - last.pan_deg + 180.0) % 360.0 - 180.0),
                    lambda b: b.tilt_deg):
            v = [get(b) for b in pts]
            vm = sum(v) / len(v)
            out.append(sum((x - tm) * (y - vm) for x, y in zip(t, v)) / den)
        return out[0], out[1]

    def clear(self) -> None:
        """A new sensor clock: the old times mean nothing on it."""
        self._b.clear()


@dataclass(frozen=True)
class HomingPlan:
    pan_deg: float
    tilt_deg: float
    goal: str              # "last_bearing" or "home"
    wait_s: float          # the blind wait after the absolute sets, unless confirmed sooner [s]
    worst_case_s: float    # what the move to this goal may take from anywhere [s]
    why: str

    def as_event(self) -> dict:
        return {"goal": self.goal, "pan_deg": round(self.pan_deg, 3), "tilt_deg": round(self.tilt_deg, 3),
                "wait_s": round(self.wait_s, 3), "worst_case_s": round(self.worst_case_s, 3), "why": self.why}


def worst_case_s(head, tilt_goal_deg: float) -> float:
    """The time the absolute move to tilt ``tilt_goal_deg`` (any pan) may take from anywhere [s]: 180 deg
    of pan, and the tilt from the farther stop (module docstring)."""
    lo, hi = head.tilt_limits_deg
    goal = min(max(tilt_goal_deg, lo), hi)    # the head cannot go past a stop (the gate keeps it inside)
    tilt_travel = max(goal - lo, hi - goal)
    return 180.0 / head.pan_speed_max_deg_s + tilt_travel / head.tilt_speed_max_deg_s + RAMP_S


def blind_wait_s(head, tilt_goal_deg: float) -> float:
    """The blind wait after the absolute sets to tilt ``tilt_goal_deg`` [s]: ``home_wait_s`` where the
    config gives it, else the worst case of the move (:func:`worst_case_s`)."""
    return head.home_wait_s if head.home_wait_s is not None else worst_case_s(head, tilt_goal_deg)


def plan_homing(head, bearings: Bearings | None, now_s: float | None,
                trusted_until_s: float | None = None, prove_identity: bool = False,
                setup_s: float = 0.0, wait_ends_early: bool = True) -> HomingPlan:
    """Where to drive a head whose pose is unknown, and how long to wait (module docstring).

    head : :class:`foveatrack.device_config.HeadConfig`; bearings : the last detections' bearings;
    now_s : sensor time now (None: unknown, no bearing is recent); trusted_until_s : detections after
    this sensor time were placed with a pose since found wrong (None: all trusted); prove_identity:
    the homing must show the head behind a reappeared link is ours (home: module docstring);
    setup_s : from now until the absolute sets are written [s]; wait_ends_early : a pose check may end
    the blind wait at once (False: tracking resumes only after it, so the bearing is carried on
    through it too)."""
    home_pan, home_tilt = head.home_deg
    b = None if bearings is None or now_s is None or prove_identity else bearings.last(trusted_until_s)
    if b is not None and now_s - b.t_s <= BEARING_MAX_AGE_S:
        age = max(now_s - b.t_s, 0.0)
        rp, rt = bearings.rate_deg_s(b)

        def carried(lead_s):
            dp, dt = (min(max(r * lead_s, -MAX_EXTRAPOLATION_DEG), MAX_EXTRAPOLATION_DEG) for r in (rp, rt))
            return (b.pan_deg + dp + 180.0) % 360.0 - 180.0, b.tilt_deg + dt   # the tilt: the gate's

        lead = age + max(setup_s, 0.0)
        pan, tilt = carried(lead)
        if not wait_ends_early:    # the wait depends on the goal's tilt (worst case): that of the goal before it
            lead += blind_wait_s(head, tilt)
            pan, tilt = carried(lead)
        goal = "last_bearing"
        why = (f"the target was last seen at {b.pan_deg:.1f}/{b.tilt_deg:.1f} deg {age:.1f} s ago, moving "
               f"{rp:+.2f}/{rt:+.2f} deg/s; looked for where it is {lead:.1f} s after it was seen")
    else:
        pan, tilt, goal = home_pan, home_tilt, "home"
        why = ("the homing must show the head behind the reappeared link is ours" if prove_identity else
               "no detection while the pose was trusted" if b is None else
               f"the last detection is {now_s - b.t_s:.0f} s old (> {BEARING_MAX_AGE_S:.0f} s)")
    return HomingPlan(pan, tilt, goal, blind_wait_s(head, tilt), worst_case_s(head, tilt), why)


class HomingConfirm:
    """Ends the blind wait once the background shows the head at rest at the goal (module docstring):
    feed it each pose check at the goal pose (:class:`foveatrack.pose_check.PoseCheckResult` or None)."""

    def __init__(self):
        self._ok: deque = deque(maxlen=CONFIRM_CHECKS)   # the last checks (a list grew while at rest there)
        self.confirmed = False

    def feed(self, res) -> bool:
        if res is None or res.kind == "inconclusive":
            return self.confirmed          # no verdict either way: the run so far stands
        near = (res.kind == "ok" and abs(res.dpan_deg) <= CONFIRM_DEG and abs(res.dtilt_deg) <= CONFIRM_DEG)
        if not near:
            self._ok.clear()
            return self.confirmed
        self._ok.append((res.dpan_deg, res.dtilt_deg))
        recent = self._ok
        if len(recent) == CONFIRM_CHECKS and all(
                max(v[k] for v in recent) - min(v[k] for v in recent) <= CONFIRM_REST_DEG for k in (0, 1)):
            self.confirmed = True
        return self.confirmed


class HomingSteps:
    """The homing's writes in order, each due ``gap_s`` after the previous write as it was really made
    (not as planned: a 10 Hz tick that fired the pan set 0.09 s late left the tilt set 0.205 s after
    it, under the PTS family's 0.2 s quiet line plus the frame's time on the wire, and the head
    ignored it).  ``steps``: ``(gap_s, name, goal)``, the first gap counted from ``t0``; the last,
    ``"done"``, may come early once the wait is confirmed (:class:`HomingConfirm`)."""

    def __init__(self, steps=(), t0: float = 0.0):
        self._steps = list(steps)
        self.due = t0 + self._steps[0][0] if self._steps else math.inf

    def __bool__(self) -> bool:
        return bool(self._steps)

    def pop_due(self, now: float, confirmed: bool = False):
        """The next ``(name, goal)`` if it is due at host time ``now``, else None."""
        if self._steps and (now >= self.due or (confirmed and self._steps[0][1] == "done")):
            _, name, frame = self._steps.pop(0)
            self.due = math.inf        # until written() says when the previous write was made
            if name == "done":
                self._steps.clear()
            return name, frame
        return None

    def written(self, t: float) -> None:
        """The popped step was written at host time ``t``: the next is due its gap after it."""
        if self._steps:
            self.due = t + self._steps[0][0]

