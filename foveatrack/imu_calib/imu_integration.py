"""The IMU's relative transform between consecutive static poses (paper Section IV.A).

"The biases of the IMU are estimated during each static pose, and linearly interpolated during the
movement between two consecutive poses" (paper).  Here:

* gyroscope bias: the mean rate over each static window (the rig is still, so the mean is the
  bias plus noise / sqrt(samples)), linearly interpolated in time between consecutive windows;
  Earth's rotation (15 deg/h) is absorbed into it;
* accelerometer bias: at rest the accelerometer reads ``f_i = b_a - R_0i^T g_0`` (``g_0``: gravity in
  the IMU frame of the first pose, ``R_0i``: the gyro-integrated attitude of pose i).  One pose
  cannot tell bias from gravity direction, but poses at different attitudes can: ``b_a`` and
  ``g_0`` come from the linear least squares over every window (the bias is taken constant over a
  sequence: BMI088 bias drift over a few minutes is far below its noise over a move);
* the move from pose i to pose i+1 is integrated in the IMU frame of pose i from rest, with gravity
  ``-(f_i - b_a)``: rotation by the bias-corrected rate (midpoint rule on the rotation vector),
  velocity and position by the trapezoidal rule; the velocity left at the next rest (which should be
  zero) is removed as a constant acceleration error over the move (a zero-velocity update at both
  ends), which takes out what remains of an accelerometer bias.

Units: time [s], rate [rad/s], specific force [m/s^2].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foveatrack.errors import UserError
from foveatrack.imu_calib.se3 import make_T, so3_exp

GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class ImuSamples:
    t_s: np.ndarray        # (N,) increasing
    gyro_rad_s: np.ndarray   # (N, 3) IMU frame
    accel_m_s2: np.ndarray   # (N, 3) specific force, IMU frame


@dataclass(frozen=True)
class ImuMotion:
    B: list                       # 4 x 4 relative transforms pose i -> i+1 (T_imu_i_imu_{i+1})
    gyro_bias_rad_s: np.ndarray   # (P, 3) per static window
    accel_bias_m_s2: np.ndarray   # (3,)
    gravity_m_s2: float           # |g_0| as estimated (a check: ~9.81)


def _window(samples: ImuSamples, t0: float, t1: float) -> np.ndarray:
    m = (samples.t_s >= t0) & (samples.t_s <= t1)
    if m.sum() < 10:
        raise UserError(f"the static window [{t0:.2f}, {t1:.2f}] s holds {int(m.sum())} IMU samples; "
                        "need at least 10 (is the IMU streaming at 200 Hz?)")
    return m


def integrate_rotation(t_s: np.ndarray, rate_rad_s: np.ndarray) -> np.ndarray:
    """Attitudes ``R(t_k)`` relative to ``R(t_0) = I`` from body rates (midpoint rule)."""
    R = np.empty((len(t_s), 3, 3))
    R[0] = np.eye(3)
    dt = np.diff(t_s)
    w_mid = 0.5 * (rate_rad_s[1:] + rate_rad_s[:-1]) * dt[:, None]
    for k in range(len(dt)):
        R[k + 1] = R[k] @ so3_exp(w_mid[k])
    return R


def relative_motions(samples: ImuSamples, windows: list[tuple[float, float]]) -> ImuMotion:
    """``B_i`` between consecutive static windows ``[(t_start_s, t_end_s), ...]`` (time order)."""
    P = len(windows)
    if P < 3:
        raise UserError(f"{P} static pose(s): the IMU calibration needs at least 3 (two pairs of poses)")
    masks = [_window(samples, a, b) for a, b in windows]
    mid_s = np.array([0.5 * (a + b) for a, b in windows])
    bg = np.array([samples.gyro_rad_s[m].mean(axis=0) for m in masks])
    f = np.array([samples.accel_m_s2[m].mean(axis=0) for m in masks])

    def bias_at(t):
        return np.column_stack([np.interp(t, mid_s, bg[:, i]) for i in range(3)])

    # Moves: from the end of window i to the start of window i+1.
    moves = []
    for i in range(P - 1):
        m = (samples.t_s >= windows[i][1]) & (samples.t_s <= windows[i + 1][0])
        idx = np.flatnonzero(m)
        # include the neighbouring samples so the integral spans the whole move
        lo, hi = max(idx[0] - 1, 0) if len(idx) else 0, min(idx[-1] + 1, len(samples.t_s) - 1) if len(idx) else 0
        sl = slice(lo, hi + 1)
        t = samples.t_s[sl]
        R = integrate_rotation(t, samples.gyro_rad_s[sl] - bias_at(t))
        moves.append((sl, t, R))
    # Accelerometer bias and gravity: f_i = b_a - R_0i^T g_0 for every window.
    R0 = [np.eye(3)]
    for _, _, R in moves:
        R0.append(R0[-1] @ R[-1])
    rows = np.vstack([np.hstack([np.eye(3), -Ri.T]) for Ri in R0])
    sol, *_ = np.linalg.lstsq(rows, f.reshape(-1), rcond=None)
    ba, g0 = sol[:3], sol[3:]
    B = []
    for i, (sl, t, R) in enumerate(moves):
        fb = samples.accel_m_s2[sl] - ba
        g_i = -(f[i] - ba)
        a = np.einsum("kij,kj->ki", R, fb) + g_i
        dt = np.diff(t)[:, None]
        v = np.vstack([np.zeros(3), np.cumsum(0.5 * (a[1:] + a[:-1]) * dt, axis=0)])
        p = np.vstack([np.zeros(3), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
        T = t[-1] - t[0]
        p_end = p[-1] - v[-1] * T / 2   # zero-velocity update: constant acceleration error removed
        B.append(make_T(R[-1], p_end))
    return ImuMotion(B, bg, ba, float(np.linalg.norm(g0)))
