"""What else flies or moves in the sky: birds (flapping and gliding, single or in flocks) and the
swaying crowns of trees at the edge of the field.  Drones are the scene's ``[[target]]`` tables.

Every object here is a :class:`SkyObject`: an id, a class, a rigid :class:`sim.world.bodies.Body`, a
trajectory (``position(t)``, ``velocity(t)``, ``max_speed_m_s`` as in :mod:`sim.world.trajectories`)
and, for a bird, a :class:`FlapSchedule` that gives the wings' angle at every point's own time (the
wings are primitives hinged on the body: :func:`sim.world.kernels.cast_flapping_kernel`).  Each
scene table (one bird, one flock, one tree) draws from a random stream of its own, keyed by its id
(:func:`sim.effects.effect_rng`), so adding a flock changes no drone's path and no other flock.

Birds
-----
Wingbeat frequency from wingspan: Pennycuick's cruising-flight formula (C. J. Pennycuick 1996,
"Wingbeat frequency of birds in steady cruising flight: new data and improved predictions",
J. Exp. Biol. 199:1613-1618; also Pennycuick 2008, *Modelling the Flying Bird*, ch. 3)::

    f = m^(3/8) g^(1/2) b^(-23/24) S^(-1/3) rho^(-3/8)

with body mass ``m`` and wing area ``S`` from the wingspan ``b`` by Rayner's allometry of birds
(J. M. V. Rayner 1988, "Form and function in avian flight", Current Ornithology 5:1-66:
``b = 1.17 m^0.39``, ``S = 0.16 m^0.72``, SI units).  That gives 13.6 Hz at b = 0.2 m (sparrow
size), 6.6 Hz at 0.65 m (a pigeon: 0.22 kg, 0.054 m^2) and 4.0 Hz at 1.5 m (a large gull).
Wings flap as ``phi(t) = phi0 + A sin(2 pi f (t - t_bout))`` (``phi0`` the dihedral of the glide,
``A`` the amplitude, default 40 deg) in flapping bouts of whole wingbeats, and are held at ``phi0``
in glides between them (flap-gliding; the bout lengths are exponential, their means set by the
share of time gliding).  The wing's area seen by the lidar changes with ``phi``: seen from below
or the side, the bird's hit count rises and falls once a wingbeat.

Flocks: the flock's centre follows the table's trajectory; each bird keeps a slot in a flattened
ellipsoid of the flock's radius around it, two wingspans or more from the others, and wanders
smoothly about it (seeded, bounded: the birds stay a wingspan apart) (:func:`flock_offsets`).

Trees
-----
A static trunk (a box in the background) and a crown (a few spheres) that sways as a damped
oscillator driven by gusts, per horizontal axis ``x'' + 2 zeta w x' + w^2 x = s xi(t)`` (white
noise ``xi``), at a stated natural frequency ``f = w / 2 pi`` (default 0.3 Hz) and damping ratio
``zeta`` (default 0.1) -- the range K. R. James et al. 2006 (Trees 20:1-17) and B. A. Gardiner's
reviews give for 5-20 m trees: 0.1-1 Hz, damping ratios 0.05-0.2 -- with ``s`` set so that the
stationary RMS sway along the wind is ``sway_m`` (``s^2 = 4 zeta w^3 sway_m^2``); across the wind
it is half of it.  The crown keeps its yaw (it does not turn to its velocity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from sim.world import bodies
from sim.world.trajectories import body_yaw_rad, heading_rad, position_velocity, spline_rows

G_M_S2 = 9.81
RHO_AIR_KG_M3 = 1.225
WINGSPAN_RANGE_M = (0.2, 1.5)
BIRD_SPEED_RANGE_M_S = (5.0, 20.0)
_GRID_S = 0.02


# ------------------------------------------------------------------------------------------ birds

def bird_mass_kg(wingspan_m: float) -> float:
    """Rayner (1988): ``b = 1.17 m^0.39`` [m, kg], inverted."""
    return (wingspan_m / 1.17) ** (1.0 / 0.39)


def bird_wing_area_m2(wingspan_m: float) -> float:
    """Rayner (1988): ``S = 0.16 m^0.72`` [m^2, kg] (both wings)."""
    return 0.16 * bird_mass_kg(wingspan_m) ** 0.72


def wingbeat_hz(wingspan_m: float) -> float:
    """Pennycuick (1996): ``f = m^(3/8) g^(1/2) b^(-23/24) S^(-1/3) rho^(-3/8)`` [Hz]."""
    m = bird_mass_kg(wingspan_m)
    s = bird_wing_area_m2(wingspan_m)
    return (m ** 0.375 * math.sqrt(G_M_S2) * wingspan_m ** (-23.0 / 24.0) * s ** (-1.0 / 3.0)
            * RHO_AIR_KG_M3 ** -0.375)


@dataclass(frozen=True)
class BirdBody:
    """A bird's primitives (body frame: x forward, y left, z up) with its two wings hinged.

    ``hinge`` (M, 3): per primitive ``(sign, y_h, z_h)``; sign 0 for the body, +1 for the left wing
    and -1 for the right, which turn by ``sign * phi`` about the body's x axis through
    ``(0, y_h, z_h)`` (positive ``phi``: wing tips up).  The primitives are given at ``phi = 0``."""

    body: bodies.Body
    hinge: np.ndarray
    wingspan_m: float

    @property
    def bounding_radius_m(self) -> float:
        # any wing angle: the hinge's distance plus the farthest wing point from it
        return float(math.hypot(self.wingspan_m / 2, 0.25 * self.wingspan_m)) + 0.02 * self.wingspan_m


def bird_body(wingspan_m: float, reflectivity: float = 0.25) -> BirdBody:
    """A bird of wingspan ``b``: body a box 0.44 b long, 0.12 b wide and deep (a pigeon's
    proportions: 0.29 m, 0.08 m at b = 0.65 m); each wing a thin box of the mean chord
    ``S / b`` (Rayner's ``S``), reaching from the body's side to the tip, 0.015 b thick."""
    b = wingspan_m
    half_w = 0.06 * b
    chord = bird_wing_area_m2(b) / b
    wing_len = b / 2 - half_w
    prims = [bodies.box((0.0, 0.0, 0.0), (0.22 * b, half_w, 0.06 * b))]
    hinge = [(0.0, 0.0, 0.0)]
    for sign in (1.0, -1.0):
        prims.append(bodies.box((0.0, sign * (half_w + wing_len / 2), 0.03 * b),
                                (chord / 2, wing_len / 2, 0.0075 * b)))
        hinge.append((sign, sign * half_w, 0.03 * b))
    return BirdBody(bodies.Body("bird", np.array(prims), np.full(3, float(reflectivity))), np.array(hinge), b)


@dataclass(frozen=True)
class FlapSchedule:
    """The wing angle of one bird over a run: flapping bouts (whole wingbeats at ``frequency_hz``
    from their start) and glides at ``phi0`` between them.

    ``bout_start_s`` (K,) sorted, ``bout_flaps`` (K,) bool: bout k starts at ``bout_start_s[k]`` and
    lasts until the next one; the first starts at or before 0."""

    frequency_hz: float
    phi0_rad: float
    amplitude_rad: float
    bout_start_s: np.ndarray
    bout_flaps: np.ndarray

    def angle_rad(self, t_s) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        k = np.searchsorted(self.bout_start_s, t, side="right") - 1
        k = np.clip(k, 0, self.bout_start_s.size - 1)
        phase = 2.0 * math.pi * self.frequency_hz * (t - self.bout_start_s[k])
        return np.where(self.bout_flaps[k], self.phi0_rad + self.amplitude_rad * np.sin(phase), self.phi0_rad)

    def flapping(self, t_s) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        k = np.clip(np.searchsorted(self.bout_start_s, t, side="right") - 1, 0, self.bout_start_s.size - 1)
        return self.bout_flaps[k]


def flap_schedule(rng: np.random.Generator, frequency_hz: float, duration_s: float, glide_fraction: float,
                  amplitude_deg: float = 40.0, phi0_deg: float = 10.0, flap_bout_s: float = 1.5) -> FlapSchedule:
    """Alternating bouts over ``[-1 s, duration_s]``: flapping bouts of mean ``flap_bout_s`` (rounded
    up to whole wingbeats, so the wings come back to ``phi0`` when a glide starts), glides of mean
    ``flap_bout_s * g / (1 - g)`` for a gliding share ``g``; ``g = 0``: always flapping, ``g = 1``:
    always gliding.  Draws from ``rng`` only (the bird's own stream)."""
    period = 1.0 / frequency_hz
    if glide_fraction <= 0.0 or glide_fraction >= 1.0:
        flaps = glide_fraction <= 0.0
        start = -1.0 - period * rng.random()     # a random wingbeat phase at t = 0
        return FlapSchedule(frequency_hz, math.radians(phi0_deg), math.radians(amplitude_deg),
                            np.array([start]), np.array([flaps]))
    glide_mean = flap_bout_s * glide_fraction / (1.0 - glide_fraction)
    t = -1.0 - (flap_bout_s + glide_mean) * rng.random()
    flaps = bool(rng.random() >= glide_fraction)
    starts, kinds = [], []
    while t <= duration_s:
        starts.append(t)
        kinds.append(flaps)
        if flaps:
            t += max(1, math.ceil(rng.exponential(flap_bout_s) / period)) * period
        else:
            t += rng.exponential(glide_mean)
        flaps = not flaps
    return FlapSchedule(frequency_hz, math.radians(phi0_deg), math.radians(amplitude_deg),
                        np.array(starts), np.array(kinds))


class SharedPath:
    """A flock centre's trajectory shared by its birds: remembers the last times asked for and what
    it answered (the birds of a flock ask about the same frame mid-time one after another), and
    gives a copy of the same values -- the same bits, one evaluation instead of one per bird."""

    def __init__(self, trajectory):
        self.trajectory = trajectory
        self.max_speed_m_s = trajectory.max_speed_m_s
        self.max_accel_m_s2 = getattr(trajectory, "max_accel_m_s2", None)
        self._memo: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def _ask(self, what: str, t_s):
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        last = self._memo.get(what)
        if last is not None and last[0].shape == t.shape and np.array_equal(last[0], t):
            return last[1].copy()
        out = getattr(self.trajectory, what)(t)
        self._memo[what] = (t.copy(), out.copy())
        return out

    def position(self, t_s):
        return self._ask("position", t_s)

    def velocity(self, t_s):
        return self._ask("velocity", t_s)


@dataclass(frozen=True)
class FlockMember:
    """One bird of a flock: the flock centre's trajectory plus the bird's own offset, its slot plus
    a smooth seeded wander (:func:`flock_offsets`)."""

    centre: object          # a sim.world.trajectories object
    slot_m: np.ndarray      # (3,)
    amp_m: np.ndarray       # (K, 3) amplitudes of the wander's sines per axis
    omega_rad_s: np.ndarray  # (K, 3)
    phase_rad: np.ndarray   # (K, 3)

    def _args(self, t_s):
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        return t, t[:, None, None] * self.omega_rad_s + self.phase_rad       # (N, K, 3)

    def position(self, t_s):
        t, arg = self._args(t_s)
        return self.centre.position(t) + self.slot_m + (self.amp_m * np.sin(arg)).sum(axis=1)

    def velocity(self, t_s):
        t, arg = self._args(t_s)
        return self.centre.velocity(t) + (self.amp_m * self.omega_rad_s * np.cos(arg)).sum(axis=1)

    @property
    def max_speed_m_s(self) -> float:
        wander = np.abs(self.amp_m * self.omega_rad_s).sum(axis=0)
        return self.centre.max_speed_m_s + math.sqrt(float((wander * wander).sum()))

    @property
    def max_accel_m_s2(self) -> float | None:
        """A bound on |acceleration|: the centre's (None if its trajectory gives none) plus the
        wander's, whose sines accelerate each axis by at most the sum of ``amp omega^2``."""
        centre = getattr(self.centre, "max_accel_m_s2", None)
        if centre is None:
            return None
        wander = np.abs(self.amp_m * self.omega_rad_s * self.omega_rad_s).sum(axis=0)
        return centre + math.sqrt(float((wander * wander).sum()))


def flock_offsets(rng: np.random.Generator, count: int, radius_m: float, centre, wingspan_m: float,
                  n_sines: int = 3) -> list[FlockMember]:
    """The birds of a flock around ``centre`` (a trajectory): each a slot drawn uniformly in an
    ellipsoid of semi-axes (r, r, r/3), at least ``gap = max(2 wingspans, 0.3 r / count^(1/3))`` from
    every earlier slot (redrawn up to 20 times; a flock packed tighter than that keeps the last
    draw), plus a wander about the slot: per axis ``n_sines`` sines of periods 4-20 s and random
    phases, together at most ``gap / 4`` from the slot -- so two birds stay at least ``gap / 2``
    (one wingspan) apart -- smooth, and of bounded speed (the cull's ``max_speed_m_s``)."""
    min_gap = max(2.0 * wingspan_m, 0.3 * radius_m / max(count, 1) ** (1.0 / 3.0))
    a_sine = min_gap / 4.0 / (n_sines * math.sqrt(3.0))      # |wander| <= sqrt(3) n a = gap / 4
    slots: list[np.ndarray] = []
    out = []
    for _ in range(count):
        for _try in range(20):
            u = rng.normal(size=3)
            u /= max(math.sqrt(float(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])), 1e-12)
            s = u * radius_m * rng.random() ** (1.0 / 3.0) * np.array([1.0, 1.0, 1.0 / 3.0])
            if all(math.dist(s, o) >= min_gap for o in slots):
                break
        slots.append(s)
        omega = 2.0 * math.pi / rng.uniform(4.0, 20.0, (n_sines, 3))
        phase = rng.uniform(0.0, 2.0 * math.pi, (n_sines, 3))
        out.append(FlockMember(centre, s, np.full((n_sines, 3), a_sine), omega, phase))
    return out


# ------------------------------------------------------------------------------------------ trees

@dataclass(frozen=True)
class SplinePath:
    """A path given on a time grid from 0 (a cubic spline): position and velocity at any time, held
    at its ends outside the grid (velocity 0 there)."""

    _spline: CubicSpline = field(repr=False, compare=False)
    duration_s: float

    def position(self, t_s):
        return spline_rows(self._spline, self.duration_s, t_s, True, False)[0]

    def velocity(self, t_s):
        return spline_rows(self._spline, self.duration_s, t_s, False, True)[1]

    def position_velocity(self, t_s):
        """``(position(t_s), velocity(t_s))`` in one evaluation."""
        return spline_rows(self._spline, self.duration_s, t_s, True, True)

    @property
    def max_speed_m_s(self) -> float:
        t = np.arange(0.0, self.duration_s + _GRID_S, _GRID_S / 2)
        return float(np.max(np.linalg.norm(self._spline(np.clip(t, 0.0, self.duration_s), 1), axis=1)))


def crown_sway(rng: np.random.Generator, rest_m, frequency_hz: float, damping_ratio: float, sway_m: float,
               wind_deg: float, duration_s: float) -> SplinePath:
    """A crown centre's path: ``rest_m`` plus the gust-driven damped oscillation of the module's
    docstring, RMS ``sway_m`` along the wind (toward ``wind_deg``, from +x toward +y) and half of it
    across, on a 20 ms grid over ``[0, duration_s]``."""
    w = 2.0 * math.pi * frequency_hz
    n = int(math.ceil(duration_s / _GRID_S)) + 2
    wd = math.radians(wind_deg)
    along = np.array([math.cos(wd), math.sin(wd), 0.0])
    across = np.array([-math.sin(wd), math.cos(wd), 0.0])
    x_along = _oscillator(rng, n, w, damping_ratio, sway_m)
    x_across = _oscillator(rng, n, w, damping_ratio, 0.5 * sway_m)
    path = np.asarray(rest_m, float) + x_along[:, None] * along + x_across[:, None] * across
    return SplinePath(CubicSpline(np.arange(n) * _GRID_S, path, axis=0), duration_s)


def _oscillator(rng, n: int, w: float, z: float, rms: float) -> np.ndarray:
    """Displacement of ``x'' + 2 z w x' + w^2 x = s xi`` on ``n`` steps of 20 ms, from its stationary
    distribution, by Euler-Maruyama with a semi-implicit velocity update (stable for w dt << 1: at
    1 Hz, w dt = 0.13).  ``s^2 = 4 z w^3 rms^2`` gives the stationary RMS ``rms``."""
    dt = _GRID_S
    s = math.sqrt(4.0 * z * w ** 3) * rms
    x = rng.normal(0.0, rms)
    v = rng.normal(0.0, w * rms)
    kicks = rng.normal(0.0, s * math.sqrt(dt), n)
    out = np.empty(n)
    for i in range(n):
        out[i] = x
        v += -(2.0 * z * w * v + w * w * x) * dt + kicks[i]
        x += v * dt
    return out


def crown_body(radius_m: float, rng: np.random.Generator, reflectivity: float = 0.25) -> bodies.Body:
    """A lumpy crown: a sphere of 0.8 ``radius_m`` and six of 0.45 ``radius_m`` on it at seeded
    directions (the outline the lidar sees changes as it sways).  Body frame at the crown's centre."""
    prims = [bodies.sphere((0.0, 0.0, 0.0), 0.8 * radius_m)]
    for _ in range(6):
        u = rng.normal(size=3)
        u /= max(math.sqrt(float(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])), 1e-12)
        prims.append(bodies.sphere(tuple(0.55 * radius_m * u), 0.45 * radius_m))
    return bodies.Body("crown", np.array(prims), np.full(len(prims), float(reflectivity)))


