"""The turn witness (foveatrack.turn_witness): the gyro's turn about each head axis, against the command.

Synthetic IMU samples from the body-rate formula of sim/head_imu.py (``omega_lidar = (p' sin t, -t',
p' cos t)``), through an IMU mounted a few degrees off the lidar's axes, with a gyro bias and the
accelerometer's specific force at rest (``R^T (0, 0, g)``).
"""

import math

import numpy as np
import pytest

from foveatrack.gyro_attitude import euler_xyz_matrix
from foveatrack.turn_witness import TurnMismatch, TurnWitness

R_LI = euler_xyz_matrix((1.5, -2.0, 3.0))     # IMU -> lidar
BIAS = np.radians([0.4, -0.7, 0.3])


def _samples(t0, t1, tilt0_deg, pan_rate, tilt_rate, hz=200.0):
    t = np.arange(t0, t1, 1.0 / hz)
    tilt = np.radians(tilt0_deg + tilt_rate * (t - t0))
    p, q = math.radians(pan_rate), math.radians(tilt_rate)
    w_lidar = np.column_stack([p * np.sin(tilt), np.full_like(t, -q), p * np.cos(tilt)])
    w_imu = w_lidar @ R_LI + BIAS                      # R_LI^T w (row vectors)
    up_lidar = np.column_stack([np.sin(tilt), np.zeros_like(t), np.cos(tilt)])
    return t, w_imu, up_lidar @ R_LI                   # acc [g] = up in the IMU frame


def _witness(tilt0_deg=35.0):
    w = TurnWitness(R_LI)
    t, g, a = _samples(0.0, 2.0, tilt0_deg, 0.0, 0.0)   # still: bias and up
    w.begin(t, g, a)
    return w


def test_the_witness_measures_each_axis_and_passes_a_turn_as_commanded():
    w = _witness()
    t, g, _ = _samples(2.0, 4.0, 35.0, 10.0, -4.0)      # 2 s: pan +20, tilt -8
    w.add(t, g)
    assert w.turned_deg["pan"] == pytest.approx(20.0, abs=0.3) and w.turned_deg["tilt"] == pytest.approx(-8.0, abs=0.1)
    w.check({"pan": 20.0, "tilt": -8.0}, stopped=True)
    w.check({"pan": 12.0, "tilt": -6.0}, stopped=True)   # a table 30 % off passes


def test_an_over_turn_stops_the_move_and_names_the_axis_and_both_turns():
    w = _witness()
    t, g, _ = _samples(2.0, 3.0, 35.0, 0.0, 15.0)       # tilting 15 deg/s where 2 was commanded
    w.add(t, g)
    with pytest.raises(TurnMismatch, match=r"turned tilt \+15\.0 deg where \+2\.0 deg was commanded so far.*far more"):
        w.check({"pan": 0.0, "tilt": 2.0}, stopped=False)


def test_an_under_turn_is_an_error_once_stopped_not_while_moving():
    w = _witness()
    t, g, _ = _samples(2.0, 3.0, 35.0, 1.0, 0.0)        # pan 1 deg where 10 were commanded
    w.add(t, g)
    w.check({"pan": 10.0, "tilt": 0.0}, stopped=False)  # lagging: not judged while the move runs
    with pytest.raises(TurnMismatch, match=r"turned pan \+1\.0 deg where \+10\.0 deg was commanded \(.*far less"):
        w.check({"pan": 10.0, "tilt": 0.0}, stopped=True)
    # a turn the wrong way is far off too
    w2 = _witness()
    t, g, _ = _samples(2.0, 3.0, 35.0, -10.0, 0.0)
    w2.add(t, g)
    with pytest.raises(TurnMismatch, match="pan"):
        w2.check({"pan": 10.0}, stopped=True)
