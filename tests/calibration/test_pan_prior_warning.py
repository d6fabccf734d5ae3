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

from foveatrack.calibration import CalibrationPlan, FeatureSpec, PriorAxisCalibrator
from foveatrack.calibration.drive import drive_calibration
from foveatrack.frames import Frame
from foveatrack.reconstruction import rotation_matrix

RATE_HZ = 20.0
TRUE_TILT0_DEG = 10.0
CORNER_W = np.array([4.0, 0.5, 1.2])     # world: front wall x = 4, left wall y = 0.5, ceiling z = 1.2


def _roll(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _corner_points(rng, n=400):
    cx, cy, cz = CORNER_W
    u = rng.uniform(0.0, 1.0, (3, n, 2))
    walls = [np.column_stack([np.full(n, cx), cy - u[0, :, 0], cz - u[0, :, 1]]),
             np.column_stack([cx - u[1, :, 0], np.full(n, cy), cz - u[1, :, 1]]),
             np.column_stack([cx - u[2, :, 0], cy - u[2, :, 1], np.full(n, cz)])]
    return np.vstack(walls) + rng.normal(0.0, 0.003, (3 * n, 3))


class _Head:
    def __init__(self):
        self.pan, self.tilt, self.t, self.v = 0.0, TRUE_TILT0_DEG, 0.0, (0.0, 0.0)

    def advance(self, t):
        self.pan += self.v[0] * (t - self.t)
        self.tilt += self.v[1] * (t - self.t)
        self.t = t

    def send(self, t, cmd):
        self.advance(t)
        self.v = (cmd.pan_dir * cmd.pan_byte / 63 * 15.0, cmd.tilt_dir * cmd.tilt_byte / 63 * 2.0)


def _frames(head, rng, roll_deg, max_s=200.0):
    mount = _roll(roll_deg)        # lidar -> tilt stage
    for k in range(int(max_s * RATE_HZ)):
        t0, t1 = k / RATE_HZ, (k + 1) / RATE_HZ
        pts = _corner_points(rng)
        t = np.sort(rng.uniform(t0, t1, len(pts)))
        xyz = np.empty_like(pts)
        for i in range(0, len(pts), 50):      # the head's pose every 2.5 ms across the frame
            head.advance(t[i])
            xyz[i:i + 50] = pts[i:i + 50] @ rotation_matrix(head.pan, head.tilt) @ mount
        head.advance(t1)
        yield Frame(t0, t1, xyz, (t * 1e9).astype(np.int64))


@lru_cache(maxsize=None)
def _pan_warnings(told_tilt0_deg: float, roll_deg: float) -> list[str]:
    head = _Head()
    plan = CalibrationPlan(pan_bytes=(20,), tilt_bytes=(63,), dwell_s=8.0, start_tilt_deg=told_tilt0_deg)
    approx = CORNER_W @ rotation_matrix(0.0, told_tilt0_deg)
    cal = PriorAxisCalibrator(plan, FeatureSpec(tuple(approx), radius_m=1.0), seed=0)
    drive_calibration(cal, _frames(head, np.random.default_rng(3), roll_deg), head.send)
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
