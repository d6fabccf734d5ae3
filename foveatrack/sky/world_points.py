"""A frame's points turned into the world frame at each point's own head pose.

The head may turn during a 100 ms frame (a saccade at tens of deg/s), so one pose per frame would
smear static scenery by metres at 100 m and the background (learned in world cubes,
:mod:`foveatrack.sky.tracks`) would never settle.  The pose estimate (the tracker's dead reckoning,
:class:`foveatrack.reconstruction.Reconstructor`, or anything with its ``angles_at`` and
``lidar_offset_m``) is asked at ``nodes`` instants evenly across the frame; each point's rotation is
the linear blend of the two nodes' matrices around its time (matrix entries move by at most
``(w dt)^2 / 8`` off the true rotation: 3.8e-5 at 100 deg/s and 10 ms nodes, 3.8 mm at 100 m), and
``p_world = R(t) (p_lidar + offset)`` -- the same turn as :meth:`Reconstructor.lidar_to_world`
(:func:`foveatrack.reconstruction.rotation_matrix`).  Every product is elementwise on columns in the
fixed order x, y, z (no BLAS: :mod:`foveatrack.fixed_order`).

The per-point loop is a numba kernel (:func:`world_points_kernel`: 48 k points of a 480 k points/s
frame in well under a millisecond, where the numpy form took ~8 ms; the points' node coordinates in a
loop of their own, vectorised); its plain-numpy twin
:func:`lidar_to_world_per_point_numpy` is what ``tests/sky/test_world_points.py`` compares it with,
bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from foveatrack.kernels import valid_point
from foveatrack.reconstruction import rotation_rows


def node_rotations(pose, t0_s: float, t1_s: float, nodes: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Node times (K,) [s], rotations (K, 3, 3) of the head between ``t0_s`` and ``t1_s``, and the
    nodes' spacing [s].  A frame of no length (or reversed) has one pose, at ``t0_s``, given as two
    equal nodes 1 s apart: every point takes it (there is no spacing to divide by)."""
    k = max(int(nodes), 2)
    step = (t1_s - t0_s) / (k - 1)
    if not step > 0.0:
        p, tl, _, _ = pose.angles_at(t0_s)
        return np.array([t0_s, t0_s + 1.0]), np.array([rotation_rows(p, tl)] * 2, np.float64), 1.0
    ts = [t0_s + (t1_s - t0_s) * i / (k - 1) for i in range(k)]
    times = np.array(ts)
    many = getattr(pose, "pan_tilt_array", None)     # the dead reckoning's, without the sigmas, as an array
    angles = many(times, True) if many is not None else np.array([pose.angles_at(t)[:2] for t in ts], np.float64)
    # every node's entries by one kernel call (rotation_entries' arithmetic), where eleven calls of it
    # and the array made of their lists took more than the poses
    R = np.empty((k, 3, 3))
    rotation_entries_kernel(angles, R)
    return times, R, step


@njit(cache=True)
def rotation_entries_kernel(angles, out):
    """``out[i]`` (3, 3): :func:`foveatrack.reconstruction.rotation_entries` of the pose ``angles[i]``
    ``(pan_deg, tilt_deg)``, its arithmetic in its order (pan outside (-180, 180] wrapped as
    ``wrap_deg`` wraps a float; libm's cos and sin, as CPython's math calls them; its twin in
    ``tests/sky/test_world_points.py``)."""
    for i in range(angles.shape[0]):
        pan = angles[i, 0]
        if not (-180.0 < pan <= 180.0):
            w = np.fmod(pan + 180.0, 360.0)      # C fmod (math.fmod is not in numba)
            w = (w + 360.0 if w < 0.0 else w) - 180.0
            pan = 180.0 if w == -180.0 else w
        p = math.radians(pan)
        t = math.radians(angles[i, 1])
        cp = math.cos(p)
        sp = math.sin(p)
        ct = math.cos(t)
        st = math.sin(t)
        out[i, 0, 0] = cp * ct
        out[i, 0, 1] = -sp
        out[i, 0, 2] = -cp * st
        out[i, 1, 0] = sp * ct
        out[i, 1, 1] = cp
        out[i, 1, 2] = -sp * st
        out[i, 2, 0] = st
        out[i, 2, 1] = 0.0
        out[i, 2, 2] = ct


@njit(cache=True)
def _node_places(t_ns, t0_s, step_s, last):
    """Every point's place between the nodes, in a loop of its own that the compiler vectorises (the
    division was half a point's cost one at a time: 25 -> 13 us for a frame's 3 k points)."""
    n = t_ns.shape[0]
    U = np.empty(n)
    for k in range(n):
        u = (t_ns[k] * 1e-9 - t0_s) / step_s
        U[k] = min(max(u, 0.0), last * 1.0)
    return U