# ------------------------------------------------------------------------------------------ objects

CLASSES = ("drone", "bird", "tree", "clutter")


@dataclass(frozen=True)
class SkyObject:
    """A moving object of the world besides the ``[[target]]`` drones: a bird or a tree's crown.

    ``hinge`` and ``flap``: a bird's wings (None for a rigid body); ``fixed_yaw``: the body keeps
    this yaw [rad] instead of turning to its velocity (a crown); ``size_m``: its size for the truth
    (a bird's wingspan, a crown's diameter)."""

    id: str
    cls: str
    body: bodies.Body
    trajectory: object
    size_m: float
    bounding_radius_m: float
    hinge: np.ndarray | None = None
    flap: FlapSchedule | None = None
    fixed_yaw: float | None = None


_NO_SLOT = np.zeros((0, 3))      # FlockPoses.velocities: no slot added (wander_sum_kernel)
_wk = None                       # sim.world.kernels, loaded on first use (numba: not on import)


def _world_kernels():
    """sim.world.kernels, imported once: an import statement in a function costs ~1 us a call, and
    FlockPoses' methods ran five a frame."""
    global _wk
    from sim.world import kernels

    _wk = kernels
    return kernels


class FlockPoses:
    """The poses of a flock's birds (consecutive :class:`SkyObject` s whose :class:`FlockMember`
    trajectories share one centre), evaluated for all of them at once: a frame asks for twenty
    birds' positions, headings and wing angles at their own rays' times, and twenty calls of each
    cost more in Python than the arithmetic.  Every value is what the member's own
    ``position``/``velocity``/:func:`~sim.world.trajectories.body_yaw_rad`/``flap.angle_rad``
    gives, by the same element-wise operations in the same order (``tests/world/test_sky.py``
    compares them bit for bit): the sines and cosines and the centre's path by numpy as there, the
    rest by kernels (:func:`sim.world.kernels.wander_rows_kernel` and its neighbours), where numpy's
    gathers and small sums over (N, 3, 3) arrays took several times the time of the sines."""

    def __init__(self, objects: list[SkyObject]):
        trajs = [o.trajectory for o in objects]
        self.objects = objects
        self.members = trajs
        centre = trajs[0].centre
        self.path = centre.trajectory if isinstance(centre, SharedPath) else centre
        self.slot = np.array([m.slot_m for m in trajs])
        self.amp = np.array([m.amp_m for m in trajs])
        self.omega = np.array([m.omega_rad_s for m in trajs])
        self.phase = np.array([m.phase_rad for m in trajs])
        self.amp_omega = self.amp * self.omega          # the velocity's factor, as FlockMember forms it
        self.flaps = [o.flap for o in objects]
        # 2 pi f as FlapSchedule.angle_rad forms it (the scalar first), phi0 and the amplitude
        self.two_pi_f = np.array([2.0 * math.pi * f.frequency_hz for f in self.flaps])
        self.phi0 = np.array([f.phi0_rad for f in self.flaps])
        self.flap_amp = np.array([f.amplitude_rad for f in self.flaps])
        # every member's bouts, one after another: member k's are [seg_lo[k], seg_hi[k])
        sizes = np.array([f.bout_start_s.size for f in self.flaps], np.int64)
        self.seg_hi = np.cumsum(sizes)
        self.seg_lo = self.seg_hi - sizes
        self.bout_start = np.concatenate([f.bout_start_s for f in self.flaps])
        self.bout_flaps = np.concatenate([f.bout_flaps for f in self.flaps])

    @staticmethod
    def groups(objects) -> list[tuple[int, int]]:
        """``(start, stop)`` of each run of two or more consecutive flapping birds of one flock in
        ``objects`` (a scene's ``others``)."""
        out = []
        k = 0
        while k < len(objects):
            o = objects[k]
            c = getattr(o.trajectory, "centre", None)
            j = k + 1
            if isinstance(o.trajectory, FlockMember) and o.flap is not None:
                while (j < len(objects) and isinstance(objects[j].trajectory, FlockMember)
                       and objects[j].trajectory.centre is c and objects[j].flap is not None):
                    j += 1
            if j - k >= 2:
                out.append((k, j))
            k = j
        return out

    def _wander_arg(self, m, t):
        wk = _wk or _world_kernels()
        arg = np.empty((t.size,) + self.omega.shape[1:])
        wk.wander_arg_kernel(t, m, self.omega, self.phase, arg)
        return arg

    def positions(self, m: np.ndarray, t: np.ndarray, arg: np.ndarray | None = None,
                  path_position: np.ndarray | None = None) -> np.ndarray:
        """(N, 3): member ``m[i]``'s position at ``t[i]`` (``path_position``: the centre's at ``t``
        where already known)."""
        wk = _wk or _world_kernels()
        arg = self._wander_arg(m, t) if arg is None else arg
        base = self.path.position(t) if path_position is None else path_position
        out = np.empty((t.size, 3))
        wk.wander_sum_kernel(np.ascontiguousarray(base), self.slot, m, self.amp, np.sin(arg), out)
        return out

    def velocities(self, m: np.ndarray, t: np.ndarray, arg: np.ndarray | None = None,
                   path_velocity: np.ndarray | None = None) -> np.ndarray:
        wk = _wk or _world_kernels()
        arg = self._wander_arg(m, t) if arg is None else arg
        base = self.path.velocity(t) if path_velocity is None else path_velocity
        out = np.empty((t.size, 3))
        wk.wander_sum_kernel(np.ascontiguousarray(base), _NO_SLOT, m, self.amp_omega, np.cos(arg), out)
        return out

    def positions_velocities(self, m: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`positions` and :meth:`velocities`, the wander's arguments and the centre's path made
        once for both, and both sums in one kernel call (:func:`sim.world.kernels.wander_rows_kernel`:
        the sensor asks for both of twenty birds at the frame's mid time and of every ray's bird, and
        the calls cost more than the sums)."""
        wk = _wk or _world_kernels()
        arg = self._wander_arg(m, t)
        p, v = position_velocity(self.path, t)
        out_p = np.empty((t.size, 3))
        out_v = np.empty((t.size, 3))
        wk.wander_rows_kernel(np.ascontiguousarray(p), np.ascontiguousarray(v), self.slot, m, self.amp,
                              self.amp_omega, np.sin(arg), np.cos(arg), out_p, out_v)
        return out_p, out_v

    def poses(self, m: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(positions (N, 3), yaws (N,))`` of members ``m`` at ``t`` (:meth:`positions`, :meth:`yaws`),
        from :meth:`positions_velocities`."""
        p, v = self.positions_velocities(m, t)
        return p, self.yaws(m, t, velocities=v)

    def yaws(self, m: np.ndarray, t: np.ndarray, arg: np.ndarray | None = None,
             path_velocity: np.ndarray | None = None, velocities: np.ndarray | None = None) -> np.ndarray:
        """Body yaw (:func:`~sim.world.trajectories.body_yaw_rad`): along the velocity (``velocities``:
        :meth:`velocities` where already made); a member hovering at some of its times is asked on its
        own (its heading looked up on the grid)."""
        if velocities is None:
            velocities = self.velocities(m, t, arg, path_velocity)
        yaw = heading_rad(velocities, default=math.nan)
        bad = np.isnan(yaw)
        if bad.any():
            for k in np.unique(m[bad]).tolist():
                rows = np.flatnonzero(m == k)
                yaw[rows] = body_yaw_rad(self.members[k], t[rows])
        return yaw

    def wing_angles(self, m: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Each ray's wing angle (``FlapSchedule.angle_rad`` of member ``m[i]`` at ``t[i]``)."""
        wk = _wk or _world_kernels()
        bout = np.empty(t.size, np.int64)
        phase = np.empty(t.size)
        wk.wing_phase_kernel(t, m, self.seg_lo, self.seg_hi, self.bout_start, self.two_pi_f, bout, phase)
        out = np.empty(t.size)
        wk.wing_angle_kernel(bout, m, self.bout_flaps, self.phi0, self.flap_amp, np.sin(phase), out)
        return out
