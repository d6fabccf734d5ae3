"""Target trajectories, evaluated at every point's own time (a 100 ms frame is not a snapshot).

Each trajectory is a frozen dataclass with vectorised ``position(t_s) -> (N, 3)`` [m] and
``velocity(t_s) -> (N, 3)`` [m/s] in the world frame (x forward from the head, y left, z up; the head's
rotation centre is the origin), and ``max_speed_m_s`` (used to bound the per-frame cull).
"""

from __future__ import annotations

import math
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from foveatrack.fixed_order import norm3


_straight_position_kernel = None
_circle_rows_kernel = None
_hover_heading_kernel = None
_spline_rows_kernel = None
_NO_ROWS = np.empty((0, 3))     # circle_rows_kernel: rows not asked for
_plain = threading.local()     # numpy_paths(): paths in numpy on this thread, no kernel


@contextmanager
def numpy_paths():
    """Within the block, this thread's paths are evaluated in numpy, never by a numba kernel (the same
    bits: :func:`sim.world.kernels.straight_position_kernel` is numpy's expression element for
    element).  For what is asked once at a scene's load (:mod:`sim.scene_placement`): the load must
    compile no kernel, since a first run compiles them in two other processes before its first frame
    (``tests/test_kernel_compile.py``); the kernel is for the closed loop's per-ray poses."""
    before = getattr(_plain, "on", False)
    _plain.on = True
    try:
        yield
    finally:
        _plain.on = before


# Up to this many rows, one broadcast of a row of three fills an (N, 3) array quicker than three column
# assignments (~0.9 against ~1.6 us at a few rows; at 3000 rows the columns take 4 us, the rows 10).
_ROWS_BROADCAST_MAX = 256


def _col(t_s) -> np.ndarray:
    return np.asarray(t_s, dtype=np.float64).reshape(-1, 1)


