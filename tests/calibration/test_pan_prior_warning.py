"""The pan prior's warning names what the corner data contradict: the start tilt, or the lean.

The pan axis prior is ``R_y(tilt0) z``: the start tilt (``tilt0_deg``) turns it in the lidar's XZ
plane, a lidar rolled on the head leans it toward lidar Y, which no start tilt gives.  The warning
used to say "the start tilt disagrees ... set tilt0_deg" whenever the test failed, also for a head
whose tilt0_deg was right and whose lidar sat rolled on it (a user then "fixes" the right tilt0_deg).

The rig is synthetic (as in test_calibration_gate.py): a room corner seen from a head that turns at
the commanded speed (pan 15 deg/s, tilt 2 deg/s at byte 63), the lidar on it rolled ``roll_deg``
about its X axis; one pan and one tilt byte, ~3 s wall a run.
"""

import math
from functools import lru_cache

import numpy as np

from calib_fixture import SyntheticHead, corner_frames
from foveatrack.calibration import CalibrationPlan, FeatureSpec, PriorAxisCalibrator
from foveatrack.calibration.drive import drive_calibration
from foveatrack.reconstruction import rotation_matrix

RATE_HZ = 20.0
TRUE_TILT0_DEG = 10.0
CORNER_W = np.array([4.0, 0.5, 1.2])     # world: front wall x = 4, left wall y = 0.5, ceiling z = 1.2


def _roll(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


@lru_cache(maxsize=None)
def _pan_warnings(told_tilt0_deg: float, roll_deg: float) -> list[str]:
    head = SyntheticHead(TRUE_TILT0_DEG)
    plan = CalibrationPlan(pan_bytes=(20,), tilt_bytes=(63,), dwell_s=8.0, start_tilt_deg=told_tilt0_deg)
    approx = CORNER_W @ rotation_matrix(0.0, told_tilt0_deg)
    cal = PriorAxisCalibrator(plan, FeatureSpec(tuple(approx), radius_m=1.0), seed=0)
    frames = corner_frames(head, np.random.default_rng(3), CORNER_W, RATE_HZ, 200.0, mount=_roll(roll_deg))
    drive_calibration(cal, frames, head.send)
    assert cal.done and cal.failure is None
    return [w for w in cal.report.warnings if "pan axis" in w]


def test_a_lidar_rolled_on_the_head_is_said_to_lean_not_to_be_a_wrong_start_tilt():
    said = _pan_warnings(TRUE_TILT0_DEG, 6.0)
    assert len(said) == 1, said
    w = said[0]
    assert w.startswith("the pan axis leans toward lidar Y"), w
    assert "tilt0_deg is not what is wrong" in w and "set tilt0_deg" not in w, w
    assert "Y axis along the tilt axis" in w, w


def test_a_wrong_start_tilt_is_said_to_be_one_and_the_lean_to_agree():
    said = _pan_warnings(18.0, 0.0)
    assert len(said) == 1, said
    w = said[0]
    assert w.startswith("the start tilt disagrees"), w
    assert "set tilt0_deg" in w and "agrees with the mounting" in w and "Y axis along the tilt axis" not in w, w


def test_both_off_names_both():
    said = _pan_warnings(18.0, 6.0)
    assert len(said) == 1, said
    w = said[0]
    assert w.startswith("the start tilt and the lean toward lidar Y disagree"), w
    assert "set tilt0_deg" in w and "Y axis along the tilt axis" in w, w


def test_a_right_prior_raises_no_pan_warning():
    assert _pan_warnings(TRUE_TILT0_DEG, 0.0) == []
