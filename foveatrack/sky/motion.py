"""The constant-velocity Kalman filter of one track, in the world frame.

State per axis ``[p, v]`` (position [m], velocity [m/s]); the three axes are independent filters
(white-acceleration noise and measurement noise isotropic, so the 6 x 6 filter is three 2 x 2 ones
exactly).  Per axis, with covariance ``[[a, b], [b, c]]``, process noise density ``q`` [m^2/s^3]
and measurement variance ``r`` [m^2]:

    predict by dt:  p += v dt;  a += 2 b dt + c dt^2 + q dt^3 / 3;  b += c dt + q dt^2 / 2;  c += q dt
    update with z:  S = a + r;  y = z - p;  p += (a / S) y;  v += (b / S) y;
                    a, b, c = a r / S, b r / S, c - b^2 / S

(Bar-Shalom, Li, Kirubarajan 2001, *Estimation with Applications to Tracking and Navigation*,
Sect. 6.3.2, the discretised continuous white-noise acceleration model).  Each line is an
elementwise numpy operation on the three axes (no BLAS, :mod:`foveatrack.fixed_order`), or in
:meth:`ConstantVelocityFilter.update` the same operations on each axis's Python floats (a few hits a
frame, where a dozen numpy calls on three elements cost more than the arithmetic): the same bits on
every CPU.
"""

from __future__ import annotations

import math

import numpy as np


class ConstantVelocityFilter:
    """Position, velocity and their per-axis covariance of one track (see module docstring)."""

    __slots__ = ("t_s", "p", "v", "a", "b", "c", "q", "r")

    def __init__(self, t_s: float, xyz_m, q_m2_s3: float, r_m2: float, v0_sigma_m_s: float):
        self.t_s = float(t_s)
        self.p = np.array(xyz_m, np.float64).reshape(3)
        self.v = np.zeros(3)
        self.a = np.full(3, float(r_m2))
        self.b = np.zeros(3)
        self.c = np.full(3, float(v0_sigma_m_s) ** 2)
        self.q = float(q_m2_s3)
        self.r = float(r_m2)

    def position_at(self, t_s: float) -> np.ndarray:
        """Position (3,) at ``t_s``, the filter unchanged (:meth:`predicted` without the variance)."""
        return self.p + self.v * (t_s - self.t_s)

    def predicted(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) and its per-axis variance (3,) at ``t_s``, the filter unchanged."""
        dt = t_s - self.t_s
        q = self.q
        return self.position_at(t_s), self.a + 2.0 * dt * self.b + dt * dt * self.c + q * dt * dt * dt / 3.0

    def predict(self, t_s: float) -> None:
        dt = t_s - self.t_s
        if dt == 0.0:
            return
        q = self.q
        self.p = self.p + self.v * dt
        self.a = self.a + 2.0 * dt * self.b + dt * dt * self.c + q * dt * dt * dt / 3.0
        self.b = self.b + dt * self.c + q * dt * dt / 2.0
        self.c = self.c + q * dt
        self.t_s = float(t_s)

    def update(self, t_s: float, z_m, r_m2: float | None = None) -> None:
        """Predict to ``t_s`` and take the measurement ``z_m`` (3,) of variance ``r_m2`` (per axis):
        :meth:`predict`'s and the update's lines axis by axis on floats, in their order."""
        dt = t_s - self.t_s
        r = self.r if r_m2 is None else float(r_m2)
        q = self.q
        axes = []
        for z, p, v, a, b, c in zip(np.asarray(z_m, np.float64).reshape(3).tolist(), self.p.tolist(),
                                    self.v.tolist(), self.a.tolist(), self.b.tolist(), self.c.tolist()):
            if dt != 0.0:
                p = p + v * dt
                a = a + 2.0 * dt * b + dt * dt * c + q * dt * dt * dt / 3.0
                b = b + dt * c + q * dt * dt / 2.0
                c = c + q * dt
            s = a + r
            y = z - p
            ka, kb = a / s, b / s
            axes.append((p + ka * y, v + kb * y, a * (r / s), b * (r / s), c - b * kb))
        if dt != 0.0:
            self.t_s = float(t_s)
        p, v, a, b, c = zip(*axes)
        self.p, self.v, self.a, self.b, self.c = np.array(p), np.array(v), np.array(a), np.array(b), np.array(c)

    def mahalanobis2(self, t_s: float, z_m) -> float:
        """Squared Mahalanobis distance of ``z_m`` from the prediction at ``t_s`` (sum x, y, z in order)."""
        p, var = self.predicted(t_s)
        d = np.asarray(z_m, np.float64).reshape(3) - p
        e = (d * d / (var + self.r)).tolist()
        return e[0] + e[1] + e[2]

    @property
    def speed_m_s(self) -> float:
        x, y, z = self.v.tolist()
        return math.sqrt(x * x + y * y + z * z)     # IEEE's correctly rounded root: np.sqrt's bits


def positions_many(filters, t_s: float) -> np.ndarray:
    """:meth:`ConstantVelocityFilter.position_at` of many filters at ``t_s``: (N, 3), row ``i`` the
    same bits as ``filters[i].position_at(t_s)``."""
    if not filters:
        return np.empty((0, 3))
    dt = t_s - np.array([f.t_s for f in filters])
    return np.array([f.p for f in filters]) + np.array([f.v for f in filters]) * dt[:, None]


def variances_many(filters, t_s: float) -> np.ndarray:
    """The variances of :meth:`ConstantVelocityFilter.predicted` of many filters at ``t_s``: (N, 3),
    row ``i`` the same bits as ``filters[i].predicted(t_s)[1]`` (the same elementwise operations in
    the same order, on arrays: one call for a frame's tracks, not one per track)."""
    if not filters:
        return np.empty((0, 3))
    dt = t_s - np.array([f.t_s for f in filters])
    q = np.array([f.q for f in filters])
    a = np.array([f.a for f in filters])
    b = np.array([f.b for f in filters])
    c = np.array([f.c for f in filters])
    return a + (2.0 * dt)[:, None] * b + (dt * dt)[:, None] * c + (q * dt * dt * dt / 3.0)[:, None]