def spline_at(spline: CubicSpline, t: np.ndarray, nu: int = 0) -> np.ndarray:
    """``spline(t, nu)`` (N, 3) of a path's spline (axis 0, three values a knot) at 1-D times ``t``:
    scipy's own evaluation (``PPoly._evaluate``, what the call runs: the same bits) without the
    call's wrapping (array-API checks, reshapes), ~5 us of a ~7 us call made four times a frame per
    body on such a path.  scipy is pinned to one minor version (pyproject.toml);
    ``tests/world/test_trajectories.py`` compares the two."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    out = np.empty((t.shape[0], 3))
    spline._ensure_c_contiguous()
    spline._evaluate(t, nu, spline.extrapolate, out)
    return out


def spline_rows(spline: CubicSpline, t_end: float, t_s, position: bool, velocity: bool):
    """``(position, velocity)`` (N, 3) of a path on ``spline`` held at its ends: the spline at the
    times clipped to ``[0, t_end]``, its derivative there with 0 where ``t < 0`` or ``t > t_end``
    (either ``_NO_ROWS`` where not asked).  One kernel call (:func:`sim.world.kernels.spline_rows_kernel`:
    scipy's piece search and sums, the same bits) where :func:`spline_at` and its clip and mask took
    ~10 us for a manual flight's position and velocity at one time (the sensor asks for both at a
    frame's mid time and at its rays' times); under :func:`numpy_paths`, or for a spline that does
    not extrapolate, the clip, scipy's evaluation and the mask (the kernel's twin)."""
    global _spline_rows_kernel
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    spline._ensure_c_contiguous()
    c = spline._c       # what PPoly._evaluate reads (spline.c, a property, costs ~2.5 us)
    if getattr(_plain, "on", False) or spline.extrapolate is not True or c.ndim != 3 or c.shape[2] != 3:
        held = np.clip(t, 0.0, t_end)
        p = spline_at(spline, held) if position else _NO_ROWS
        if velocity:
            v = spline_at(spline, held, 1)
            v[(t < 0) | (t > t_end)] = 0.0
        else:
            v = _NO_ROWS
        return p, v
    if _spline_rows_kernel is None:   # numba loads on first use, not on import
        from sim.world.kernels import spline_rows_kernel as _spline_rows_kernel
    p = np.empty((t.shape[0], 3)) if position else _NO_ROWS
    v = np.empty((t.shape[0], 3)) if velocity else _NO_ROWS
    _spline_rows_kernel(c, spline._x, np.ascontiguousarray(t), float(t_end), p, v)
    return p, v


@dataclass(frozen=True)
class Straight:
    """Constant-velocity pass: ``p(t) = start + velocity * t``."""

    start_m: tuple[float, float, float]
    velocity_m_s: tuple[float, float, float]
    # float64 copies of the two, made once (the closed loop asks for positions several times a frame)
    _start: np.ndarray = field(init=False, repr=False, compare=False)
    _velocity: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for name, value in (("_start", self.start_m), ("_velocity", self.velocity_m_s)):
            a = np.array(value, dtype=np.float64).reshape(3)
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    def position(self, t_s):
        global _straight_position_kernel
        if getattr(_plain, "on", False):
            return self._start + np.ascontiguousarray(t_s, dtype=np.float64).reshape(-1, 1) * self._velocity
        if _straight_position_kernel is None:   # numba loads on first use, not on import
            from sim.world.kernels import straight_position_kernel as _straight_position_kernel
        t = np.ascontiguousarray(t_s, dtype=np.float64).reshape(-1)
        out = np.empty((t.shape[0], 3))
        _straight_position_kernel(self._start, self._velocity, t, out)
        return out

    def velocity(self, t_s):
        out = np.empty((_col(t_s).shape[0], 3))
        if out.shape[0] <= _ROWS_BROADCAST_MAX:   # a frame's few rays on a drone, or its mid time
            out[:] = self._velocity
        else:    # column by column: broadcasting rows of three costs more for many rows
            for i in range(3):
                out[:, i] = self._velocity[i]
        return out

    @property
    def max_speed_m_s(self) -> float:
        return norm3(self.velocity_m_s)

    @property
    def max_accel_m_s2(self) -> float:
        """A bound on |acceleration| (the sensor's per-ray cull, :func:`sim.world.kernels.moving_cull_kernel`)."""
        return 0.0


@dataclass(frozen=True)
class Circle:
    """Orbit at constant speed in a horizontal circle; positive speed = counter-clockwise from above."""

    centre_m: tuple[float, float, float]
    radius_m: float
    speed_m_s: float
    start_deg: float = 0.0

    def _trig(self, t_s):
        """``cos`` and ``sin`` (N,) of the orbit's phase at ``t_s`` (numpy's, as both methods use them)."""
        ph = (math.radians(self.start_deg) + _col(t_s) * (self.speed_m_s / self.radius_m)).reshape(-1)
        return np.cos(ph), np.sin(ph)

    # Column by column, each element as ``centre + radius * (cos, sin, 0)`` and ``speed * (-sin, cos, 0)``
    # (numpy's stacked (N, 3) forms, the same bits: tests/world/test_trajectories.py): a flock's
    # centre is asked for both at a frame's rays' times, and the stacking cost more than the sines;
    # the columns by one kernel call (sim.world.kernels.circle_rows_kernel) where they took fourteen
    # numpy calls, in numpy under numpy_paths().
    def _rows(self, cos, sin, position: bool, velocity: bool):
        global _circle_rows_kernel
        p = np.empty((cos.size, 3)) if position else _NO_ROWS
        v = np.empty((cos.size, 3)) if velocity else _NO_ROWS
        cx, cy, cz = self.centre_m
        r, s = self.radius_m, self.speed_m_s
        if not getattr(_plain, "on", False):
            if _circle_rows_kernel is None:   # numba loads on first use, not on import
                from sim.world.kernels import circle_rows_kernel as _circle_rows_kernel
            _circle_rows_kernel(cos, sin, float(cx), float(cy), float(cz), float(r), float(s), p, v)
            return p, v
        if position:
            p[:, 0] = cx + r * cos
            p[:, 1] = cy + r * sin
            p[:, 2] = cz + r * 0.0
        if velocity:
            v[:, 0] = s * -sin
            v[:, 1] = s * cos
            v[:, 2] = s * 0.0
        return p, v

    def position(self, t_s):
        return self._rows(*self._trig(t_s), True, False)[0]

    def velocity(self, t_s):
        return self._rows(*self._trig(t_s), False, True)[1]

    def position_velocity(self, t_s):
        """``(position(t_s), velocity(t_s))``, the phase's sine and cosine taken once for both."""
        return self._rows(*self._trig(t_s), True, True)

    @property
    def max_speed_m_s(self) -> float:
        return abs(self.speed_m_s)

    @property
    def max_accel_m_s2(self) -> float:
        """A bound on |acceleration|: the centripetal ``v^2 / r`` of the orbit."""
        return self.speed_m_s * self.speed_m_s / abs(self.radius_m)


@dataclass(frozen=True)
class FigureEight:
    """Lemniscate of Gerono in a vertical plane facing the head (y-z), ``size_m`` half-width."""

    centre_m: tuple[float, float, float]
    size_m: float
    period_s: float

    def position(self, t_s):
        w = 2 * math.pi / self.period_s
        ph = w * _col(t_s)
        return np.asarray(self.centre_m) + self.size_m * np.hstack([np.zeros_like(ph), np.sin(ph), np.sin(ph) * np.cos(ph)])

    def velocity(self, t_s):
        w = 2 * math.pi / self.period_s
        ph = w * _col(t_s)
        return self.size_m * w * np.hstack([np.zeros_like(ph), np.cos(ph), np.cos(2 * ph)])

    @property
    def max_speed_m_s(self) -> float:
        return self.size_m * 2 * math.pi / self.period_s * math.sqrt(2)


@dataclass(frozen=True)
class Waypoints:
    """Smooth path through waypoints at a nominal speed (a clamped cubic spline in time); the target
    holds the last waypoint after arriving."""

    points_m: tuple[tuple[float, float, float], ...]
    speed_m_s: float
    _spline: CubicSpline = field(init=False, repr=False, compare=False)
    _t_end: float = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        pts = np.asarray(self.points_m, float)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        t = np.concatenate([[0.0], np.cumsum(seg / self.speed_m_s)])
        object.__setattr__(self, "_spline", CubicSpline(t, pts, axis=0, bc_type="clamped"))
        object.__setattr__(self, "_t_end", float(t[-1]))

    def position(self, t_s):
        return spline_rows(self._spline, self._t_end, t_s, True, False)[0]

    def velocity(self, t_s):
        return spline_rows(self._spline, self._t_end, t_s, False, True)[1]

    @property
    def max_speed_m_s(self) -> float:
        t = np.linspace(0, self._t_end, 2000)
        return float(np.max(np.linalg.norm(self._spline(t, 1), axis=1)))


@dataclass(frozen=True)
class Manual:
    """A "manually flown" path: random but bounded acceleration and speed, seeded.

    Acceleration is an Ornstein-Uhlenbeck process (time constant ``tau_s``) clipped to
    ``max_accel_m_s2``; beyond ``radius_m`` from ``centre_m`` the pilot brakes toward the centre at
    full acceleration, so the flight stays within ``radius_m + v_max^2 / (2 a_max)``; velocity is
    clipped to ``max_speed_m_s``.  Integrated on a 20 ms grid over ``duration_s`` once, then a cubic spline
    gives position and velocity at any time, so every run with one seed flies the same path.
    """

    centre_m: tuple[float, float, float]
    radius_m: float
    max_speed_m_s: float
    max_accel_m_s2: float
    duration_s: float
    seed: int
    tau_s: float = 1.5
    _spline: CubicSpline = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        dt = 0.02
        n = int(math.ceil(self.duration_s / dt)) + 2
        rng = np.random.default_rng(np.random.SeedSequence(self.seed))
        c = np.asarray(self.centre_m, float)
        p = c.copy()
        v = np.zeros(3)
        a = np.zeros(3)
        pos = np.empty((n, 3))
        for i in range(n):
            pos[i] = p
            a += -a * dt / self.tau_s + self.max_accel_m_s2 * math.sqrt(2 * dt / self.tau_s) * rng.standard_normal(3)
            off = p - c
            dist = norm3(off)   # fixed-order sums (foveatrack.fixed_order): BLAS's differ per CPU
            if dist > self.radius_m:
                acc = -off / dist * self.max_accel_m_s2
            else:
                acc = a.copy()
                na = norm3(acc)
                if na > self.max_accel_m_s2:
                    acc *= self.max_accel_m_s2 / na
            v = v + acc * dt
            nv = norm3(v)
            if nv > self.max_speed_m_s:
                v *= self.max_speed_m_s / nv
            p = p + v * dt
        object.__setattr__(self, "_spline", CubicSpline(np.arange(n) * dt, pos, axis=0))

    def position(self, t_s):
        # Hover where the flight ends (never extrapolate the spline past the flown path).
        return spline_rows(self._spline, self.duration_s, t_s, True, False)[0]

    def velocity(self, t_s):
        return spline_rows(self._spline, self.duration_s, t_s, False, True)[1]

    def position_velocity(self, t_s):
        """``(position(t_s), velocity(t_s))`` in one evaluation (the sensor asks for both at the
        frame's mid time and at the rays' times)."""
        return spline_rows(self._spline, self.duration_s, t_s, True, True)


def position_velocity(traj, t_s) -> tuple[np.ndarray, np.ndarray]:
    """``(traj.position(t_s), traj.velocity(t_s))``: in one evaluation where the trajectory has one
    (``position_velocity``: what the two share made once, the same values), else in two."""
    both = getattr(traj, "position_velocity", None)
    return both(t_s) if both is not None else (traj.position(t_s), traj.velocity(t_s))


# A hovering body keeps the heading it had when it last moved, looked up on this grid of absolute
# times (so a point's yaw depends on its own time only, never on how the frames cut the run).
HOVER_LOOKUP_STEP_S = 0.05
HOVER_LOOKUP_SPAN_S = 120.0


def body_yaw_rad(traj, t_s, velocity: np.ndarray | None = None) -> np.ndarray:
    """Yaw of a body flying ``traj`` at each time ``t_s`` [s]: along its horizontal velocity while it
    moves (:func:`heading_rad`); while it hovers, the heading it had at the last grid time
    (``HOVER_LOOKUP_STEP_S``) it moved, within ``HOVER_LOOKUP_SPAN_S`` before; before it first
    moves, the heading it will have; 0 if it never moves within the span.

    A function of the time alone (chunk-independent), and continuous through a stop: snapping to a
    fixed yaw below 1e-4 m/s turned a slowing quadrotor by up to 180 deg in one step.
    ``velocity``: ``traj.velocity(t_s)`` where the caller has it.
    """
    t = _col(t_s)[:, 0]
    yaw = heading_rad(traj.velocity(t) if velocity is None else velocity, default=math.nan)
    hover = np.flatnonzero(np.isnan(yaw))
    if hover.size == 0:
        return yaw
    n = int(round(HOVER_LOOKUP_SPAN_S / HOVER_LOOKUP_STEP_S))
    k = np.arange(1, n + 1, dtype=np.float64)
    cells = np.floor(t[hover] / HOVER_LOOKUP_STEP_S)
    for cell in np.unique(cells):           # a frame's hovering points share one or two cells
        past = heading_rad(traj.velocity((cell - k + 1) * HOVER_LOOKUP_STEP_S), default=math.nan)
        found = past[~np.isnan(past)]
        if found.size == 0:                 # not moved yet: the heading it will have
            ahead = heading_rad(traj.velocity((cell + k) * HOVER_LOOKUP_STEP_S), default=math.nan)
            found = ahead[~np.isnan(ahead)]
        yaw[hover[cells == cell]] = found[0] if found.size else 0.0
    return yaw


def heading_rad(velocity: np.ndarray, default: float = 0.0) -> np.ndarray:
    """Yaw of the body (x forward along the horizontal velocity); ``default`` when hovering
    (``vx^2 + vy^2 <= 1e-8`` or undefined: :func:`sim.world.kernels.hover_heading_kernel`)."""
    global _hover_heading_kernel
    if _hover_heading_kernel is None:   # numba loads on first use, not on import
        from sim.world.kernels import hover_heading_kernel as _hover_heading_kernel
    yaw = np.arctan2(velocity[:, 1], velocity[:, 0])   # numpy's atan2: its bits (numba's libm call may differ)
    _hover_heading_kernel(velocity, float(default), yaw)
    return yaw
