"""The daemon's homing writes its absolute goals through the one step: the gate keeps the tilt goal
inside the stops less the margin and says why (issue 26: the homing clamped its own goal, a second
tilt rule, and wrote raw Pelco sets beside the gate)."""

from __future__ import annotations

import json
import math

import pytest

from foveatrack.control import STOP, HeadCommand
from foveatrack.frame_step import FrameStep
from foveatrack.gate import TILT_GOAL_DOWN, TILT_GOAL_UP, TILT_UNKNOWN, CommandGate, Limits
from gimbal.pelco import encode_set_pan, encode_set_tilt
from inprocess import inprocess_daemon

LIMITS = Limits(tilt_limits_deg=(-30.0, 60.0), tilt_margin_deg=2.0)


class GoalSink:
    def __init__(self, ok=True):
        self.ok, self.goals = ok, []

    def send(self, cmd, send_t_s, source):
        return self.ok

    def send_goal(self, axis, goal_deg, source):
        self.goals.append((axis, goal_deg, source))
        return self.ok


class NoController:
    """The step's controller must not be told of an absolute goal: any call fails the test."""

    def __getattr__(self, name):
        raise AssertionError(f"the controller was called ({name}) for an absolute goal")


@pytest.mark.parametrize("asked, written, why", [(80.0, 58.0, (TILT_GOAL_UP,)), (58.5, 58.0, (TILT_GOAL_UP,)),
                                                  (-45.0, -28.0, (TILT_GOAL_DOWN,)), (12.5, 12.5, ()),
                                                  (58.0, 58.0, ())])
def test_a_tilt_goal_is_clamped_by_the_gate_with_its_reason(asked, written, why):
    sink, gate = GoalSink(), CommandGate(LIMITS)
    gate.head_cmd = HeadCommand(1, 20, 0, 0)      # the head was panning before the homing
    rec = FrameStep(NoController(), gate, sink).own_goal("tilt", asked, "homing")
    assert rec.goal_deg == pytest.approx(written) and rec.limited == why and rec.asked_deg == asked
    assert rec.reached_head and sink.goals == [("tilt", pytest.approx(written), "homing")]
    assert gate.head_cmd == STOP                  # an absolute set replaces the latched motion


def test_pan_is_wrapped_a_bad_goal_is_refused_and_a_failed_write_keeps_the_last_command():
    sink, gate = GoalSink(), CommandGate(LIMITS)
    step = FrameStep(NoController(), gate, sink)
    rec = step.own_goal("pan", 190.0, "homing")
    assert rec.goal_deg == pytest.approx(-170.0) and rec.limited == ()
    rec = step.own_goal("tilt", math.nan, "homing")
    assert rec.goal_deg is None and rec.limited == (TILT_UNKNOWN,) and not rec.reached_head
    assert len(sink.goals) == 1                   # nothing written for the NaN goal
    moving = HeadCommand(-1, 10, 0, 0)
    gate.head_cmd = moving
    rec = FrameStep(NoController(), gate, GoalSink(ok=False)).own_goal("tilt", 10.0, "homing")
    assert not rec.reached_head and gate.head_cmd == moving
    with pytest.raises(ValueError, match="axis"):
        step.own_goal("roll", 0.0, "homing")


class FakeHead:
    connected = True
    tilt_zero = "zenith"

    def __init__(self):
        self.raw = []

    def send_frame(self, raw):
        self.raw.append(bytes(raw))
        return True


def _homing_at_100_s(tmp_path, head, extra: str):
    """An in-process daemon homing to pan 5 deg (``extra``: more [head] keys), its link lost and back
    at host time 100 s."""
    d, _ = inprocess_daemon(tmp_path, head, f'on_reconnect = "home"\nhome_pan_deg = 5.0\nhome_wait_s = 1.0\n{extra}')
    d._pose_unknown(0.0, "link_lost")
    d._reconnected(100.0)
    return d


def test_the_daemons_homing_to_a_goal_beyond_the_stop_writes_the_gates_goal(tmp_path):
    """A home tilt between the margin's line and the stop (59.5 deg; stops -30/60, margin 2: a config
    may set it, the stops are checked, not the margin): the daemon writes the set-tilt to 58 deg, logs
    why, and rebases the tracker there (before, the homing wrote 59.5: its own clamp held bearings only)."""
    head = FakeHead()
    d = _homing_at_100_s(tmp_path, head, 'home_tilt_deg = 59.5\ntilt_limits_deg = [-30.0, 60.0]\ntilt_margin_deg = 2.0')
    try:
        assert d._homing.tilt_deg == 59.5          # the plan asks; the gate decides at the write
        d._pose_tick(100.35)                       # the pan set
        d._pose_tick(100.65)                       # the tilt set
        assert d.pose_state == "homing" and d._homing.tilt_deg == pytest.approx(58.0)
        h = d.cfg.head
        assert head.raw[-2:] == [encode_set_pan(h.address, 5.0, h.protocol),
                                 encode_set_tilt(h.address, 58.0, h.protocol, "zenith")]
        d._pose_tick(101.7)                        # the wait is over
        assert d.pose_state is None
        pan, tilt, _, _ = d.tracker.recon.angles_at(0.0)
        assert (pan, tilt) == pytest.approx((5.0, 58.0))
    finally:
        d.recorder.close()
        d.log.close()
    events = [json.loads(x) for x in (tmp_path / "d.jsonl").read_text().splitlines()]
    homing = [e for e in events if e["event"] == "head_homing"]
    assert [e["axis"] for e in homing] == ["pan", "tilt"]
    assert "limited" not in homing[0]
    assert homing[1]["limited"] == [TILT_GOAL_UP] and homing[1]["asked_deg"] == 59.5
    assert homing[1]["home_deg"] == pytest.approx([5.0, 58.0])
    homed = [e for e in events if e["event"] == "head_homed"]
    assert homed and homed[0]["tilt_deg"] == pytest.approx(58.0)


def test_the_daemons_tilt_set_waits_its_quiet_line_after_a_late_pan_set(tmp_path):
    """The sets were due at fixed times after the reconnect; a tick that wrote the pan set 0.09 s late
    left the tilt set 0.205 s after it, and the head (0.2 s quiet line + the frame on the wire) ignored
    it.  Each set is now due 0.3 s after the previous write."""
    head = FakeHead()
    d = _homing_at_100_s(tmp_path, head, 'home_tilt_deg = 10.0')
    try:
        n0 = len(head.raw)                         # the STOP
        d._pose_tick(100.29)
        assert len(head.raw) == n0                 # the quiet line after the STOP
        d._pose_tick(100.39)                       # a late tick: the pan set
        assert len(head.raw) == n0 + 1
        d._pose_tick(100.6)                        # planned at 100.6 once; 0.21 s after the pan set now
        assert len(head.raw) == n0 + 1
        d._pose_tick(100.69)                       # 0.3 s after it
        assert len(head.raw) == n0 + 2 and head.raw[-1] == encode_set_tilt(d.cfg.head.address, 10.0,
                                                                           d.cfg.head.protocol, "zenith")
    finally:
        d.recorder.close()
        d.log.close()
