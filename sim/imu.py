"""An IMU rigidly mounted with the lidar (paper Section IV.A, Fig. 11a), simulated only when a scene
has an ``[imu]`` table.

Noise model (the continuous-time model of Kalibr's "IMU Noise Model" wiki, after IEEE Std 952-1997):
each axis reads ``truth + b(t) + n``, white noise ``n`` of standard deviation
``noise_density * sqrt(rate_hz)`` per sample, bias ``b(t) = b0 + random walk`` with increments of
standard deviation ``bias_walk * sqrt(dt)``; ``b0`` is drawn once per run (1-sigma below).

Numbers: Livox's Horizon and Avia carry a Bosch BMI088 (Livox's product specifications list it; the
lidar streams it at 200 Hz as data type 6, ``shared/facts/livox.md``).  From the BMI088 data sheet
(Bosch Sensortec BST-BMI088-DS001, Table 1-2; typical values):

=========================  ========================  =================================
quantity                   data sheet (typical)      here
=========================  ========================  =================================
gyro output noise density  0.014 deg/s/sqrt(Hz)      ``gyro_noise_density_deg_s_rthz``
gyro zero-rate offset      +-1 deg/s                 ``gyro_bias_sigma_deg_s`` = 0.5 (1-sigma)
accel output noise         175 ug/sqrt(Hz)           ``accel_noise_density_ug_rthz``
accel zero-g offset        +-20 mg                   ``accel_bias_sigma_mg`` = 10 (1-sigma)
=========================  ========================  =================================

The data sheet gives no bias random walk; ``gyro_bias_walk_deg_s_rts`` = 0.001 deg/s/sqrt(s) and
``accel_bias_walk_ug_rts`` = 50 ug/sqrt(s) are our assumptions (of the order Kalibr users report for
consumer MEMS IMUs of this class); a scene may override any of them.  The BMI088 numbers were taken
from the data sheet's published typical values and were not re-checked against the PDF here.

Frames: the scene gives the IMU's pose in the lidar frame, ``X = T_lidar_imu`` (rotation as
roll/pitch/yaw [deg] about the lidar's x, y, z, applied in that order: ``R = Rz(yaw) Ry(pitch)
Rx(roll)``; translation [m]), the unknown the calibration recovers (``A X = X B``).  Gravity is
``(0, 0, -9.80665)`` m/s^2 in the world (z up); Earth's rotation is not simulated.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy.spatial.transform import Rotation

from foveatrack.config_util import as_float, as_vec, check_keys
from foveatrack.errors import UserError
from foveatrack.fixed_order import mats3_times_mat3
from foveatrack.imu_calib.imu_integration import GRAVITY_M_S2, ImuSamples
from foveatrack.imu_calib.se3 import make_T, so3_exp, so3_log

G_WORLD = np.array([0.0, 0.0, -GRAVITY_M_S2])


def pose_T(rpy_deg, t_m) -> np.ndarray:
    """4 x 4 pose from roll/pitch/yaw [deg] (scipy's extrinsic "xyz", the scene files' convention)
    and a translation [m]."""
    return make_T(Rotation.from_euler("xyz", rpy_deg, degrees=True).as_matrix(), t_m)


@dataclass(frozen=True)
class ImuNoise:
    """Noise of one IMU (defaults: BMI088, see the module docstring)."""

    rate_hz: float = 200.0
    gyro_noise_density_deg_s_rthz: float = 0.014
    gyro_bias_sigma_deg_s: float = 0.5
    gyro_bias_walk_deg_s_rts: float = 0.001
    accel_noise_density_ug_rthz: float = 175.0
    accel_bias_sigma_mg: float = 10.0
    accel_bias_walk_ug_rts: float = 50.0

    @property
    def gyro_sigma_rad_s(self) -> float:
        """Per-sample white-noise standard deviation [rad/s]."""
        return float(np.radians(self.gyro_noise_density_deg_s_rthz) * np.sqrt(self.rate_hz))

    @property
    def accel_sigma_m_s2(self) -> float:
        return float(self.accel_noise_density_ug_rthz * 1e-6 * GRAVITY_M_S2 * np.sqrt(self.rate_hz))


@dataclass(frozen=True)
class ImuSpec:
    """The scene's ``[imu]``: the true mount, the nominal one (the drawing's, which seeds the
    registration), and the noise."""

    rotation_deg: tuple = (0.0, 0.0, 0.0)
    translation_m: tuple = (0.0, 0.0, 0.0)
    nominal_rotation_deg: tuple = (0.0, 0.0, 0.0)
    nominal_translation_m: tuple = (0.0, 0.0, 0.0)
    noise: ImuNoise = field(default_factory=ImuNoise)
    # In a closed loop (sim/head_imu.py): how long the IMU streams, the head at rest at its start
    # pose, before the run's first frame (the daemon starts the lidar and waits for a target) [s].
    rest_before_s: float = 5.0

    @property
    def T_lidar_imu(self) -> np.ndarray:
        return pose_T(self.rotation_deg, self.translation_m)

    @property
    def nominal_T_lidar_imu(self) -> np.ndarray:
        return pose_T(self.nominal_rotation_deg, self.nominal_translation_m)


@dataclass(frozen=True)
class PoseSchedule:
    """The scene's ``[imu_poses]``: the static-pose sequence of Section IV.A."""

    count: int = 13
    step_deg: float = 10.0
    step_m: float = 0.10
    dwell_s: float = 10.0
    move_s: float = 1.0
    home_rpy_deg: tuple = (0.0, 0.0, 0.0)   # the lidar's home pose in the world (roll/pitch/yaw as [imu])
    home_m: tuple = (0.0, 0.0, 0.0)

    @property
    def T_world_home(self) -> np.ndarray:
        return pose_T(self.home_rpy_deg, self.home_m)

    def windows(self) -> list[tuple[float, float]]:
        per = self.dwell_s + self.move_s
        return [(i * per, i * per + self.dwell_s) for i in range(self.count)]

    @property
    def duration_s(self) -> float:
        return self.count * self.dwell_s + (self.count - 1) * self.move_s


