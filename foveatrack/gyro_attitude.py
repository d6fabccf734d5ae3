"""The head's attitude from the lidar's gyro: an alternative to dead-reckoning the commands.

The PTS-303H reports no orientation, so the tracker integrates the calibrated speed of each command
it sent (:class:`foveatrack.reconstruction.Reconstructor`).  A Livox Horizon / Avia / Tele-15 carries
an IMU (a BMI088 on the Horizon and Avia) and streams it at 200 Hz (SDK data type 6); the lidar is on
the head's tilt stage, so its gyro measures the head's own rotation.  :class:`GyroAttitude` integrates
the bias-corrected gyro into the lidar's attitude in the world and reads pan and tilt off it
(``[tracker] attitude = "gyro"``); the default stays ``"commands"``.  One class serves every driver:
the simulator feeds it the simulated gyro (``sim/head_imu.py``), the daemon the lidar's IMU packets.

Strapdown attitude update (Savage, "Strapdown Inertial Navigation Integration Algorithm Design,
Part 1: Attitude Algorithms", J. Guidance, Control, and Dynamics 21(1), 1998, eqs. 7-10 and 39;
Bortz's rotation-vector equation to second order).  Between two samples ``k, k+1`` taken
``dt`` apart, with the rate linear in time between them, the rotation vector of the step is

.. math:: \\phi = \\tfrac12(\\omega_k + \\omega_{k+1})\\,\\Delta t
          + \\tfrac1{12}(\\omega_k \\times \\omega_{k+1})\\,\\Delta t^2

(the second term is the coning correction) and the attitude quaternion (lidar -> world) is updated
``q_{k+1} = q_k \\otimes \\exp(\\phi/2)``, then renormalised.  Rates [rad/s] are in the lidar frame,
``\\omega_{lidar} = R_{lidar,imu}(\\omega_{imu} - b)``; ``R_{lidar,imu}`` is the IMU's mount
(``imu_rotation_deg``, roll/pitch/yaw about the lidar's x, y, z, ``R = Rz Ry Rx``: the convention
and the result of ``foveatrack calibrate-imu``).  Pan and tilt are read off the attitude by the
convention of :mod:`foveatrack.reconstruction` (``R = R_z(pan) R_y(-tilt)``):
``pan = atan2(R_10, R_00)``, ``tilt = atan2(R_20, hypot(R_00, R_10))``.  For a constant rate about
a fixed axis the update is exact (to rounding); otherwise the error per step is third order in
``dt`` (about ``dt^3 / 12`` times the rate's curvature): 2e-5 deg after 10 s of pan at 30 deg/s
while tilting at 10 deg/s, sampled at 200 Hz (``tests/tracker/test_gyro_attitude.py``).

Gyro bias.  The BMI088's zero-rate offset is up to 1 deg/s, far more than the speed table's errors,
so the bias is estimated whenever the head is known to be at rest, and the attitude is held there (a
zero-velocity update).  "At rest" comes from the commands the tracker itself sent: before the first
motion command (the head waits, homed, while the lidar starts), and from ``rest_margin_s`` after a
STOP's effect plus the deceleration from the larger of the speed the dead reckoning expects and the
gyro's latest rate (a mis-calibrated table underrates it), until the next motion command
*leaves* (its send time: the head cannot move earlier).  Each rest stretch's mean rate (at most
``REST_CHUNK_S`` long) updates a per-axis random-walk Kalman filter of the bias:
``P += q (t - t_prev)``, ``K = P / (P + r)``, ``b += K (z - b)``, ``P *= 1 - K``, with
``q = bias_walk^2`` [rad^2/s^3] and ``r = noise_density^2 / T`` [rad^2/s^2] for a stretch of
duration ``T`` (white noise of density ``noise_density`` averaged over ``T``).  The commands can be
wrong about rest (a STOP lost on a noisy link): every ``CHECK_SAMPLES`` samples of a stretch its mean
rate is compared with the bias, and beyond ``REST_CHECK_SIGMA`` sigma (``sqrt(P + r)``) on any axis
the stretch is refuted: its rest interval ends where it began and its samples are integrated as
motion (the answers given meanwhile, held, are corrected from then on).

Between and after samples.  ``angles_at(t)`` interpolates the per-sample angles linearly (5 ms
apart); beyond the last sample (the tracker asks about a command's effect time, in the future) it
adds the commands' dead-reckoned change from the last sample's time, so the gyro source never
predicts worse than the commands do over that short span.

Uncertainty (1 sigma, both axes alike; approximate): per moving stretch between bias updates the
bias's standard deviation times the stretch's duration (the bias error is constant over it, so it
adds linearly in time), stretches added in quadrature, plus the white noise's angle random walk
``noise_density^2 * t_moving``; beyond the last sample, the commands' variance growth since then.

Units: time [s] (the sensor's clock, like the frames), rates [rad/s], angles [deg] at the interface.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from foveatrack.control import HeadCommand
from foveatrack.detection import wrap_deg
from foveatrack.fixed_order import rows_times_mat3T
from foveatrack.reconstruction import HeadPose, Reconstructor, rotation_matrix

#: A rest stretch longer than this is folded into the bias estimate in pieces of this length, so a
#: long wait keeps the estimate fresh (the bias walks) [s].
REST_CHUNK_S = 2.0
#: Every this many rest samples the stretch's mean rate is checked against the bias estimate ...
CHECK_SAMPLES = 20
#: ... and a deviation beyond this many sigma on any axis refutes the rest.
REST_CHECK_SIGMA = 5.0
#: Deceleration assumed for the gyro's rate when neither the table nor the config gives the head's
#: (a table without timing): the PTS-303H's slower axis, tilt, 10 deg/s^2 [deg/s^2].
FALLBACK_ACCEL_DEG_S2 = 10.0
#: The BMI088's zero-rate offset, 1 sigma (data sheet: +-1 deg/s typical): the bias prior [deg/s].
BIAS_PRIOR_SIGMA_DEG_S = 0.5


def euler_xyz_matrix(rpy_deg) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` from (roll, pitch, yaw) [deg] (the IMU mount's convention)."""
    r, p, y = (math.radians(float(a)) for a in rpy_deg)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def quat_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method, the largest pivot)."""
    m = np.asarray(R, float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def quat_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quat_step(q, phi) -> tuple[float, float, float, float]:
    """``q ⊗ exp(phi / 2)``, renormalised: the body-frame rotation vector ``phi`` [rad] applied."""
    px, py, pz = phi
    a = math.sqrt(px * px + py * py + pz * pz)
    if a < 1e-8:   # sin(a/2)/a to O(a^4): exact in double precision below this
        c, s = 1.0 - a * a / 8.0, 0.5 - a * a / 48.0
    else:
        c, s = math.cos(0.5 * a), math.sin(0.5 * a) / a
    dw, dx, dy, dz = c, s * px, s * py, s * pz
    w, x, y, z = q
    r = (w * dw - x * dx - y * dy - z * dz,
         w * dx + x * dw + y * dz - z * dy,
         w * dy - x * dz + y * dw + z * dx,
         w * dz + x * dy - y * dx + z * dw)
    n = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3])
    return (r[0] / n, r[1] / n, r[2] / n, r[3] / n)


def step_rotation_vector(w0, w1, dt: float) -> tuple[float, float, float]:
    """The rotation vector [rad] of one step from body rates ``w0``, ``w1`` [rad/s] at its ends,
    the rate linear in between: trapezoid + coning term (module docstring, Savage 1998)."""
    c = (w0[1] * w1[2] - w0[2] * w1[1], w0[2] * w1[0] - w0[0] * w1[2], w0[0] * w1[1] - w0[1] * w1[0])
    k = dt * dt / 12.0
    return (0.5 * (w0[0] + w1[0]) * dt + k * c[0], 0.5 * (w0[1] + w1[1]) * dt + k * c[1],
            0.5 * (w0[2] + w1[2]) * dt + k * c[2])


def pan_tilt_from_quat(q) -> tuple[float, float]:
    """(pan, tilt) [deg] of a lidar -> world attitude, ``R = R_z(pan) R_y(-tilt)`` (pan wrapped)."""
    w, x, y, z = q
    r00 = 1 - 2 * (y * y + z * z)
    r10 = 2 * (x * y + w * z)
    r20 = 2 * (x * z - w * y)
    return math.degrees(math.atan2(r10, r00)), math.degrees(math.atan2(r20, math.hypot(r00, r10)))


class BiasFilter:
    """The gyro bias per axis [rad/s] as a random walk, updated with the mean rate of rest stretches
    (module docstring)."""

    def __init__(self, noise_density_rad_s_rthz: float, bias_walk_rad_s_rts: float,
                 prior_sigma_rad_s: float = math.radians(BIAS_PRIOR_SIGMA_DEG_S)):
        self.n2 = noise_density_rad_s_rthz ** 2
        self.q = bias_walk_rad_s_rts ** 2
        self.b = np.zeros(3)
        self.P = prior_sigma_rad_s ** 2
        self.t_s: float | None = None
        self.updates = 0

    @property
    def sigma_rad_s(self) -> float:
        return math.sqrt(self.P)

    def predict(self, t_s: float) -> None:
        if self.t_s is not None and t_s > self.t_s:
            self.P += self.q * (t_s - self.t_s)
        self.t_s = t_s if self.t_s is None else max(self.t_s, t_s)

    def update(self, t_s: float, mean_rate_rad_s: np.ndarray, duration_s: float) -> None:
        """Fold in a rest stretch ending at ``t_s``: its mean rate over ``duration_s`` of samples."""
        self.predict(t_s)
        r = self.n2 / max(duration_s, 1e-6)
        k = self.P / (self.P + r)
        self.b = self.b + k * (np.asarray(mean_rate_rad_s, float) - self.b)
        self.P *= 1.0 - k
        self.updates += 1


class GyroAttitude(HeadPose):
    """Head angles from the bias-corrected gyro, with the commands' dead reckoning beyond the last
    sample; the interface of :class:`~foveatrack.reconstruction.Reconstructor` (what the tracker
    asks of its attitude source) plus :meth:`on_imu`.

    commands : Reconstructor            the command dead reckoning (start pose, table, timing)
    imu_rotation_deg : (3,) [deg]       the IMU's mount in the lidar frame (roll, pitch, yaw)
    noise_density_deg_s_rthz : > 0      gyro white noise [deg/s/sqrt(Hz)] (BMI088: 0.014)
    bias_walk_deg_s_rts : >= 0          gyro bias random walk [deg/s/sqrt(s)]
    rest_margin_s : >= 0 [s]            wait this long after the expected stop before trusting rest
    history_s : > 0 [s]                 how far back ``angles_at`` answers from samples (older, once
                                        samples were dropped: NaN with infinite sigma)
    """

    def __init__(self, commands: Reconstructor, *, imu_rotation_deg=(0.0, 0.0, 0.0),
                 noise_density_deg_s_rthz: float = 0.014, bias_walk_deg_s_rts: float = 0.001,
                 rest_margin_s: float = 0.2, history_s: float = 10.0):
        self.commands = commands
        self.lidar_offset_m = commands.lidar_offset_m
        self.R_lidar_imu = euler_xyz_matrix(imu_rotation_deg)
        self.bias = BiasFilter(math.radians(noise_density_deg_s_rthz), math.radians(bias_walk_deg_s_rts))
        self.rest_margin_s = rest_margin_s
        self.history_s = history_s
        t0 = commands.pan.t0
        p0, t0_deg, s0, _ = commands.angles_at(t0)
        self._q = quat_from_matrix(rotation_matrix(p0, t0_deg))
        self._sigma0_deg = s0
        # Rest stretches [start, end) from the commands; the head rests until the first motion command.
        self._rest: list[list[float]] = [[-math.inf, math.inf]]
        self._cmd_undo: tuple | None = None   # (send time, rests before it) of the last command
        # Samples: time, unwrapped pan, tilt, sigma (after the step to that sample).
        self._t: list[float] = []
        self._pan: list[float] = []
        self._tilt: list[float] = []
        self._sig: list[float] = []
        self._trimmed = False             # samples older than history_s were dropped
        self._pan_unwrap_deg = 0.0        # turns added to keep the stored pan continuous
        self._w_prev: np.ndarray | None = None   # previous sample's bias-corrected rate (lidar frame)
        self._t_prev: float | None = None
        self._rest_sum = np.zeros(3)
        self._rest_n = 0
        self._rest_t0: float | None = None
        self._rest_t1: float | None = None
        self._var_closed = 0.0            # variance of closed moving stretches [rad^2]
        self._move_s = 0.0                # moving time in the open stretch [s]
        self._move_total_s = 0.0
        self.samples = 0
        self.rest_samples = 0
        self.gaps = 0                     # steps longer than 3 nominal sample periods (lost packets)
        self.rests_refuted = 0            # rest stretches the gyro showed to be motion
        self.nonfinite_samples = 0        # samples dropped for a NaN / inf time or rate
        self._rest_buf: list = []
        self._rest_undo = None

    # -- the Reconstructor interface --------------------------------------------------------------
    @property
    def effect_delay_s(self) -> float:
        return self.commands.effect_delay_s

    @property
    def last_send_t_s(self):
        return self.commands.last_send_t_s

    @property
    def last_command(self):
        return self.commands.last_command

    def on_command(self, t_s: float, cmd: HeadCommand) -> None:
        """A command left at ``t_s``: the dead reckoning learns it, and it bounds the rest stretches."""
        self.commands.on_command(t_s, cmd)
        # A second command at the same instant replaces the first (the gate limited it, the write
        # failed, the head is frozen): the rests are as if only the second had been sent.
        if self._cmd_undo is not None and self._cmd_undo[0] == t_s:
            self._rest = [list(iv) for iv in self._cmd_undo[1]]
        else:
            self._cmd_undo = (t_s, [list(iv) for iv in self._rest])
        last = self._rest[-1]
        if cmd.is_stop:
            if last[1] != math.inf:   # moving: rest once the expected deceleration is over
                t_eff = t_s + self.commands.effect_delay_s
                vp, vt = self.commands.speeds_at(t_eff)
                decel = max(self._decel_s(self.commands.pan, vp), self._decel_s(self.commands.tilt, vt))
                # the gyro's latest rate is the head's real speed (a table may be wrong about it)
                if self._w_prev is not None:   # the body rate in head axes: pan = wx sin t + wz cos t, tilt = -wy
                    wx, wy, wz = self._w_prev
                    tl = math.radians(pan_tilt_from_quat(self._q)[1])
                    for ax, rate in ((self.commands.pan, wx * math.sin(tl) + wz * math.cos(tl)), (self.commands.tilt, wy)):
                        decel = max(decel, math.degrees(abs(rate)) / (ax.accel or FALLBACK_ACCEL_DEG_S2))
                self._rest.append([t_eff + decel + self.rest_margin_s, math.inf])
        else:
            # The head may move from the moment the command leaves; a rest not yet begun is void.
            if last[1] == math.inf:
                last[1] = t_s
                if last[1] <= last[0]:
                    self._rest.pop()
        if len(self._rest) > 64:
            del self._rest[:-64]

    @staticmethod
    def _decel_s(axis, v: float) -> float:
        return 0.0 if axis.accel is None or v == 0.0 else abs(v) / axis.accel

    def at_rest(self, t_s: float) -> bool:
        """Do the commands sent so far say the head is still at ``t_s``?"""
        for a, b in reversed(self._rest):
            if a <= t_s < b:
                return True
            if b <= t_s:
                return False
        return False

    def angles_at(self, t_s: float) -> tuple[float, float, float, float]:
        """(pan_deg, tilt_deg, sigma_pan_deg, sigma_tilt_deg) at ``t_s``; pan wrapped to (-180, 180]."""
        T = self._t
        if not T or t_s >= T[-1]:
            if T:
                t_ref, p_ref, ti_ref, s_ref = T[-1], self._pan[-1], self._tilt[-1], self._sig[-1]
            else:
                t_ref = self.commands.pan.t0
                p_ref, ti_ref = pan_tilt_from_quat(self._q)
                s_ref = self._sigma0_deg
            if t_s == t_ref:
                return wrap_deg(p_ref), ti_ref, s_ref, s_ref
            cp1, ct1, sp1, st1 = self.commands.angles_at(t_s)
            cp0, ct0, sp0, st0 = self.commands.angles_at(t_ref)
            pan = wrap_deg(p_ref + wrap_deg(cp1 - cp0))
            tilt = ti_ref + (ct1 - ct0)
            sp = math.sqrt(s_ref ** 2 + max(sp1 ** 2 - sp0 ** 2, 0.0))
            st = math.sqrt(s_ref ** 2 + max(st1 ** 2 - st0 ** 2, 0.0))
            return pan, tilt, sp, st
        i = bisect.bisect_right(T, t_s)
        if i == 0:
            if self._trimmed:   # older than the kept samples: unknown, not the oldest kept angle
                return math.nan, math.nan, math.inf, math.inf
            return wrap_deg(self._pan[0]), self._tilt[0], self._sig[0], self._sig[0]
        t0, t1 = T[i - 1], T[i]
        u = (t_s - t0) / (t1 - t0)
        pan = self._pan[i - 1] + u * (self._pan[i] - self._pan[i - 1])
        tilt = self._tilt[i - 1] + u * (self._tilt[i] - self._tilt[i - 1])
        s = self._sig[i - 1] + u * (self._sig[i] - self._sig[i - 1])
        return wrap_deg(pan), tilt, s, s

    def tilt_at(self, t_s: float) -> tuple[float, float]:
        _, t, _, st = self.angles_at(t_s)
        return t, st

    def speeds_at(self, t_s: float) -> tuple[float, float]:
        return self.commands.speeds_at(t_s)

    def accels_deg_s2(self) -> tuple[float | None, float | None]:
        return self.commands.accels_deg_s2()

    # -- the gyro ---------------------------------------------------------------------------------
    def on_imu(self, t_s, gyro_rad_s) -> None:
        """Gyro samples in time order: ``t_s`` (N,) [s, sensor clock], ``gyro_rad_s`` (N, 3) in the
        IMU's frame [rad/s].  Samples not after the last one are ignored (a duplicate packet); samples
        with a NaN or infinite time or rate are dropped and counted (``nonfinite_samples``)."""
        t_arr = np.asarray(t_s, float).reshape(-1)
        g = np.asarray(gyro_rad_s, float).reshape(-1, 3)
        if t_arr.size == 0:
            return
        w_lidar = rows_times_mat3T(g, self.R_lidar_imu)   # g @ R.T, the same bits on every CPU
        for k in range(t_arr.size):
            t = float(t_arr[k])
            if not (math.isfinite(t) and np.isfinite(w_lidar[k]).all()):
                self.nonfinite_samples += 1   # one NaN would make the attitude NaN for good
                continue
            if self._t_prev is not None and t <= self._t_prev:
                continue
            self._sample(t, w_lidar[k])
        self._trim()

    def _sample(self, t: float, w_raw: np.ndarray) -> None:
        self.samples += 1
        if self.at_rest(t):
            if self._rest_n == 0:   # a rest stretch begins: remember where to resume if it is refuted
                self._rest_t0 = t
                self._rest_undo = (self._q, self._w_prev, self._t_prev, len(self._t))
                self._rest_buf = []
            self.rest_samples += 1
            self._rest_sum += w_raw
            self._rest_n += 1
            self._rest_t1 = t
            self._rest_buf.append((t, w_raw))
            self._w_prev = w_raw - self.bias.b
            self._t_prev = t
            self._record(t)                     # held: the head is still
            if self._rest_n % CHECK_SAMPLES == 0 and not self._rest_consistent():
                self._refute_rest()
            elif self._rest_t1 - self._rest_t0 >= REST_CHUNK_S:
                self._fold_rest()
            return
        if self._rest_n:
            self._fold_rest()
        w = w_raw - self.bias.b
        if self._t_prev is not None and self._w_prev is not None:
            dt = t - self._t_prev
            if len(self._t) > 1 and dt > 3.0 * (self._t[-1] - self._t[-2]):
                self.gaps += 1
            self._q = quat_step(self._q, step_rotation_vector(self._w_prev, w, dt))
            self._move_s += dt
            self._move_total_s += dt
        self._w_prev = w
        self._t_prev = t
        self._record(t)

    def _record(self, t: float) -> None:
        pan, tilt = pan_tilt_from_quat(self._q)
        if self._pan:   # keep the stored pan continuous for interpolation
            prev = self._pan[-1]
            pan = prev + wrap_deg(pan - wrap_deg(prev))
        var = (self._sigma0_deg ** 2 + math.degrees(1) ** 2 * (
            self._var_closed + (self.bias.sigma_rad_s * self._move_s) ** 2 + self.bias.n2 * self._move_total_s))
        self._t.append(t)
        self._pan.append(pan)
        self._tilt.append(tilt)
        self._sig.append(math.sqrt(var))

    def _rest_duration_s(self) -> float:
        n = self._rest_n   # n samples average n sample periods of noise
        return (self._rest_t1 - self._rest_t0) * n / (n - 1) if n > 1 else 1.0 / 200.0

    def _rest_consistent(self) -> bool:
        """Is the stretch's mean rate the bias, within ``REST_CHECK_SIGMA`` (per axis)?  If not, the
        head moves although the commands say it rests (a STOP lost on the link, a longer dead time)."""
        P = self.bias.P + self.bias.q * max(self._rest_t1 - (self.bias.t_s or self._rest_t1), 0.0)
        lim = REST_CHECK_SIGMA * math.sqrt(P + self.bias.n2 / self._rest_duration_s())
        return bool(np.all(np.abs(self._rest_sum / self._rest_n - self.bias.b) <= lim))

    def _refute_rest(self) -> None:
        """The open stretch was motion: end its rest interval where it began and integrate its samples."""
        t0 = self._rest_t0
        for iv in reversed(self._rest):
            if iv[0] <= t0 < iv[1]:
                iv[1] = t0
                break
        self._rest = [iv for iv in self._rest if iv[1] > iv[0]] or [[-math.inf, -math.inf]]
        buf = self._rest_buf
        self._q, self._w_prev, self._t_prev, n_hist = self._rest_undo
        del self._t[n_hist:], self._pan[n_hist:], self._tilt[n_hist:], self._sig[n_hist:]
        self._rest_sum = np.zeros(3)
        self._rest_n = 0
        self.samples -= len(buf)
        self.rest_samples -= len(buf)
        self.rests_refuted += 1
        for t, w_raw in buf:
            self._sample(t, w_raw)

    def _fold_rest(self) -> None:
        """Close the open rest stretch: its mean rate updates the bias; the moving stretch before it
        is closed with the bias uncertainty it had."""
        self._var_closed += (self.bias.sigma_rad_s * self._move_s) ** 2
        self._move_s = 0.0
        self.bias.update(self._rest_t1, self._rest_sum / self._rest_n, self._rest_duration_s())
        self._rest_sum = np.zeros(3)
        self._rest_n = 0

    def _trim(self) -> None:
        if len(self._t) > 64 and self._t[-1] - self._t[0] > 1.5 * self.history_s:
            cut = bisect.bisect_left(self._t, self._t[-1] - self.history_s)
            del self._t[:cut], self._pan[:cut], self._tilt[:cut], self._sig[:cut]
            self._trimmed = True


class ImuFeed:
    """The lidar's IMU samples held until the frame they precede (the daemon's feed to
    :meth:`foveatrack.tracker.Tracker.on_imu`).

    ``push`` takes what the Livox client decoded (data type 6: packet times [ns] on the sensor clock,
    gyro [rad/s]); ``release(t_end_s)`` returns, in time order, the samples before a frame's end and
    keeps the later ones.  A sample before the last frame end released (a late packet: the source has
    moved past it) is dropped and counted in ``late``; one more than ``AHEAD_S`` after the frame's end
    (a wild timestamp, which would block every later sample) in ``bad_time``.  Samples before the
    first frame are the head's wait at start: they are released with it (the bias's first estimate).
    The accelerometer's samples, where pushed, ride along (the third of :meth:`release`'s values, for
    the recording; None if none was ever pushed): the tracker uses only the gyro.
    """

    AHEAD_S = 5.0

    def __init__(self):
        self._t: list[np.ndarray] = []
        self._g: list[np.ndarray] = []
        self._a: list[np.ndarray] = []
        self.has_accel = False
        self.not_before_s = -math.inf     # released up to here (and a rebased tracker's start)
        self.samples_in = 0
        self.samples_fed = 0
        self.late = 0
        self.bad_time = 0

    def push(self, t_ns, gyro_rad_s, accel_g=None) -> None:
        t = np.asarray(t_ns, np.int64).reshape(-1)
        if t.size:
            self._t.append(t * 1e-9)
            self._g.append(np.asarray(gyro_rad_s, float).reshape(-1, 3))
            # a batch without accel among ones with it: NaN (recorded as the source gave it)
            self._a.append(np.full((t.size, 3), np.nan) if accel_g is None
                           else np.asarray(accel_g, float).reshape(-1, 3))
            self.has_accel |= accel_g is not None
            self.samples_in += t.size

    def release(self, t_end_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The samples before ``t_end_s``: times [s], gyro (n, 3), accel (n, 3) or None (none pushed)."""
        if not self._t:
            self.not_before_s = max(self.not_before_s, t_end_s)
            return np.empty(0), np.empty((0, 3)), np.empty((0, 3)) if self.has_accel else None
        t = np.concatenate(self._t)
        g = np.concatenate(self._g)
        a = np.concatenate(self._a)
        order = np.argsort(t, kind="stable")
        t, g, a = t[order], g[order], a[order]
        late = t < self.not_before_s
        wild = t > t_end_s + self.AHEAD_S
        self.late += int(late.sum())
        self.bad_time += int(wild.sum())
        now = (t < t_end_s) & ~late
        keep = (t >= t_end_s) & ~wild
        self._t, self._g, self._a = ([t[keep]], [g[keep]], [a[keep]]) if keep.any() else ([], [], [])
        self.not_before_s = max(self.not_before_s, t_end_s)
        self.samples_fed += int(now.sum())
        return t[now], g[now], a[now] if self.has_accel else None

    def restart(self, t0_s: float) -> None:
        """A new tracker starts at ``t0_s`` (a new sensor clock, a homed head): the pending samples
        and any before ``t0_s`` are not its (the head may have moved while its pose was unknown)."""
        self._t, self._g, self._a = [], [], []
        self.not_before_s = t0_s
