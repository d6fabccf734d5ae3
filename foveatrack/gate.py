"""The command gate: the one way a tracker's command reaches a head, in every driver.

Every driver runs a frame through its controller and then through :class:`CommandGate`, in the one
step :class:`foveatrack.frame_step.FrameStep`, so the command path the hardware uses is the one the
simulator exercises and replay re-enacts::

    tracker command --decide()--> limits (speed bytes, turbo, tilt stops) --> stale frame -> STOP
                    --(the sink writes it)--> wrote(): a failed write leaves the head on its last command

The head reports nothing, so the tracker dead-reckons from what it sent.  Whenever the gate changes a
command, or the sink fails to write it, the tracker is told what the head really got, at the same
instant (:meth:`Tracker.command_sent` replaces the command sent at that time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from foveatrack.control import STOP, HeadCommand
from foveatrack.speed_table import TURBO
from gimbal.head_facts import DEFAULT_HEAD, HeadFacts

# Recorded in a command's ``limited`` list when STOP was sent because the frame was older than
# ``stale_frame_s`` when processed (the daemon judges by the wall clock, so replay reads it from the
# recording; the simulator by virtual time).
STALE_FRAME = "stale_frame"
# Recorded when tilt motion was refused because the driver gave no finite tilt estimate (or no finite
# uncertainty) while the gate has tilt stops to keep: the gate fails closed.  A NaN compared with a
# stop is False, so before this rule "tilt up at the stop" passed whenever the estimate was missing.
TILT_UNKNOWN = "tilt_unknown"
# Recorded when the daemon wrote STOP because the head's link was down: whatever a reopened link
# carries first is STOP, and from then on the head's pose is unknown.
LINK_DOWN = "link_down"
# Recorded when an absolute tilt goal (a homing's: foveatrack.daemon.homing_plan) lay beyond a stop less
# the margin and was moved onto that line; the tilt rule for goals is the one for speed commands.
TILT_GOAL_UP = "tilt_goal_stop_up"
TILT_GOAL_DOWN = "tilt_goal_stop_down"

# Two tilt margins, two layers: the tracker keeps TrackerConfig.tilt_margin_deg (3 deg) from a stop
# by itself; the gate, the last line, refuses tilt toward a stop GATE_TILT_MARGIN_DEG (2 deg) from
# it, so it only acts when the tracker did not (a bug, a misconfigured table).  The daemon's [head]
# tilt_margin_deg and a scene's [gate] tilt_margin_deg set this one; its default is the head facts'.
GATE_TILT_MARGIN_DEG = DEFAULT_HEAD.tilt_margin_deg


@dataclass(frozen=True)
class Limits:
    """Hard limits applied to every command after the tracker, before it is encoded.

    max_pan_byte, max_tilt_byte : 0..63       highest speed byte allowed per axis
    allow_turbo : bool                        may pan use 0xFF (else it becomes max_pan_byte)
    tilt_limits_deg : (lo, hi) [deg]          the head's tilt stops
    tilt_margin_deg : >= 0 [deg]              no tilt motion toward a stop once the estimated tilt
                                              (+ its 2 sigma) is within this of it

    Built from a head's facts (:meth:`of`); the defaults are :data:`gimbal.head_facts.DEFAULT_HEAD`'s.
    """

    max_pan_byte: int = DEFAULT_HEAD.max_pan_byte
    max_tilt_byte: int = DEFAULT_HEAD.max_tilt_byte
    allow_turbo: bool = DEFAULT_HEAD.allow_turbo
    tilt_limits_deg: tuple[float, float] = DEFAULT_HEAD.tilt_limits_deg
    tilt_margin_deg: float = DEFAULT_HEAD.tilt_margin_deg

    @classmethod
    def of(cls, facts: HeadFacts) -> "Limits":
        """The gate's limits for a head: its stops and the limits configured with it."""
        return cls(facts.max_pan_byte, facts.max_tilt_byte, facts.allow_turbo, tuple(facts.tilt_limits_deg),
                   facts.tilt_margin_deg)

    def apply(self, cmd: HeadCommand, tilt_deg: float, tilt_sigma_deg: float = 0.0) -> tuple[HeadCommand, list[str]]:
        """The command that may leave, and the reasons it was changed (empty if unchanged).

        ``tilt_deg``, ``tilt_sigma_deg``: the driver's estimate of the head's tilt and its 1 sigma [deg];
        either not finite (a driver that does not know where its head points) refuses all tilt
        motion (:data:`TILT_UNKNOWN`): the stops cannot be kept without it."""
        why = []
        pd, pb, td, tb = cmd.pan_dir, cmd.pan_byte, cmd.tilt_dir, cmd.tilt_byte
        if pb == TURBO and not self.allow_turbo:
            pb, why = self.max_pan_byte, why + ["turbo"]
        elif pb != TURBO and pb > self.max_pan_byte:
            pb, why = self.max_pan_byte, why + ["pan_speed"]
        if tb > self.max_tilt_byte:
            tb, why = self.max_tilt_byte, why + ["tilt_speed"]
        lo, hi = self.tilt_limits_deg
        s2 = 2.0 * max(tilt_sigma_deg, 0.0)
        if td != 0 and not (math.isfinite(tilt_deg) and math.isfinite(s2)):
            td, tb, why = 0, 0, why + [TILT_UNKNOWN]
        elif td > 0 and tilt_deg + s2 >= hi - self.tilt_margin_deg:
            td, tb, why = 0, 0, why + ["tilt_stop_up"]
        elif td < 0 and tilt_deg - s2 <= lo + self.tilt_margin_deg:
            td, tb, why = 0, 0, why + ["tilt_stop_down"]
        return HeadCommand(pd, pb if pd else 0, td, tb if td else 0), why

    def clamp_tilt_goal(self, tilt_deg: float) -> tuple[float, list[str]]:
        """An absolute tilt goal [deg] kept ``tilt_margin_deg`` inside the stops, and why it was moved
        (empty if it was not): a goal at the margin's line is where a speed command toward the stop
        would be refused."""
        lo, hi = self.tilt_limits_deg
        m = self.tilt_margin_deg
        if tilt_deg > hi - m:
            return hi - m, [TILT_GOAL_UP]
        if tilt_deg < lo + m:
            return lo + m, [TILT_GOAL_DOWN]
        return tilt_deg, []


