"""A witness of the head's turns: what the lidar's gyro measured against what was commanded, per axis.

The head reports nothing, so every driver that moves it dead-reckons from its speed table.  A head that
turns far more or less than it was told -- a slipping worm gear, a wrong speed table, another head on
the port (a ``heavy-worm`` tilting 15 deg/s where a PTS-303's table says 2 drove the live IMU
calibration's 10 deg steps 77 deg each, past the tilt limit) -- is seen by the gyro of a lidar that
carries one (Horizon, Avia, Tele-15; on the tilt stage, so it turns with the head).  Where a driver has
it, :class:`TurnWitness` stops the run with an error naming the axis, the commanded and the measured
turn.

Axes (the convention of :mod:`foveatrack.reconstruction`, ``R = R_z(pan) R_y(-tilt)``, lidar -> world):
the body rate of the lidar is ``omega = R^T (pan_dot z_world) - tilt_dot y_lidar``, so
``tilt_dot = -omega . y_lidar`` (the tilt axis is fixed in the lidar frame) and ``pan_dot = omega . up``
with ``up = R^T z_world``, the direction the accelerometer reads at rest (its specific force is ``+g``
up).  Rates come in the IMU frame and are turned into the lidar's by the mount ``R_lidar_imu`` (a few
degrees from identity: the tolerances below dwarf it).  The bias is the gyro's mean over the last
stretch the head stood still (the BMI088's zero-rate offset, up to 1 deg/s, would otherwise add 5 deg
over a 5 s move).

Tolerance: a turn is "far" off when it differs from the commanded one by more than ``abs_tol_deg`` plus
``rel_tol`` of it (3 deg + 50 %: the dead time and the ramps, a few tenths of a degree, and a table
error of 30 % pass; 77 for 10 does not).  While a move runs only over-turning is checked, against the
turn commanded so far (the measurement lags it: dead time, ramp, the IMU's packets in flight, which
can only hide an over-turn, never fake one); once the head has stopped, both ways.
"""

from __future__ import annotations

import math

import numpy as np

from foveatrack.errors import UserError

AXES = ("pan", "tilt")


class TurnMismatch(UserError):
    """The head turned far more or less than commanded (the message names the axis and both turns)."""


class TurnWitness:
    """Integrates the bias-corrected gyro about the head's two axes over one move (see module docstring).

    R_lidar_imu : (3, 3) the IMU's mount (IMU -> lidar), default identity (Livox mounts it so)
    rel_tol, abs_tol_deg : how far off a turn may be before it is an error
    """

    def __init__(self, R_lidar_imu=None, rel_tol: float = 0.5, abs_tol_deg: float = 3.0):
        self.R = np.eye(3) if R_lidar_imu is None else np.asarray(R_lidar_imu, float)[:3, :3]
        self.rel_tol, self.abs_tol_deg = float(rel_tol), float(abs_tol_deg)
        self.axes_imu: np.ndarray | None = None   # (2, 3): pan's and tilt's rate as a dot product in the IMU frame
        self.bias = np.zeros(3)
        self.turned_deg = {a: 0.0 for a in AXES}
        self._last_t: float | None = None
        self._last_w: np.ndarray | None = None

    def begin(self, t_s, gyro_rad_s, acc) -> None:
        """Start a move from the samples of the still stretch before it (``t_s`` (N,) [s], ``gyro_rad_s``
        (N, 3), ``acc`` (N, 3) any unit, IMU frame): bias from the mean rate, up from the mean
        specific force.  Integration starts after the stretch's last sample."""
        g = np.asarray(gyro_rad_s, float)
        a = np.asarray(acc, float)
        if len(g) < 10:
            raise UserError(f"the turn witness needs the gyro at rest before a move; got {len(g)} samples")
        self.bias = g.mean(axis=0)
        up_imu = a.mean(axis=0)
        up_imu = up_imu / np.linalg.norm(up_imu)
        y_imu = self.R.T @ np.array([0.0, 1.0, 0.0])
        self.axes_imu = np.vstack([up_imu, -y_imu])
        self.turned_deg = {ax: 0.0 for ax in AXES}
        self._last_t, self._last_w = float(t_s[-1]), np.zeros(2)

    def add(self, t_s, gyro_rad_s) -> None:
        """Gyro samples in time order (any before the last one added are skipped): trapezoids of the
        bias-corrected rate about each axis."""
        if self.axes_imu is None:
            return
        t = np.asarray(t_s, float)
        keep = t > self._last_t
        if not keep.any():
            return
        t = np.concatenate([[self._last_t], t[keep]])
        w = np.vstack([self._last_w, (np.asarray(gyro_rad_s, float)[keep] - self.bias) @ self.axes_imu.T])
        area = 0.5 * ((w[1:] + w[:-1]) * np.diff(t)[:, None]).sum(axis=0)
        for i, ax in enumerate(AXES):
            self.turned_deg[ax] += math.degrees(float(area[i]))
        self._last_t, self._last_w = float(t[-1]), w[-1]

    def _far(self, commanded_deg: float, measured_deg: float) -> bool:
        return abs(measured_deg - commanded_deg) > self.abs_tol_deg + self.rel_tol * abs(commanded_deg)

    def check(self, commanded_deg: dict, stopped: bool) -> None:
        """Raise :class:`TurnMismatch` if an axis turned far from ``commanded_deg`` (``{"pan": deg,
        "tilt": deg}``, signed: pan + left, tilt + up): ``stopped`` False while the move runs (over-turn
        only, against what was commanded so far), True once the head is still (both ways)."""
        for ax in AXES:
            c, m = float(commanded_deg.get(ax, 0.0)), self.turned_deg[ax]
            over = abs(m) > abs(c) and self._far(c, m)
            if over or (stopped and self._far(c, m)):
                raise TurnMismatch(
                    f"the head turned {ax} {m:+.1f} deg where {c:+.1f} deg was commanded"
                    f"{'' if stopped else ' so far'} (measured by the lidar's gyro; allowed "
                    f"{self.abs_tol_deg:g} deg + {100 * self.rel_tol:.0f} %): far {'more' if abs(m) > abs(c) else 'less'} "
                    "than the speed table says -- another head on the port, a wrong [head] speed_table or a "
                    "slipping gear")
