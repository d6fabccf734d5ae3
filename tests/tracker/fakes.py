"""TEST DOUBLES (not the project's head or world model): a small kinematic pan/tilt head and
synthetic point clouds, written here so the tracker's tests do not depend on gimbal/ or sim/.

FakeHead: true speed per byte from a given function, dead time, optional acceleration limit,
tilt stops; angles integrated exactly between commands (piecewise constant acceleration,
evaluated on a fine grid only for the acceleration phase).
"""

from __future__ import annotations

import math

import numpy as np

from foveatrack.control import HeadCommand
from foveatrack.reconstruction import rotation_matrix

TURBO = 0xFF


def nonlinear_speed(vmax, power=1.7, dead_bytes=3, turbo=None):
    """A nonlinear monotone curve with a dead zone: 0 below ``dead_bytes``."""
    def f(b):
        if b == TURBO:
            return turbo
        if b < dead_bytes:
            return 0.0
        return vmax * ((b - dead_bytes + 1) / (64 - dead_bytes)) ** power
    return f


class FakeHead:
    def __init__(self, pan_speed, tilt_speed, *, dead_time_s=0.0, accel_deg_s2=None, pan0=0.0, tilt0=0.0,
                 tilt_limits=(-90.0, 90.0)):
        self.speed = {"pan": pan_speed, "tilt": tilt_speed}
        self.dead = dead_time_s
        self.accel = accel_deg_s2
        self.limits = tilt_limits
        # per axis: list of (t_eff, v_target); state integrated lazily
        self.t = 0.0
        self.ang = {"pan": pan0, "tilt": tilt0}
        self.v = {"pan": 0.0, "tilt": 0.0}
        self.tgt = {"pan": 0.0, "tilt": 0.0}
        self.pending = []   # (t_eff, axis, v_target)

    def command(self, t_s, cmd: HeadCommand):
        for axis in ("pan", "tilt"):
            d, b = cmd.axis(axis)
            v = 0.0 if d == 0 else d * self.speed[axis](b)
            self.pending.append((t_s + self.dead, axis, v))
        self.pending.sort(key=lambda x: x[0])

    def _adv_axis(self, axis, dt):
        a, v, tgt = self.accel, self.v[axis], self.tgt[axis]
        if a is None or v == tgt:
            self.ang[axis] += tgt * dt
            self.v[axis] = tgt
        else:
            T = abs(tgt - v) / a
            s = math.copysign(a, tgt - v)
            if dt <= T:
                self.ang[axis] += v * dt + 0.5 * s * dt * dt
                self.v[axis] = v + s * dt
            else:
                self.ang[axis] += v * T + 0.5 * s * T * T + tgt * (dt - T)
                self.v[axis] = tgt
        if axis == "tilt":
            lo, hi = self.limits
            if not lo <= self.ang[axis] <= hi:
                self.ang[axis] = min(max(self.ang[axis], lo), hi)
                self.v[axis] = 0.0

    def advance(self, t):
        while self.pending and self.pending[0][0] <= t:
            te, axis, v = self.pending.pop(0)
            for ax in ("pan", "tilt"):
                self._adv_axis(ax, te - self.t)
            self.t = te
            self.tgt[axis] = v
        for ax in ("pan", "tilt"):
            self._adv_axis(ax, t - self.t)
        self.t = t

    def angles_at_times(self, ts):
        """Angles at increasing times (advances the head)."""
        out = np.empty((len(ts), 2))
        for i, t in enumerate(ts):
            self.advance(t)
            out[i] = self.ang["pan"], self.ang["tilt"]
        return out


def world_to_lidar(w, pan, tilt):
    return rotation_matrix(pan, tilt).T @ np.asarray(w, float)


def world_to_lidar_many(w, pan_deg, tilt_deg):
    """Vectorised R(pan_i, tilt_i)^T w_i for arrays (n,3), (n,), (n,)."""
    p, t = np.radians(pan_deg), np.radians(tilt_deg)
    cp, sp, ct, st = np.cos(p), np.sin(p), np.cos(t), np.sin(t)
    x, y, z = w[:, 0], w[:, 1], w[:, 2]
    # R = [[cp ct, -sp, -cp st], [sp ct, cp, -sp st], [st, 0, ct]]; R^T w:
    return np.column_stack([cp * ct * x + sp * ct * y + st * z,
                            -sp * x + cp * y,
                            -cp * st * x - sp * st * y + ct * z])


def target_frame(head: FakeHead, target_fn, t0, t1, rng, n=40, spread_m=0.1):
    """Points on a small target (gaussian blob) whose world centre is target_fn(t), seen by the
    head; returns (xyz_lidar (n,3), t_ns (n,)).  Times evenly spread in [t0, t1)."""
    t_ns = np.linspace(int(round(t0 * 1e9)), int(round(t1 * 1e9)) - 1, n).astype(np.int64)
    ang = head.angles_at_times(t_ns * 1e-9)
    xyz = np.empty((n, 3))
    for i in range(n):
        w = np.asarray(target_fn(t_ns[i] * 1e-9)) + rng.normal(0, spread_m, 3)
        xyz[i] = world_to_lidar(w, ang[i, 0], ang[i, 1])
    return xyz, t_ns


def corner_frame(head: FakeHead, corner, normals, t0, t1, rng, n=900, size_m=0.6, noise_m=0.01,
                 fov_deg=38.4):
    """Points on the three faces of an inside room corner at world point ``corner``.  ``normals``
    are the three face normals pointing into the room; each face is a square of ``size_m`` spanned by
    the two other normals' negatives (the walls extend away from the corner, into the room side).
    Points outside the lidar's circular FoV are dropped; range noise along the ray."""
    corner = np.asarray(corner, float)
    N = [np.asarray(v, float) / np.linalg.norm(v) for v in normals]
    t_ns = np.sort(rng.integers(int(round(t0 * 1e9)), int(round(t1 * 1e9)), n)).astype(np.int64)
    ang = head.angles_at_times(t_ns * 1e-9)
    face = rng.integers(0, 3, n)
    u = rng.uniform(0, size_m, n)[:, None]
    v = rng.uniform(0, size_m, n)[:, None]
    A = np.array([N[1], N[0], N[0]])[face]
    B = np.array([N[2], N[2], N[1]])[face]
    pts = corner + u * A + v * B          # into the room along the other two normals
    p = world_to_lidar_many(pts, ang[:, 0], ang[:, 1])
    r = np.linalg.norm(p, axis=1)
    xyz = p * (1 + rng.normal(0, noise_m, n) / r)[:, None]
    off = np.degrees(np.arccos(np.clip(xyz[:, 0] / np.linalg.norm(xyz, axis=1), -1, 1)))
    keep = off <= fov_deg / 2
    return xyz[keep], t_ns[keep]
