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
:meth:`ConstantVelocityFilter.update` the same operations axis by axis in a numba kernel
(:func:`update_kernel`, ~0.75 us where its plain-Python twin :func:`update_floats` took ~3 us and a
dozen numpy calls on three elements more; ``tests/sky/test_sky_tracks.py`` compares the two bit for
bit): the same bits on every CPU.

A filter keeps its state in one (5, 3) array, rows ``p, v, a, b, c``, made afresh at every change
(never written in place: a position or velocity handed out stays as it was): a frame's predictions
of every track (:func:`positions_many`, :func:`variances_many`) gather one array per filter, not five,
and predict them all in one kernel call (:func:`predictions_kernel`; its numpy twin :func:`_positions`
and :func:`_variances`, compared bit for bit in ``tests/sky/test_sky_tracks.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


class ConstantVelocityFilter:
    """Position, velocity and their per-axis covariance of one track (see module docstring)."""

    __slots__ = ("t_s", "state", "q", "r")

    def __init__(self, t_s: float, xyz_m, q_m2_s3: float, r_m2: float, v0_sigma_m_s: float):
        self.t_s = float(t_s)
        state = np.zeros((5, 3))           # rows p, v, a, b, c (module docstring)
        state[0] = np.array(xyz_m, np.float64).reshape(3)
        state[2] = float(r_m2)
        state[4] = float(v0_sigma_m_s) ** 2
        self.state = state
        self.q = float(q_m2_s3)
        self.r = float(r_m2)

    def _row(k: int, doc: str):
        def get(self) -> np.ndarray:
            return self.state[k]

        def put(self, value) -> None:
            # a fresh state with the row replaced: what was handed out before stays as it was
            state = self.state.copy()
            state[k] = value
            self.state = state
        return property(get, put, doc=doc)

    p = _row(0, "position (3,) [m]")
    v = _row(1, "velocity (3,) [m/s]")
    a = _row(2, "per-axis variance of the position (3,)")
    b = _row(3, "per-axis covariance of position and velocity (3,)")
    c = _row(4, "per-axis variance of the velocity (3,)")
    del _row

    def position_at(self, t_s: float) -> np.ndarray:
        """Position (3,) at ``t_s``, the filter unchanged (:meth:`predicted` without the variance)."""
        return self.p + self.v * (t_s - self.t_s)

    def distance_at(self, t_s: float, z_m) -> float:
        """``norm3(z_m - position_at(t_s))``: the same operations in their order, on floats (a
        matched object's distance from its track's prediction, a few a frame: ~0.4 us, not ~1.6)."""
        dt = t_s - self.t_s
        (px, py, pz), (vx, vy, vz) = self.state[:2].tolist()
        zx, zy, zz = np.asarray(z_m, np.float64).reshape(3).tolist()
        x, y, z = zx - (px + vx * dt), zy - (py + vy * dt), zz - (pz + vz * dt)
        return math.sqrt(x * x + y * y + z * z)

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
        p, v, a, b, c = self.state
        self.state = np.array([p + v * dt, v, a + 2.0 * dt * b + dt * dt * c + q * dt * dt * dt / 3.0,
                               b + dt * c + q * dt * dt / 2.0, c + q * dt])
        self.t_s = float(t_s)

    def update(self, t_s: float, z_m, r_m2: float | None = None) -> None:
        """Predict to ``t_s`` and take the measurement ``z_m`` (3,) of variance ``r_m2`` (per axis):
        :meth:`predict`'s and the update's lines axis by axis, in their order (:func:`update_kernel`)."""
        dt = t_s - self.t_s
        state = np.empty((5, 3))
        update_kernel(self.state, float(dt), np.ascontiguousarray(z_m, np.float64).reshape(3),
                      self.r if r_m2 is None else float(r_m2), self.q, state)
        if dt != 0.0:
            self.t_s = float(t_s)
        self.state = state

    def mahalanobis2(self, t_s: float, z_m) -> float:
        """Squared Mahalanobis distance of ``z_m`` from the prediction at ``t_s`` (sum x, y, z in order)."""
        p, var = self.predicted(t_s)
        d = np.asarray(z_m, np.float64).reshape(3) - p
        e = (d * d / (var + self.r)).tolist()
        return e[0] + e[1] + e[2]

    @property
    def speed_m_s(self) -> float:
        x, y, z = self.state[1].tolist()            # (v, without the property's call)
        return math.sqrt(x * x + y * y + z * z)     # IEEE's correctly rounded root: np.sqrt's bits


@njit(cache=True)
def update_kernel(state, dt, z, r, q, out):
    """:meth:`ConstantVelocityFilter.update` of the state (5, 3) by ``dt`` [s] with the measurement
    ``z`` (3,) of variance ``r``, noise density ``q``: the new state into ``out`` (5, 3).  Per axis
    :meth:`ConstantVelocityFilter.predict`'s lines (unless ``dt`` is 0) and the update's, in their
    order (twin: :func:`update_floats`)."""
    for i in range(3):
        p = state[0, i]
        v = state[1, i]
        a = state[2, i]
        b = state[3, i]
        c = state[4, i]
        if dt != 0.0:
            p = p + v * dt
            a = a + 2.0 * dt * b + dt * dt * c + q * dt * dt * dt / 3.0
            b = b + dt * c + q * dt * dt / 2.0
            c = c + q * dt
        s = a + r
        y = z[i] - p
        ka = a / s
        kb = b / s
        out[0, i] = p + ka * y
        out[1, i] = v + kb * y
        out[2, i] = a * (r / s)
        out[3, i] = b * (r / s)
        out[4, i] = c - b * kb


def update_floats(state, dt: float, z, r: float, q: float) -> np.ndarray:
    """:func:`update_kernel` on each axis's Python floats: its twin, the new state (5, 3)."""
    axes = []
    for z, p, v, a, b, c in zip(np.asarray(z, np.float64).reshape(3).tolist(), *np.asarray(state).tolist()):
        if dt != 0.0:
            p = p + v * dt
            a = a + 2.0 * dt * b + dt * dt * c + q * dt * dt * dt / 3.0
            b = b + dt * c + q * dt * dt / 2.0
            c = c + q * dt
        s = a + r
        y = z - p
        ka, kb = a / s, b / s
        axes.append((p + ka * y, v + kb * y, a * (r / s), b * (r / s), c - b * kb))
    return np.array(list(zip(*axes)))      # per axis (p, v, a, b, c) -> rows p, v, a, b, c


def _gathered(filters, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The filters' states (N, 5, 3) and their times to ``t_s`` (N,), in one gather."""
    return np.array([f.state for f in filters]), t_s - np.array([f.t_s for f in filters])


def _positions(S: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """:meth:`ConstantVelocityFilter.position_at` of gathered states, row by row (the same bits): the
    numpy twin of :func:`predictions_kernel`'s positions."""
    return S[:, 0] + S[:, 1] * dt[:, None]


def _variances(S: np.ndarray, dt: np.ndarray, filters) -> np.ndarray:
    """The variances of :meth:`ConstantVelocityFilter.predicted` of gathered states, row by row (the
    same elementwise operations in the same order): the numpy twin of :func:`predictions_kernel`'s
    variances."""
    q = np.array([f.q for f in filters])
    a, b, c = S[:, 2], S[:, 3], S[:, 4]
    return a + (2.0 * dt)[:, None] * b + (dt * dt)[:, None] * c + (q * dt * dt * dt / 3.0)[:, None]


@njit(cache=True)
def predictions_kernel(S, t, q, t_s, pos, var):
    """Positions (into ``pos`` (N, 3)) and, if ``var`` has the rows, variances (into ``var``) at
    ``t_s`` of the gathered states ``S`` (N, 5, 3) at times ``t`` (N,) with noise densities ``q``
    (N,): :func:`_positions`' and :func:`_variances`' operations on each element, in their order
    (one call where they were a dozen numpy calls on a frame's twenty tracks)."""
    for i in range(S.shape[0]):
        dt = t_s - t[i]
        for a in range(3):
            pos[i, a] = S[i, 0, a] + S[i, 1, a] * dt
        if var.shape[0]:
            dt2 = 2.0 * dt
            dtdt = dt * dt
            qt = q[i] * dt * dt * dt / 3.0
            for a in range(3):
                var[i, a] = S[i, 2, a] + dt2 * S[i, 3, a] + dtdt * S[i, 4, a] + qt


def _predicted(filters, t_s: float, want_var: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (N, 3) and, with ``want_var``, variances (N, 3; else (0, 3)) of the filters at ``t_s``,
    and the gathered states (N, 5, 3): one gather of their states and times, one
    :func:`predictions_kernel` call."""
    n = len(filters)
    S = np.array([f.state for f in filters])
    t = np.array([f.t_s for f in filters])
    pos = np.empty((n, 3))
    var = np.empty((n if want_var else 0, 3))
    predictions_kernel(S, t, np.array([f.q for f in filters]) if want_var else t, float(t_s), pos, var)
    return pos, var, S


def positions_many(filters, t_s: float) -> np.ndarray:
    """:meth:`ConstantVelocityFilter.position_at` of many filters at ``t_s``: (N, 3), row ``i`` the
    same bits as ``filters[i].position_at(t_s)``."""
    if not filters:
        return np.empty((0, 3))
    return _predicted(filters, t_s, False)[0]


def positions_velocities_many(filters, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`positions_many` and the filters' velocities (N, 3) of the same gather: its rows are a
    fresh array's, which nothing writes, so a frame's views hand them out without a copy each."""
    if not filters:
        return np.empty((0, 3)), np.empty((0, 3))
    pos, _, S = _predicted(filters, t_s, False)
    return pos, S[:, 1]


def predictions_many(filters, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`positions_many` and :func:`variances_many` (the same bits) of one gather of the
    filters' states: the association reads both for every track."""
    if not filters:
        return np.empty((0, 3)), np.empty((0, 3))
    return _predicted(filters, t_s, True)[:2]


def variances_many(filters, t_s: float) -> np.ndarray:
    """The variances of :meth:`ConstantVelocityFilter.predicted` of many filters at ``t_s``: (N, 3),
    row ``i`` the same bits as ``filters[i].predicted(t_s)[1]`` (one call for a frame's tracks, not
    one per track)."""
    if not filters:
        return np.empty((0, 3))
    return _predicted(filters, t_s, True)[1]