@dataclass(frozen=True)
class Proposal:
    """A command a driver wants to send and its head's tilt estimate, as :meth:`CommandGate.decide`
    reads them (a tracker's output has the same fields); for drivers without a controller output
    (the live IMU calibration's pose steps)."""

    command: HeadCommand
    head_tilt_deg: float
    head_sigma_tilt_deg: float


class CommandGate:
    """Limits, stale frames and failed writes, between a tracker and a head (see the module docstring).

    limits : Limits or None (None: the tracker's commands pass unchanged, as in recordings made
             before the daemon recorded its limits)
    """

    def __init__(self, limits: Limits | None):
        self.limits = limits
        self.head_cmd: HeadCommand = STOP   # what the head last received (it starts stopped)

    def decide(self, tracker, out, send_t_s: float, stale: bool = False,
               stop_why: tuple[str, ...] = ()) -> tuple[HeadCommand, list[str]]:
        """The command to write for the tracker output ``out`` sent at ``send_t_s``, and why it differs
        from the tracker's (empty: unchanged).  ``stale``: the frame was too old when processed (the
        driver judges: wall clock, recording or virtual time); STOP is sent instead, as for any of the
        driver's ``stop_why`` reasons (the daemon's head link is down: :data:`LINK_DOWN`).  ``out`` must
        carry the driver's tilt estimate (``head_tilt_deg``, ``head_sigma_tilt_deg``): without a
        finite one, tilt motion is refused.  ``tracker`` None: nothing dead-reckons from what is
        sent (a driver that stops on any change)."""
        cmd, why = out.command, []
        if self.limits is not None:
            cmd, why = self.limits.apply(out.command, out.head_tilt_deg, out.head_sigma_tilt_deg)
        if stale:
            cmd, why = STOP, why + [STALE_FRAME]
        if stop_why:
            cmd, why = STOP, why + list(stop_why)
        if why and tracker is not None:
            tracker.command_sent(send_t_s, cmd)
        return cmd, why

    def decide_goal(self, axis: str, goal_deg: float) -> tuple[float | None, list[str]]:
        """An absolute goal (a Pelco set-pan / set-tilt: the daemon's homing) that may leave, and why it
        differs from the one asked for: pan wrapped to [-180, 180), tilt kept inside the stops less the
        margin (:meth:`Limits.clamp_tilt_goal`).  A goal that is not finite is refused (None,
        :data:`TILT_UNKNOWN` or ``"pan_unknown"``): nothing is written."""
        if not math.isfinite(goal_deg):
            return None, [TILT_UNKNOWN if axis == "tilt" else "pan_unknown"]
        if axis == "pan":
            return (goal_deg + 180.0) % 360.0 - 180.0, []
        if axis != "tilt":
            raise ValueError(f"an absolute goal is for axis 'pan' or 'tilt', not {axis!r}")
        if self.limits is None:
            return goal_deg, []
        return self.limits.clamp_tilt_goal(goal_deg)

    def wrote_goal(self, ok: bool) -> None:
        """After the sink wrote an absolute goal: the head moves there and stops, its latched motion
        replaced (``ok`` False: it never got the bytes and keeps its last command)."""
        if ok:
            self.head_cmd = STOP

    def wrote(self, tracker, send_t_s: float, cmd: HeadCommand, ok: bool,
              ran_instead: HeadCommand | None = None) -> HeadCommand:
        """After the sink wrote ``cmd`` (registered with the tracker at ``send_t_s``): ``ok`` False means
        the head never got the bytes and keeps running its last command, which the dead reckoning is
        told at the same instant (a Pelco head latches motion: a link outage would otherwise read as
        the head following the tracker).  ``ran_instead``: the sink knows the head ran this command
        instead (a replay under another configuration follows the recorded head); the dead reckoning
        is told so at the same instant.  Returns what the head now runs."""
        if ran_instead is not None:
            self.head_cmd = ran_instead
            if tracker is not None:
                tracker.command_sent(send_t_s, ran_instead)
        elif ok:
            self.head_cmd = cmd
        elif tracker is not None:
            tracker.command_sent(send_t_s, self.head_cmd)
        return self.head_cmd