@njit(cache=True)
def _node_changes(R):
    """Each node interval's change of the entries (K - 1, 3, 3), once, not once a point."""
    last = R.shape[0] - 1
    D = np.empty((last, 3, 3))
    for i in range(last):
        for r in range(3):
            for c in range(3):
                D[i, r, c] = R[i + 1, r, c] - R[i, r, c]
    return D


@njit(cache=True)
def _interval(u, last):
    """The node interval ``i`` of a point at place ``u`` (>= 0) between ``last + 1`` nodes, and its
    weight ``w`` in it."""
    i = min(int(u), last - 1)       # u >= 0: truncation is floor
    return i, u - i


@njit(cache=True)
def _entry_row(R, D, i, w, r, qx, qy, qz):
    """Row ``r`` of a point ``q`` turned in node interval ``i`` at weight ``w``: the entries blended,
    then their products with ``q`` summed in a fixed order."""
    m0 = R[i, r, 0] + D[i, r, 0] * w
    m1 = R[i, r, 1] + D[i, r, 1] * w
    m2 = R[i, r, 2] + D[i, r, 2] * w
    return m0 * qx + m1 * qy + m2 * qz


@njit(cache=True)
def _turn(xyz, k, R, D, u, off, out, row):
    """Point ``k`` of ``xyz`` turned at its place ``u`` between the nodes, into ``out[row]``."""
    i, w = _interval(u, R.shape[0] - 1)
    qx = xyz[k, 0] + off[0]
    qy = xyz[k, 1] + off[1]
    qz = xyz[k, 2] + off[2]
    for r in range(3):
        out[row, r] = _entry_row(R, D, i, w, r, qx, qy, qz)


@njit(cache=True)
def world_points_kernel(xyz, t_ns, R, t0_s, step_s, off, out):
    """The per-point turn (module docstring): ``R`` (K, 3, 3) the node rotations ``step_s`` apart from
    ``t0_s``, ``off`` (3,) the lidar's offset; written into ``out`` (N, 3)."""
    U = _node_places(t_ns, t0_s, step_s, R.shape[0] - 1)
    D = _node_changes(R)
    for k in range(xyz.shape[0]):
        _turn(xyz, k, R, D, U[k], off, out, k)


@njit(cache=True)
def first_valid_kernel(xyz):
    """The index of the first point of ``xyz`` (N, 3) that is valid (:func:`foveatrack.kernels.valid_point`),
    -1 for none."""
    for j in range(xyz.shape[0]):
        if valid_point(xyz[j, 0], xyz[j, 1], xyz[j, 2]):
            return j
    return -1


@njit(cache=True)
def world_in_box_kernel(xyz, t_ns, R, t0_s, step_s, off, lo, hi, xyz_out, t_out, world_out):
    """The valid points of ``xyz`` (N, 3) (:func:`foveatrack.kernels.valid_point`), each turned as
    :func:`world_points_kernel` turns it, and of those the ones inside the world box ``lo <= p < hi``
    (:func:`foveatrack.kernels.box_inside_kernel`'s test): their lidar points, times and world points
    into the first rows of ``xyz_out``, ``t_out``, ``world_out``, in point order; returns how many.
    One pass where the validity test, the turn, the box test and the cuts of three arrays were five
    (a frame's 3 k points, a tenth of them kept).  The world z first, each row by :func:`_turn`'s
    operations: the scenes' D has its floor just under the head, and on swarm + flock 12 of 2.4 k
    points a frame pass it; the others skip x and y (the kernel 25 -> 14 us a frame)."""
    n = xyz.shape[0]
    U = _node_places(t_ns, t0_s, step_s, R.shape[0] - 1)
    D = _node_changes(R)
    last = R.shape[0] - 1
    off0, off1, off2 = off[0], off[1], off[2]
    lo0, lo1, lo2 = lo[0], lo[1], lo[2]
    hi0, hi1, hi2 = hi[0], hi[1], hi[2]
    m = 0
    for k in range(n):
        x = xyz[k, 0]
        y = xyz[k, 1]
        z = xyz[k, 2]
        if not valid_point(x, y, z):
            continue
        i, w = _interval(U[k], last)
        qx = x + off0
        qy = y + off1
        qz = z + off2
        wz = _entry_row(R, D, i, w, 2, qx, qy, qz)
        if not ((wz >= lo2) & (wz < hi2)):
            continue
        wx = _entry_row(R, D, i, w, 0, qx, qy, qz)
        wy = _entry_row(R, D, i, w, 1, qx, qy, qz)
        if (wx >= lo0) & (wx < hi0) & (wy >= lo1) & (wy < hi1):
            world_out[m, 0] = wx
            world_out[m, 1] = wy
            world_out[m, 2] = wz
            xyz_out[m, 0] = x
            xyz_out[m, 1] = y
            xyz_out[m, 2] = z
            t_out[m] = t_ns[k]
            m += 1
    return m


