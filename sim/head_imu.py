"""The scene's IMU on the served head: what a Livox Horizon / Avia on a pan/tilt head streams as data
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

from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from foveatrack.imu_calib.imu_integration import GRAVITY_M_S2
from sim.imu import G_WORLD, ImuNoise

Pose = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


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
    R_wi = R_wl @ X[:3, :3]
    p = R_wl @ X[:3, 3]                                   # (n, 5, 3): IMU positions
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
