"""The lidar's gyro on the head in a closed loop, simulated only when the scene has ``[imu]``.

The lidar sits on the head's tilt stage and its IMU rigidly with it (``[imu] rotation_deg``: the IMU's
mount in the lidar frame, as for the lidar-IMU calibration, :mod:`sim.imu`).  The lidar's attitude in
the world is ``R = R_z(pan) R_y(-tilt)`` (:mod:`foveatrack.reconstruction`), so its body rate is

.. math:: \\omega_{lidar} = R^T \\omega_{world}
          = (\\dot p \\sin t,\\; -\\dot t,\\; \\dot p \\cos t) \\quad [rad/s]

(pan about the world vertical, tilt about the pan-turned y axis) with the head's true rates and
tilt at the sample's time (:meth:`gimbal.pts303h.PTS303H.rates_at`, the speed ripple included when
the scene lists it).  The gyro reads ``R_{lidar,imu}^T \\omega_{lidar} + b(t) + n`` with the noise
model and BMI088 numbers of :mod:`sim.imu` (bias drawn once per run, its random walk, white noise),
at ``[imu] rate_hz`` on the frames' clock, ``t_k = k / rate_hz``.  The accelerometer is not
simulated here (the tracker uses only the gyro).

Before the first frame the IMU streams for ``[imu] rest_before_s`` with the head at rest at its start
pose (the daemon starts the lidar and waits for a target): those samples come with the first frame.

Randomness: the gyro's own stream (``sim.effects.effect_rng(seed, "head_imu")``), drawn in a fixed
order (the bias once, then per frame the walk increments and the white noise of that frame's
samples), so a scene without ``[imu]`` draws nothing and gives the same bits as before, and adding
``[imu]`` changes no other effect's draws.
"""

from __future__ import annotations

import math

import numpy as np

from foveatrack.gyro_attitude import euler_xyz_matrix
from sim.effects import effect_rng


def lidar_body_rate_rad_s(pan_rate_deg_s, tilt_deg, tilt_rate_deg_s) -> np.ndarray:
    """(N, 3) body rate of the lidar [rad/s] from the head's rates and tilt (module docstring)."""
    pr = np.radians(np.asarray(pan_rate_deg_s, float))
    tr = np.radians(np.asarray(tilt_rate_deg_s, float))
    t = np.radians(np.asarray(tilt_deg, float))
    return np.stack([pr * np.sin(t), -tr, pr * np.cos(t)], axis=-1)


class HeadGyro:
    """Gyro samples from the head's true motion, frame by frame (``samples_until``)."""

    def __init__(self, spec, seed: int, tilt0_deg: float, white: bool = True, bias: bool = True):
        self.noise = spec.noise
        self.rate_hz = float(spec.noise.rate_hz)
        self.R_imu_lidar = euler_xyz_matrix(spec.rotation_deg).T
        self.tilt0_deg = tilt0_deg
        self.white = white
        self.bias_on = bias
        self.rng = effect_rng(seed, "head_imu")
        n = self.noise
        self.bias0_rad_s = self.rng.normal(0.0, math.radians(n.gyro_bias_sigma_deg_s), 3)
        self._bias = self.bias0_rad_s.copy()    # the bias at the last sample drawn
        self._walk_sigma = math.radians(n.gyro_bias_walk_deg_s_rts) * math.sqrt(1.0 / self.rate_hz)
        self._k_next = -int(round(spec.rest_before_s * self.rate_hz))
        self._first = True
        self.true_bias_rad_s: np.ndarray | None = None   # the bias at each sample of the last batch

    def samples_until(self, head, t1_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The samples at ``k / rate_hz < t1_s`` not yet given: ``(t_s (N,), gyro_rad_s (N, 3))`` in the
        IMU frame.  Ask after the commands arriving before ``t1_s`` reached ``head``."""
        k1 = math.ceil(t1_s * self.rate_hz - 1e-9)
        k = np.arange(self._k_next, k1)
        self._k_next = max(self._k_next, k1)
        t = k / self.rate_hz
        if t.size == 0:
            return t, np.empty((0, 3))
        w = np.zeros((t.size, 3))
        moving = t >= 0.0          # before the run the head rests at its start pose
        if moving.any():
            tm = t[moving]
            _, tilt = head.angles_at(tm, wrap_pan=False)
            vp, vt = head.rates_at(tm)
            w[moving] = lidar_body_rate_rad_s(vp, tilt, vt)
        w = w @ self.R_imu_lidar.T
        # the walk's first increment is after the first sample (the bias at it is bias0)
        walk = self.rng.normal(0.0, self._walk_sigma, (t.size, 3))
        if self._first:
            walk[0] = 0.0
            self._first = False
        bias = self._bias + np.cumsum(walk, axis=0)
        self._bias = bias[-1].copy()
        white = self.rng.normal(0.0, self.noise.gyro_sigma_rad_s, (t.size, 3))
        self.true_bias_rad_s = bias
        out = w
        if self.bias_on:
            out = out + bias
        if self.white:
            out = out + white
        return t, out