_NOISE_KEYS = [k for k in ImuNoise.__dataclass_fields__]


def imu_from_table(t: Mapping, where: str) -> ImuSpec:
    check_keys(t, ["rotation_deg", "translation_m", "nominal_rotation_deg", "nominal_translation_m", "rest_before_s"]
               + _NOISE_KEYS, where)
    kw = {}
    if "rest_before_s" in t:
        kw["rest_before_s"] = as_float(t["rest_before_s"], "rest_before_s", where, lo=0, hi=600)
    for k in ("rotation_deg", "nominal_rotation_deg"):
        if k in t:
            v = as_vec(t[k], k, where, 3)
            if max(abs(x) for x in v) > 180:
                raise UserError(f"{where}: {k} angles must be within +-180 deg, got {list(v)}")
            kw[k] = v
    for k in ("translation_m", "nominal_translation_m"):
        if k in t:
            v = as_vec(t[k], k, where, 3)
            if max(abs(x) for x in v) > 2.0:
                raise UserError(f"{where}: {k} must be within +-2 m of the lidar (a rigid mount), got {list(v)}")
            kw[k] = v
    nk = {}
    for k in _NOISE_KEYS:
        if k in t:
            lo_open = k == "rate_hz"
            nk[k] = as_float(t[k], k, where, lo=0, lo_open=lo_open, hi=2000.0 if k == "rate_hz" else None)
    return ImuSpec(**kw, noise=ImuNoise(**nk))


def poses_from_table(t: Mapping, where: str) -> PoseSchedule:
    check_keys(t, ["count", "step_deg", "step_m", "dwell_s", "move_s", "home_rpy_deg", "home_m"], where)
    kw = {}
    if "count" in t:
        c = t["count"]
        if isinstance(c, bool) or not isinstance(c, int) or not 3 <= c <= 200:
            raise UserError(f"{where}: count must be an integer in [3, 200] (static poses), got {c!r}")
        kw["count"] = c
    if "step_deg" in t:
        kw["step_deg"] = as_float(t["step_deg"], "step_deg", where, lo=0, hi=45)
    if "step_m" in t:
        kw["step_m"] = as_float(t["step_m"], "step_m", where, lo=0, hi=1.0)
    if "dwell_s" in t:
        kw["dwell_s"] = as_float(t["dwell_s"], "dwell_s", where, lo=0.1, hi=600)
    if "move_s" in t:
        kw["move_s"] = as_float(t["move_s"], "move_s", where, lo=0.2, hi=60)
    if "home_rpy_deg" in t:
        kw["home_rpy_deg"] = as_vec(t["home_rpy_deg"], "home_rpy_deg", where, 3)
    if "home_m" in t:
        kw["home_m"] = as_vec(t["home_m"], "home_m", where, 3)
    return PoseSchedule(**kw)


