"""The speed-table calibration keeps its head from the tilt stops (issue 25).

The calibration driver reports the head's tilt as the procedure sees it (the start tilt plus the corner's
turn about the tilt axis), so the command gate's tilt stop fires; a command the gate changes ends the run
with an error naming why (a leg cut short would be timed and measured wrong).  Before, the driver gave
NaN, every comparison with a stop was False, and "tilt up at the stop" passed unchanged.

The frame source is a room corner (front wall, left wall, ceiling) seen from a head that turns at the
commanded speed (pan 15 deg/s, tilt 2 deg/s at byte 63, linear, no dead time: the kinematics only
matter for where the corner appears) and holds at its true stop, 60 deg; the sink is that head.  It
starts at tilt 50 deg, so the calibration's first tilt leg (up, at most 15 deg) would pass 58, the
gate's stop less its 2 deg margin.
"""

import math

import numpy as np
import pytest

from calib_fixture import SyntheticHead, corner_frames
from foveatrack.calibration import CalibrationPlan, FeatureSpec, PriorAxisCalibrator
from foveatrack.calibration.drive import drive_calibration
from foveatrack.errors import UserError
from foveatrack.frames import Frame
from foveatrack.gate import CommandGate, Limits
from foveatrack.reconstruction import rotation_matrix

RATE_HZ = 20.0
TILT0_DEG, TILT_STOP_DEG, MARGIN_DEG = 50.0, 60.0, 2.0
CORNER_W = np.array([4.0, 0.5, 5.0])     # world: front wall x = 4, left wall y = 0.5, ceiling z = 5


def test_the_tilt_stop_fires_in_the_speed_table_calibration():
    rng = np.random.default_rng(3)
    head = SyntheticHead(TILT0_DEG, TILT_STOP_DEG)
    plan = CalibrationPlan(pan_bytes=(20,), tilt_bytes=(63,), dwell_s=8.0, start_tilt_deg=TILT0_DEG)
    approx = CORNER_W @ rotation_matrix(0.0, TILT0_DEG)
    cal = PriorAxisCalibrator(plan, FeatureSpec(tuple(approx), radius_m=1.0), seed=0)
    gate = CommandGate(Limits(tilt_limits_deg=(-30.0, TILT_STOP_DEG), tilt_margin_deg=MARGIN_DEG))
    with pytest.raises(UserError) as err:
        drive_calibration(cal, corner_frames(head, rng, CORNER_W, RATE_HZ, 60.0), head.send, gate=gate)
    msg = str(err.value)
    assert "tilt_stop_up" in msg and "no table was written" in msg, msg
    # it fired on the tilt leg, before the head reached the gate's margin, and the head was stopped
    assert any(leg.axis == "tilt" for leg in cal.legs)
    assert head.max_tilt < TILT_STOP_DEG - MARGIN_DEG + 0.2, head.max_tilt
    assert head.v == (0.0, 0.0)
    est = float(msg.split("estimated tilt ")[1].split(" ")[0])
    assert abs(est - head.tilt) < 0.5, (est, head.tilt)     # the corner's estimate is the head's tilt


def test_without_a_finite_tilt_the_gate_refuses_tilt_and_says_why():
    from foveatrack.control import HeadCommand
    from foveatrack.gate import TILT_UNKNOWN, Proposal

    gate = CommandGate(Limits(tilt_limits_deg=(-30.0, 60.0)))
    for tilt, sigma in ((math.nan, 0.0), (10.0, math.nan), (math.inf, 0.0)):
        cmd, why = gate.decide(None, Proposal(HeadCommand(1, 5, 1, 5), tilt, sigma), 0.0)
        assert cmd == HeadCommand(1, 5, 0, 0) and why == [TILT_UNKNOWN]
    # pan alone needs no tilt estimate
    assert gate.decide(None, Proposal(HeadCommand(1, 5, 0, 0), math.nan, math.nan), 0.0) == (HeadCommand(1, 5, 0, 0), [])


def test_the_tilt_estimate_outlives_the_corner_unless_the_tilt_moves_unseen():
    # the corner last seen at t = 0; pan legs (any length) leave the tilt where it was, but more than
    # TILT_UNSEEN_MAX_S of tilt motion out of sight voids the estimate (the gate then refuses tilt)
    from types import SimpleNamespace

    from foveatrack.calibration.drive import CalibrationDriver
    from foveatrack.calibration.procedure import TILT_UNSEEN_MAX_S
    from foveatrack.control import HeadCommand

    commands = iter([HeadCommand(1, 20, 0, 0)] * 30 + [HeadCommand(0, 0, 1, 63)] * 30)
    cal = SimpleNamespace(start_tilt_deg=lambda: (10.0, 0.5, False), done=False,
                          step=lambda frame: next(commands), tilt_since_start_deg=lambda t: (1.0, 0.1, 0.0))
    driver = CalibrationDriver(cal)
    tilts = []
    for k in range(60):
        frame = Frame(k / RATE_HZ, (k + 1) / RATE_HZ, np.zeros((0, 3)), np.zeros(0, np.int64))
        tilts.append(driver.process(frame, frame.t_end_s).head_tilt_deg)
    assert all(t == 11.0 for t in tilts[:30])                       # 1.5 s of pan, the corner unseen
    first_nan = next(k for k, t in enumerate(tilts) if math.isnan(t))
    assert (first_nan - 30) / RATE_HZ == pytest.approx(TILT_UNSEEN_MAX_S, abs=2 / RATE_HZ)
