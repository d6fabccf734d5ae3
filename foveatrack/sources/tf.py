"""The sensor's pose from a bag's ``/tf`` and ``/tf_static`` (``tf2_msgs/msg/TFMessage``): clouds
turned into a fixed frame (``--fixed-frame``, e.g. ``map`` or ``world``) before tracking, for a lidar
on a mount that moved while recording (a pan/tilt head, a vehicle).

Each edge parent -> child of the tree holds its transforms in time order; a lookup at time ``t``
takes, on every edge of the chain from the cloud's frame up to the fixed frame, the latest transform
at or before ``t`` (a static one at any time): no interpolation, so the pose may lag by up to one
``/tf`` period (ROS publishes it at 50-100 Hz for a moving mount).

A point ``p`` of the child frame is ``R(q) p + t`` in the parent frame (``geometry_msgs/Transform``:
translation ``t``, rotation quaternion ``q = (x, y, z, w)``).
"""

from __future__ import annotations

import bisect

import numpy as np

from foveatrack.errors import UserError
from foveatrack.fixed_order import mat3_vec, mats3_times_mat3, rows_times_mat3T

TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")


def quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a quaternion (normalised first)."""
    n = (x * x + y * y + z * z + w * w) ** 0.5
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def apply(R: np.ndarray, t: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """``R p + t`` for every row, in a fixed order (:mod:`foveatrack.fixed_order`: not BLAS's,
    which differs per CPU)."""
    return rows_times_mat3T(xyz, R) + t


class TfBuffer:
    def __init__(self):
        self._edges: dict[str, tuple[str, list[int], list]] = {}   # child -> (parent, times, (R, t))

    def add(self, parent: str, child: str, t_ns: int, translation, rotation_xyzw, static: bool) -> None:
        parent, child = parent.lstrip("/"), child.lstrip("/")
        R = quat_matrix(*(float(v) for v in rotation_xyzw))
        tr = np.array([float(v) for v in translation])
        entry = self._edges.get(child)
        if entry is None or entry[0] != parent:
            entry = self._edges[child] = (parent, [], [])
        _, times, poses = entry
        t = -(2 ** 62) if static else int(t_ns)
        i = bisect.bisect_right(times, t)
        times.insert(i, t)
        poses.insert(i, (R, tr))

    @property
    def frames(self) -> set[str]:
        return set(self._edges) | {p for p, _, _ in self._edges.values()}

    def lookup(self, target: str, source: str, t_ns: int, where: str) -> tuple[np.ndarray, np.ndarray]:
        """``(R, t)`` turning points of ``source`` into ``target`` at ``t_ns``."""
        target, source = target.lstrip("/"), source.lstrip("/")
        R, t = np.eye(3), np.zeros(3)
        frame, seen = source, set()
        while frame != target:
            if frame in seen or frame not in self._edges:
                known = ", ".join(sorted(self.frames)) or "none"
                raise UserError(f"{where}: no transform from {source!r} to {target!r} in /tf and /tf_static "
                                f"(frames: {known})")
            seen.add(frame)
            parent, times, poses = self._edges[frame]
            i = bisect.bisect_right(times, int(t_ns)) - 1
            if i < 0:
                raise UserError(f"{where}: /tf has no transform {parent!r} -> {frame!r} at or before "
                                f"{t_ns * 1e-9:.6f} s (the first is at {times[0] * 1e-9:.6f} s)")
            Re, te = poses[i]
            R, t = mats3_times_mat3(Re, R), mat3_vec(Re, t) + te     # fixed order, not BLAS's
            frame = parent
        return R, t