class RigTrajectory:
    """The IMU's pose in the world: static at ``T_world_imu[i]`` during window i, moving between
    with a minimum-jerk profile ``s(u) = 10u^3 - 15u^4 + 6u^5`` (rotation about a fixed body axis,
    translation along a line), so rates and accelerations are exact and smooth."""

    def __init__(self, poses_world_imu: list[np.ndarray], dwell_s: float, move_s: float):
        self.poses = poses_world_imu
        self.dwell_s = dwell_s
        self.move_s = move_s
        self._phi = [so3_log(mats3_times_mat3(a[:3, :3].T, b[:3, :3]))   # not BLAS's per-CPU order
                     for a, b in zip(poses_world_imu, poses_world_imu[1:])]

    def _segment(self, t: np.ndarray):
        per = self.dwell_s + self.move_s
        i = np.clip(np.floor(t / per).astype(int), 0, len(self.poses) - 1)
        tau = t - i * per - self.dwell_s
        moving = (tau > 0) & (i < len(self.poses) - 1)
        u = np.where(moving, np.clip(tau / self.move_s, 0, 1), 0.0)
        return i, moving, u

    def truth(self, t: np.ndarray):
        """``(R_world_imu (N,3,3), p (N,3), omega_body (N,3) [rad/s], a_world (N,3) [m/s^2])``."""
        i, moving, u = self._segment(t)
        s = 10 * u**3 - 15 * u**4 + 6 * u**5
        sd = (30 * u**2 - 60 * u**3 + 30 * u**4) / self.move_s
        sdd = (60 * u - 180 * u**2 + 120 * u**3) / self.move_s**2
        n = len(t)
        R = np.empty((n, 3, 3))
        p = np.empty((n, 3))
        w = np.zeros((n, 3))
        a = np.zeros((n, 3))
        for k in range(n):
            T0 = self.poses[i[k]]
            if moving[k]:
                phi = self._phi[i[k]]
                dp = self.poses[i[k] + 1][:3, 3] - T0[:3, 3]
                R[k] = mats3_times_mat3(T0[:3, :3], so3_exp(s[k] * phi))
                p[k] = T0[:3, 3] + s[k] * dp
                w[k] = sd[k] * phi
                a[k] = sdd[k] * dp
            else:
                R[k] = T0[:3, :3]
                p[k] = T0[:3, 3]
        return R, p, w, a


def simulate_imu(traj: RigTrajectory, noise: ImuNoise, duration_s: float, rng: np.random.Generator,
                 white: bool = True) -> ImuSamples:
    """Gyro and accelerometer samples at ``noise.rate_hz`` over ``[0, duration_s]``.

    ``rng``: the IMU's own stream (the scene's seed, key "imu").  Draw order: gyro bias, accel bias,
    gyro walk, accel walk, gyro white, accel white (fixed, so a seed gives the same run).
    """
    n = int(np.floor(duration_s * noise.rate_hz)) + 1
    t = np.arange(n) / noise.rate_hz
    dt = 1.0 / noise.rate_hz
    R, _, w, a = traj.truth(t)
    f = np.einsum("kji,kj->ki", R, a - G_WORLD)      # R^T (a - g)
    bg0 = rng.normal(0, np.radians(noise.gyro_bias_sigma_deg_s), 3)
    ba0 = rng.normal(0, noise.accel_bias_sigma_mg * 1e-3 * GRAVITY_M_S2, 3)
    wg = rng.normal(0, np.radians(noise.gyro_bias_walk_deg_s_rts) * np.sqrt(dt), (n, 3))
    wa = rng.normal(0, noise.accel_bias_walk_ug_rts * 1e-6 * GRAVITY_M_S2 * np.sqrt(dt), (n, 3))
    wg[0] = 0.0
    wa[0] = 0.0
    bg = bg0 + np.cumsum(wg, axis=0)
    ba = ba0 + np.cumsum(wa, axis=0)
    ng = rng.normal(0, noise.gyro_sigma_rad_s, (n, 3)) if white else np.zeros((n, 3))
    na = rng.normal(0, noise.accel_sigma_m_s2, (n, 3)) if white else np.zeros((n, 3))
    return ImuSamples(t, w + bg + ng, f + ba + na)