def lidar_to_world_per_point(xyz: np.ndarray, t_ns: np.ndarray, pose, t0_s: float, t1_s: float,
                             nodes: int = 11) -> np.ndarray:
    """Points (N, 3) of the lidar frame -> world (N, 3), each at its own time ``t_ns`` (see module)."""
    xyz = np.ascontiguousarray(xyz, np.float64).reshape(-1, 3)
    n = xyz.shape[0]
    if n == 0:
        return np.empty((0, 3))
    _, R, step = node_rotations(pose, t0_s, t1_s, nodes)
    off = np.ascontiguousarray(np.asarray(pose.lidar_offset_m, np.float64).reshape(3))
    out = np.empty((n, 3))
    world_points_kernel(xyz, np.ascontiguousarray(t_ns, np.int64), R, float(t0_s), step, off, out)
    return out


def lidar_to_world_in_box(xyz: np.ndarray, t_ns: np.ndarray, pose, t0_s: float, t1_s: float, nodes: int,
                          lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The valid points of a frame (finite, not (0, 0, 0)) turned into the world as
    :func:`lidar_to_world_per_point` turns them, and of those the ones inside the world box ``[lo,
    hi)``: ``(xyz, t_ns, world)`` of those, in point order (:func:`world_in_box_kernel`).  The pose
    is asked only for a frame with a valid point, as the turn of the valid points asks it."""
    xyz = np.ascontiguousarray(xyz, np.float64).reshape(-1, 3)
    t_ns = np.ascontiguousarray(t_ns, np.int64)
    if first_valid_kernel(xyz) < 0:
        return np.empty((0, 3)), np.empty(0, np.int64), np.empty((0, 3))
    _, R, step = node_rotations(pose, t0_s, t1_s, nodes)
    off = np.ascontiguousarray(np.asarray(pose.lidar_offset_m, np.float64).reshape(3))
    n = xyz.shape[0]
    xyz_out, t_out, world = np.empty((n, 3)), np.empty(n, np.int64), np.empty((n, 3))
    m = world_in_box_kernel(xyz, t_ns, R, float(t0_s), step, off, lo, hi, xyz_out, t_out, world)
    return xyz_out[:m], t_out[:m], world[:m]


def lidar_to_world_in_box_numpy(xyz: np.ndarray, t_ns: np.ndarray, pose, t0_s: float, t1_s: float, nodes: int,
                                lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Twin of :func:`lidar_to_world_in_box`: the validity mask, :func:`lidar_to_world_per_point_numpy`
    and the box's numpy test, as the sky tracker made them before."""
    from foveatrack.detection import valid_points

    ok = valid_points(xyz)
    xyz, t_ns = np.asarray(xyz, np.float64)[ok], np.asarray(t_ns, np.int64)[ok]
    world = lidar_to_world_per_point_numpy(xyz, t_ns, pose, t0_s, t1_s, nodes)
    x, y, z = world[:, 0], world[:, 1], world[:, 2]
    inside = np.flatnonzero((x >= lo[0]) & (x < hi[0]) & (y >= lo[1]) & (y < hi[1]) & (z >= lo[2]) & (z < hi[2]))
    return xyz[inside], t_ns[inside], world[inside]


def lidar_to_world_per_point_numpy(xyz: np.ndarray, t_ns: np.ndarray, pose, t0_s: float, t1_s: float,
                                   nodes: int = 11) -> np.ndarray:
    """Twin of :func:`lidar_to_world_per_point` in plain numpy."""
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    n = xyz.shape[0]
    if n == 0:
        return np.empty((0, 3))
    ts, R, step = node_rotations(pose, t0_s, t1_s, nodes)
    off = np.asarray(pose.lidar_offset_m, np.float64).reshape(3).tolist()
    qx, qy, qz = xyz[:, 0] + off[0], xyz[:, 1] + off[1], xyz[:, 2] + off[2]
    t = np.asarray(t_ns, np.int64) * 1e-9
    u = np.clip((t - t0_s) / step, 0.0, ts.size - 1.0)
    i = np.minimum(np.floor(u).astype(np.int64), ts.size - 2)
    w = u - i
    a, b = R[i], R[i + 1]            # (N, 3, 3) the two nodes' rotations around each point
    M = a + (b - a) * w[:, None, None]
    out = np.empty((n, 3))
    for r in range(3):
        out[:, r] = M[:, r, 0] * qx + M[:, r, 1] * qy + M[:, r, 2] * qz
    return out
