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


class MoveWitness:
    """The witness for a head moved frame by frame by a controller (the daemon's tracker): each move,
    from a still stretch to the next (the head given STOP and settled), is one :class:`TurnWitness`
    move, checked for over-turning while it runs and both ways once the head has settled.

    A driver calls :meth:`samples` with each frame's gyro samples (sensor time, before the frame's
    end) and then :meth:`command` with what the head runs from the frame's send time on.  The turn
    commanded is integrated from the speed table (``direction * speed(byte)`` over each command's time;
    the dead time and the ramps are within the tolerance).  A move that starts without a still stretch
    of :attr:`STILL_MIN_S` before it (the head given a new motion before it settled) is not witnessed
    (counted in :attr:`unwitnessed`).  ``up_guess``: the IMU's up direction where the lidar sends no
    accelerometer readings (the driver's estimate: ``R_imu_lidar R(pan, tilt)^T z``)."""

    SETTLE_S = 1.0      # after a STOP reaches the head: its dead time and deceleration, then still
    STILL_MIN_S = 0.5   # the shortest still stretch a move's bias and up may come from
    KEEP_S = 2.0        # gyro samples kept while still (the newest still stretch)

    def __init__(self, table, R_lidar_imu=None, rel_tol: float = 0.5, abs_tol_deg: float = 3.0):
        self.table = table
        self.witness = TurnWitness(R_lidar_imu, rel_tol, abs_tol_deg)
        self.head = None                 # the command the head runs (None: STOP, as it starts)
        self.cmds: list = []             # (t_s, HeadCommand) of the move under witness
        self.moving = False
        self.still_since = -math.inf     # sensor time since which the head has stood still (at rest at the start)
        self.t_stop = math.inf           # when the move under witness was given STOP
        self._t = np.zeros(0)
        self._g = np.zeros((0, 3))
        self._a = np.zeros((0, 3))
        self.moves_checked = 0
        self.unwitnessed = 0

    def _commanded_deg(self, t_end_s: float) -> dict:
        out = {"pan": 0.0, "tilt": 0.0}
        for k, (t, c) in enumerate(self.cmds):
            t_next = self.cmds[k + 1][0] if k + 1 < len(self.cmds) else t_end_s
            dt = max(0.0, min(t_next, t_end_s) - t)
            for ax, d, b in (("pan", c.pan_dir, c.pan_byte), ("tilt", c.tilt_dir, c.tilt_byte)):
                if d:
                    out[ax] += d * self.table.axis(ax).speed_deg_s(b) * dt
        return out

    def samples(self, t_s, gyro_rad_s, acc=None, up_guess=None) -> None:
        """This frame's gyro samples (and accelerometer's, any unit; None: ``up_guess`` stands for
        them); raises :class:`TurnMismatch` if the move under witness turned far from its command."""
        t = np.asarray(t_s, float)
        if not len(t):
            return
        g = np.asarray(gyro_rad_s, float)
        a = np.asarray(acc, float) if acc is not None else np.tile(np.asarray(up_guess, float), (len(t), 1))
        if self.moving:
            self.witness.add(t, g)
            t_last = float(t[-1])
            commanded = self._commanded_deg(t_last)
            if any(not math.isfinite(v) for v in commanded.values()):
                self.moving = False      # a byte the table does not know: not witnessed
                self.unwitnessed += 1
            elif t_last >= self.t_stop + self.SETTLE_S:
                self.witness.check(commanded, stopped=True)
                self.moving = False
                self.moves_checked += 1
            else:
                self.witness.check(commanded, stopped=False)
        keep = np.concatenate([self._t, t]) >= float(t[-1]) - self.KEEP_S
        self._t = np.concatenate([self._t, t])[keep]
        self._g = np.vstack([self._g, g])[keep]
        self._a = np.vstack([self._a, a])[keep]

    def command(self, t_s: float, cmd) -> None:
        """The head runs ``cmd`` from ``t_s`` on (after the gate and the link)."""
        if cmd == self.head or (self.head is None and cmd.is_stop):
            return
        was_still = self.head is None or self.head.is_stop
        self.head = cmd
        if self.moving:
            self.cmds.append((t_s, cmd))
            if cmd.is_stop:
                self.t_stop = t_s
            elif self.t_stop < math.inf:
                self.t_stop = math.inf   # moving again before it settled: the same move goes on
            return
        if cmd.is_stop:
            self.still_since = t_s + self.SETTLE_S
            return
        if not was_still:
            return
        still = (self._t >= self.still_since) & (self._t < t_s)
        if still.sum() < 10 or self._t[still][-1] - self._t[still][0] < self.STILL_MIN_S:
            self.unwitnessed += 1
            self.still_since = math.inf  # until the head is given STOP again
            return
        self.witness.begin(self._t[still], self._g[still], self._a[still])
        self.cmds, self.t_stop, self.moving = [(t_s, cmd)], math.inf, True
