"""The lidar's IMU on the pan/tilt head, simulated only when the scene has ``[imu]``: one module, two
drivers, two routes to the same kinematics.

* :class:`HeadGyro` (the closed loop, :mod:`sim.loop`): the gyro from the head model's own rates,
  exactly, for the tracker's gyro attitude (``[tracker] attitude = "gyro"``).
* :class:`HeadImu` (``foveatrack lidar serve`` with ``--head-truth``): gyro and accelerometer by
  finite differences of the pose function the served points are cast with (all it has is the head's
  truth file), streamed as Livox data type 6 for ``calibrate-imu --config``.

``tests/imu_calib/test_head_imu.py`` checks that the two routes agree on one head motion.

The closed loop's gyro
----------------------

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

The served IMU
--------------

The scene's IMU on the served head: what a Livox Horizon / Avia on a pan/tilt head streams as data
type 6 while the head moves (``foveatrack lidar serve`` with a scene ``[imu]`` and ``--head-truth``).

The rig: the lidar's optical centre on the head's rotation centre (as :mod:`sim.lidar_server` casts
it), its attitude ``R_world_lidar = Rz(pan) Ry(-tilt)`` (:func:`sim.world.kernels.rotate_pan_tilt_kernel`),
the IMU rigidly at ``X = T_lidar_imu`` (the scene's ``[imu]``, :class:`sim.imu.ImuSpec`).  So the IMU's
attitude is ``R_world_lidar R_X`` and its position ``R_world_lidar t_X``: it swings on an arc of radius
``|t_X|`` about the head's centre, which is what makes ``t_X`` observable from the accelerometer.

Kinematics from the same pose function the served lidar uses (``pose(t_s) -> (pan_deg, tilt_deg)``,
the head truth interpolated linearly between its lines), by finite differences over ``h`` = one IMU
period (5 ms) about each sample time ``t``:

* body rate: ``Log(R_world_imu(t - h/2)^T R_world_imu(t + h/2)) / h`` [rad/s];
* acceleration: ``(p(t + h) - 2 p(t) + p(t - h)) / h^2`` [m/s^2] (the IMU's position ``p``), so the
  trapezoidal double integral of the samples over a move from rest to rest telescopes back to the
  displacement the lidar's poses imply; specific force ``R_world_imu(t)^T (a - g)``.

Both therefore agree with the lidar's poses to the pose function's own interpolation error (a truth
line every 20 ms: ``accel * dt^2 / 8`` = 0.002 deg at 40 deg/s^2), zero at rest.  The differences need
the pose ``h`` after ``t``: the served IMU runs ``imu_lag_s`` behind the points (the virtual lidar's
``imu_lag_s``) so the head truth covers it.

Noise: the scene's :class:`sim.imu.ImuNoise` (white noise, a bias drawn once, bias random walk), the
same model as :func:`sim.imu.simulate_imu`, drawn here per served batch from one stream (the scene's
seed, key ``"imu"``), in the order gyro bias, accel bias (once), then per batch gyro walk, accel walk,
gyro white, accel white.  Units out: gyro [rad/s], specific force [g] (the Livox IMU packet's).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from foveatrack.fixed_order import mats3_times_mat3, mats3_times_vec3, rows_times_mat3T
from foveatrack.gyro_attitude import euler_xyz_matrix
from foveatrack.imu_calib.imu_integration import GRAVITY_M_S2
from sim.effects import effect_rng
from sim.imu import G_WORLD, ImuNoise

Pose = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


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
        w = rows_times_mat3T(w, self.R_imu_lidar)   # w @ R.T, the same bits on every CPU
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


def head_rotations(pan_deg: np.ndarray, tilt_deg: np.ndarray) -> np.ndarray:
    """``R_world_lidar = Rz(pan) Ry(-tilt)`` per sample, (n, 3, 3): the rotation
    :func:`sim.world.kernels.rotate_pan_tilt_kernel` applies to beam directions."""
    p, t = np.radians(np.asarray(pan_deg, float)), np.radians(np.asarray(tilt_deg, float))
    cp, sp, ct, st = np.cos(p), np.sin(p), np.cos(t), np.sin(t)
    R = np.zeros((len(p), 3, 3))
    # Ry(-t) = [[ct, 0, -st], [0, 1, 0], [st, 0, ct]]; Rz(p) = [[cp, -sp, 0], [sp, cp, 0], [0, 0, 1]]
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = cp * ct, -sp, -cp * st
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = sp * ct, cp, -sp * st
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = st, 0.0, ct
    return R


def head_imu_truth(pose: Pose, X: np.ndarray, t_s: np.ndarray, h_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free ``(gyro (n,3) [rad/s], specific force (n,3) [m/s^2])`` of an IMU at ``X`` on the
    head whose pose is ``pose`` (see the module docstring), at times ``t_s`` [s]."""
    t = np.asarray(t_s, float)
    n = len(t)
    offs = np.array([-h_s, -h_s / 2, 0.0, h_s / 2, h_s])
    pan, tilt = pose((t[:, None] + offs[None, :]).reshape(-1))
    R_wl = head_rotations(pan, tilt).reshape(n, 5, 3, 3)
    R_wi = mats3_times_mat3(R_wl, X[:3, :3])              # R_wl @ X_R, not BLAS's per-CPU order
    p = mats3_times_vec3(R_wl, X[:3, 3])                  # (n, 5, 3): IMU positions
    rel = np.einsum("nji,njk->nik", R_wi[:, 1], R_wi[:, 3])   # R(t - h/2)^T R(t + h/2)
    gyro = Rotation.from_matrix(rel).as_rotvec().reshape(n, 3) / h_s
    a = (p[:, 4] - 2 * p[:, 2] + p[:, 0]) / h_s**2
    f = np.einsum("nji,nj->ni", R_wi[:, 2], a - G_WORLD)
    return gyro, f


