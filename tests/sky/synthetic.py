"""Synthetic frames for the sky tracker's tests: objects as balls of points in the world, seen from a
head whose pose is a function of time, with a wall of static scenery behind them."""

from __future__ import annotations

import math

import numpy as np

from foveatrack.frames import Frame
from foveatrack.reconstruction import rotation_matrix


class Pose:
    """``angles_at(t) -> (pan, tilt, 0, 0)`` from a function of time; no lidar offset."""

    def __init__(self, fn=lambda t: (0.0, 0.0)):
        self.fn = fn
        self.lidar_offset_m = np.zeros(3)

    def angles_at(self, t_s):
        p, t = self.fn(t_s)
        return p, t, 0.0, 0.0


def frame_of(objects, t0, t1, pose, rng, n_per_object=30, wall=True, half_angle_deg=None):
    """A frame seeing ``objects`` (list of callables t -> (centre (3,), radius)) from ``pose``.  Each
    point gets its own time; points off the field (``half_angle_deg``) are dropped."""
    xyz, t_ns = [], []
    items = [(f, n_per_object) for f in objects]
    if wall:   # a static wall 60 m ahead: scenery the background must learn
        items.append((lambda t: (np.array([60.0, 0.0, 5.0]), None), 200))
    for f, n in items:
        ts = np.sort(rng.uniform(t0, t1, n))
        for t in ts:
            c, r = f(t)
            if r is None:
                p = c + np.array([0.0, rng.uniform(-3, 3), rng.uniform(-1.5, 1.5)])
            else:
                d = rng.normal(size=3)
                p = c + r * d / math.sqrt(float(d @ d))
            pan, tilt, _, _ = pose.angles_at(t)
            q = rotation_matrix(pan, tilt).T @ p
            if half_angle_deg is not None:
                if math.degrees(math.atan2(math.hypot(q[1], q[2]), q[0])) > half_angle_deg:
                    continue
            xyz.append(q)
            t_ns.append(int(round(t * 1e9)))
    if not xyz:
        return Frame(t0, t1, np.empty((0, 3)), np.empty(0, np.int64))
    o = np.argsort(t_ns, kind="stable")
    return Frame(t0, t1, np.array(xyz)[o], np.array(t_ns, np.int64)[o])


def run(tracker, objects, duration_s, pose=None, seed=0, fovea=None, **kw):
    """Frames at 10 Hz through ``tracker``; ``fovea(out_prev) -> track id or None``.  Returns outputs."""
    pose = pose or Pose()
    rng = np.random.default_rng(seed)
    outs = []
    for k in range(int(round(duration_s * 10))):
        t0, t1 = k * 0.1, (k + 1) * 0.1
        fr = frame_of(objects, t0, t1, pose, rng, **kw)
        outs.append(tracker.process(fr, pose, None if fovea is None else fovea(outs[-1] if outs else None)))
    return outs


def straight(p0, v, radius=0.2):
    p0, v = np.asarray(p0, float), np.asarray(v, float)
    return lambda t: (p0 + v * t, radius)
