"""Rigid bodies and background built from exact primitives (see :mod:`sim.world.kernels`).

The default intruder is a small quadrotor like the paper's (Fig. 12, 13): a body box, four arms
(thin boxes, the ones a beam footprint only partly hits) and four rotor disks, about 0.35 m across.
Body frame: x forward (the direction of flight), y left, z up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foveatrack.fixed_order import dot3, norm3
from sim.world.kernels import BOX, DISK, PLANE, PRIM_COLUMNS, RECT, SPHERE


def _row(kind, centre, size=(0, 0, 0), a=(0, 0, 0), b=(0, 0, 0)) -> np.ndarray:
    r = np.zeros(PRIM_COLUMNS)
    r[0] = kind
    r[1:4] = centre
    r[4:7] = size
    r[7:10] = a
    r[10:13] = b
    return r


def sphere(centre, radius) -> np.ndarray:
    return _row(SPHERE, centre, (radius, 0, 0))


def box(centre, half_extents, yaw_rad: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return _row(BOX, centre, half_extents, (c, s, 0.0), (-s, c, 0.0))


def disk(centre, radius, normal=(0.0, 0.0, 1.0)) -> np.ndarray:
    n = np.asarray(normal, float)
    return _row(DISK, centre, (radius, 0, 0), n / norm3(n))


def plane(point, normal) -> np.ndarray:
    n = np.asarray(normal, float)
    return _row(PLANE, point, (0, 0, 0), n / norm3(n))


def rect(centre, normal, axis_u, half_u, half_v) -> np.ndarray:
    n = np.asarray(normal, float)
    n = n / norm3(n)     # fixed-order sums (foveatrack.fixed_order): BLAS's differ per CPU
    u = np.asarray(axis_u, float)
    u = u - n * dot3(u, n)
    return _row(RECT, centre, (half_u, half_v, 0), n, u / norm3(u))


@dataclass(frozen=True)
class Body:
    """Primitives of one rigid body (body frame) and their reflectivities (0-1)."""

    name: str
    prims: np.ndarray  # (M, 13)
    reflectivity: np.ndarray  # (M,)

    @property
    def bounding_radius_m(self) -> float:
        """Radius of a sphere about the body origin that contains every primitive."""
        r = 0.0
        for p in self.prims:
            kind = int(p[0])
            centre = norm3(p[1:4])
            if kind == SPHERE or kind == DISK:
                r = max(r, centre + p[4])
            elif kind == BOX:
                r = max(r, centre + norm3(p[4:7]))
            else:
                return math.inf
        return r


def quadrotor(span_m: float = 0.35, reflectivity: float = 0.3) -> Body:
    """A quadrotor of ``span_m`` motor-to-motor diagonal plus rotors (default ~0.35 m across).

    Proportions of a Phantom-class 350 mm frame: body 0.14 x 0.14 x 0.07 m, arms 0.025 m wide and
    0.016 m thick, rotor disks 0.2 m in diameter, 0.02 m above the arms.  Rotor disks stand for the
    spinning blades (a solid disk: a 100 ms frame sees them smeared over the whole disk); they
    return at half the body's reflectivity.
    """
    k = span_m / 0.35
    prims = [box((0, 0, 0), (0.07 * k, 0.07 * k, 0.035 * k))]
    refl = [reflectivity]
    arm_half = span_m / 2 / 2  # half of the arm from centre to motor
    for i in range(4):
        ang = math.pi / 4 + i * math.pi / 2
        ca, sa = math.cos(ang), math.sin(ang)
        prims.append(box((ca * arm_half, sa * arm_half, 0.0), (arm_half, 0.0125 * k, 0.008 * k), ang))
        refl.append(reflectivity)
        prims.append(disk((ca * span_m / 2, sa * span_m / 2, 0.028 * k), 0.1 * k))
        refl.append(reflectivity / 2)
    return Body("quadrotor", np.array(prims), np.array(refl))


def sphere_body(radius_m: float, reflectivity: float = 0.5) -> Body:
    return Body("sphere", np.array([sphere((0, 0, 0), radius_m)]), np.array([reflectivity]))


def box_body(size_m, reflectivity: float = 0.5) -> Body:
    half = np.asarray(size_m, float) / 2
    return Body("box", np.array([box((0, 0, 0), half)]), np.array([reflectivity]))


# --- background -------------------------------------------------------------------------------

def ground(height_m: float) -> np.ndarray:
    """Ground plane ``height_m`` below the head (z = -height_m), facing up."""
    return plane((0, 0, -height_m), (0, 0, 1))


def wall(centre, normal, width_m, height_m) -> np.ndarray:
    n = np.asarray(normal, float)
    u = np.cross((0, 0, 1), n)
    if norm3(u) < 1e-9:
        u = np.array([1.0, 0, 0])
    return rect(centre, n, u, width_m / 2, height_m / 2)


def room(size_m, centre=(0.0, 0.0, 0.0)) -> list[np.ndarray]:
    """Inside of a box room (floor, ceiling, four walls) as six rectangles."""
    sx, sy, sz = (float(v) / 2 for v in size_m)
    cx, cy, cz = (float(v) for v in centre)
    return [
        rect((cx + sx, cy, cz), (-1, 0, 0), (0, 1, 0), sy, sz),
        rect((cx - sx, cy, cz), (1, 0, 0), (0, 1, 0), sy, sz),
        rect((cx, cy + sy, cz), (0, -1, 0), (1, 0, 0), sx, sz),
        rect((cx, cy - sy, cz), (0, 1, 0), (1, 0, 0), sx, sz),
        rect((cx, cy, cz + sz), (0, 0, -1), (1, 0, 0), sx, sy),
        rect((cx, cy, cz - sz), (0, 0, 1), (1, 0, 0), sx, sy),
    ]