class HeadImu:
    """``imu_source`` of :class:`sim.virtual_lidar.VirtualLivox`: the scene's IMU on the head.

    pose : stream time [s] -> (pan_deg, tilt_deg), the served lidar's own pose function
    X : 4 x 4 ``T_lidar_imu`` (the scene's true mount)
    noise : :class:`sim.imu.ImuNoise`; rng : the IMU's random stream
    """

    def __init__(self, pose: Pose, X: np.ndarray, noise: ImuNoise, rng: np.random.Generator):
        self.pose, self.X, self.noise, self.rng = pose, np.asarray(X, float), noise, rng
        self.h_s = 1.0 / noise.rate_hz
        self._bg = rng.normal(0, np.radians(noise.gyro_bias_sigma_deg_s), 3)
        self._ba = rng.normal(0, noise.accel_bias_sigma_mg * 1e-3 * GRAVITY_M_S2, 3)

    def __call__(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t_s = np.asarray(t_ns, dtype=np.int64) * 1e-9
        n = len(t_s)
        if n == 0:
            return np.zeros((0, 3)), np.zeros((0, 3))
        nz, dt, rng = self.noise, self.h_s, self.rng
        gyro, f = head_imu_truth(self.pose, self.X, t_s, self.h_s)
        wg = rng.normal(0, np.radians(nz.gyro_bias_walk_deg_s_rts) * np.sqrt(dt), (n, 3))
        wa = rng.normal(0, nz.accel_bias_walk_ug_rts * 1e-6 * GRAVITY_M_S2 * np.sqrt(dt), (n, 3))
        bg = self._bg + np.cumsum(wg, axis=0)
        ba = self._ba + np.cumsum(wa, axis=0)
        self._bg, self._ba = bg[-1], ba[-1]
        gyro = gyro + bg + rng.normal(0, nz.gyro_sigma_rad_s, (n, 3))
        f = f + ba + rng.normal(0, nz.accel_sigma_m_s2, (n, 3))
        return gyro, f / GRAVITY_M_S2
