"""Numba kernels of the virtual world: beam rotation by the head, and exact ray-primitive intersection.

Every kernel takes arrays and scalars only and has a plain-numpy twin in ``tests/world_twins.py``.
Rays start at the origin of the frame they are given in (the lidar's optical centre, at the head's
rotation centre); ranges are in metres, ``inf`` where nothing is hit.

Primitive table (one row per primitive, body frame of its owner), ``prims`` (M, 13) float64:

=====  ==========================================================================================
col    meaning
=====  ==========================================================================================
0      kind: 0 sphere, 1 box (oriented), 2 disk (one-sided flat circle), 3 plane (infinite),
       4 rectangle (finite plane patch)
1-3    centre (sphere, box, disk, rectangle) or a point on the plane [m]
4-6    sphere: (radius, 0, 0); box: half extents along its axes u, v, w [m];
       disk: (radius, 0, 0); rectangle: (half_u, half_v, 0) [m]; plane: unused
7-9    box: axis u (unit); disk/plane/rectangle: unit normal
10-12  box: axis v (unit; w = u x v); rectangle: axis u (unit; v = n x u)
=====  ==========================================================================================
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import overload

from sim.scan.kernels import RAY_OK

SPHERE, BOX, DISK, PLANE, RECT = 0, 1, 2, 3, 4
_BLOCK = 256   # beams per x, y, z block (rotation runs: a 1 ms run of a Mid-40 is 100; background cast)
PRIM_COLUMNS = 13
_EPS = 1e-12


@njit(cache=True)
def rotate_pan_tilt_kernel(d_lidar, pan_rad, tilt_rad, out):
    """World direction of each beam: :math:`R_z(\\mathrm{pan})\\,R_y(-\\mathrm{tilt})\\,d`.

    Pan turns about world +Z (positive = left, counter-clockwise from above); tilt raises the lidar's
    +X toward +Z (positive = up), i.e. a rotation of ``-tilt`` about the panned +Y axis.  At pan =
    tilt = 0 the lidar frame is the world frame (X forward, Y left, Z up).
    """
    for j in range(d_lidar.shape[0]):
        x = d_lidar[j, 0]
        y = d_lidar[j, 1]
        z = d_lidar[j, 2]
        ct = math.cos(tilt_rad[j])
        st = math.sin(tilt_rad[j])
        # R_y(-tilt): x' = x cos t - z sin t ; z' = x sin t + z cos t
        x1 = x * ct - z * st
        z1 = x * st + z * ct
        cp = math.cos(pan_rad[j])
        sp = math.sin(pan_rad[j])
        out[j, 0] = x1 * cp - y * sp
        out[j, 1] = x1 * sp + y * cp
        out[j, 2] = z1


@njit(cache=True, inline="always")
def _box_axes(prims, m):
    """A box's unit axes u, v (its columns 7-12) and w = u x v, as nine floats."""
    ux, uy, uz = prims[m, 7], prims[m, 8], prims[m, 9]
    vx, vy, vz = prims[m, 10], prims[m, 11], prims[m, 12]
    return ux, uy, uz, vx, vy, vz, uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


@njit(cache=True, inline="always")
def _hit_prim(prims, m, ox, oy, oz, dx, dy, dz):
    """Smallest positive distance along the ray (o, d) to primitive ``m``; inf if missed."""
    kind = int(prims[m, 0])
    cx = prims[m, 1] - ox
    cy = prims[m, 2] - oy
    cz = prims[m, 3] - oz
    if kind == SPHERE:
        r = prims[m, 4]
        b = cx * dx + cy * dy + cz * dz
        c = cx * cx + cy * cy + cz * cz - r * r
        disc = b * b - c
        if disc < 0.0:
            return math.inf
        s = math.sqrt(disc)
        t = b - s
        if t > _EPS:
            return t
        t = b + s
        return t if t > _EPS else math.inf
    if kind == BOX:
        ux, uy, uz, vx, vy, vz, wx, wy, wz = _box_axes(prims, m)
        t_near = -math.inf
        t_far = math.inf
        for axis in range(3):
            if axis == 0:
                ax, ay, az, h = ux, uy, uz, prims[m, 4]
            elif axis == 1:
                ax, ay, az, h = vx, vy, vz, prims[m, 5]
            else:
                ax, ay, az, h = wx, wy, wz, prims[m, 6]
            e = ax * cx + ay * cy + az * cz  # centre offset along the axis
            f = ax * dx + ay * dy + az * dz  # ray direction along the axis
            if abs(f) > _EPS:
                t1 = (e - h) / f
                t2 = (e + h) / f
                if t1 > t2:
                    t1, t2 = t2, t1
                if t1 > t_near:
                    t_near = t1
                if t2 < t_far:
                    t_far = t2
                if t_near > t_far or t_far < _EPS:
                    return math.inf
            elif -e - h > 0.0 or -e + h < 0.0:
                return math.inf
        return t_near if t_near > _EPS else (t_far if t_far > _EPS else math.inf)
    # Flat kinds: plane through the centre with normal n.
    nx, ny, nz = prims[m, 7], prims[m, 8], prims[m, 9]
    den = nx * dx + ny * dy + nz * dz
    if abs(den) < _EPS:
        return math.inf
    t = (nx * cx + ny * cy + nz * cz) / den
    if t <= _EPS:
        return math.inf
    if kind == PLANE:
        return t
    px = dx * t - cx
    py = dy * t - cy
    pz = dz * t - cz
    if kind == DISK:
        r = prims[m, 4]
        return t if px * px + py * py + pz * pz <= r * r else math.inf
    # RECT
    ux, uy, uz = prims[m, 10], prims[m, 11], prims[m, 12]
    vx = ny * uz - nz * uy
    vy = nz * ux - nx * uz
    vz = nx * uy - ny * ux
    a = px * ux + py * uy + pz * uz
    b = px * vx + py * vy + pz * vz
    return t if (abs(a) <= prims[m, 4] and abs(b) <= prims[m, 5]) else math.inf


@njit(cache=True, nogil=True, error_model="numpy")   # den = 0 gives inf/nan (masked), not an exception
def cast_static_kernel(d_world, prims, prim_offset, out_range, out_prim):
    """Nearest hit of rays from the origin against static primitives (the background).

    ``out_range``/``out_prim`` are updated only where a primitive is nearer than the value already
    there (so targets and background can be cast in either order); hits record ``prim_offset + m``.

    Block by block (256 rays copied into x, y, z arrays), then
    primitive by primitive (each ray still meets them in table order, so the result is the same as
    ray by ray): the flat kinds of a background — ground plane, walls and room faces (rectangles),
    disks — get branch-free loops with their constants hoisted (:func:`_cast_flat_block`) that LLVM
    vectorises, with :func:`_hit_prim`'s arithmetic unchanged; opposed rectangles with the origin
    between them (a room's walls) are tested one per ray (:func:`_pair_hit`), a room's three pairs
    in one pass.  A 60 x 40 x 8 m hall (six rectangles) on a 10k-ray frame: 650 -> 190-240 us
    (blocks) -> 115-150 us (room pass), the same bits throughout.
    """
    n = d_world.shape[0]
    # Blocks for one primitive too (a ground plane): straight through the rows (strided columns)
    # measured 190 us against 75 us in blocks on a 10k-ray frame, and compiled every block helper
    # a second time for strided arrays (~9 s of CPU on a first run).
    bx = np.empty(_BLOCK)
    by = np.empty(_BLOCK)
    bz = np.empty(_BLOCK)
    br = np.empty(_BLOCK)
    bp = np.empty(_BLOCK, dtype=np.int64)
    d_flat = d_world.reshape(-1)
    for j0 in range(0, n, _BLOCK):
        m_blk = min(_BLOCK, n - j0)
        r_blk = out_range[j0:j0 + m_blk]
        p_blk = out_prim[j0:j0 + m_blk]
        _rows_to_xyz(d_flat[3 * j0:3 * (j0 + m_blk)], m_blk, bx, by, bz)
        for i in range(m_blk):
            br[i] = r_blk[i]
            bp[i] = p_blk[i]
        _cast_prims(prims, prim_offset, bx, by, bz, m_blk, br, bp)
        for i in range(m_blk):
            r_blk[i] = br[i]
            p_blk[i] = bp[i]


# The helpers called once per block (this one, the block loops, the per-block constants) are
# compiled as functions of their own, not inlined by numba: inlined, they made cast_static_kernel's
# first compile 70 s of CPU (its body was typed twice, for row and block arrays); then ~25 s, with the
# same bits and time per frame, and ~14 s since one primitive goes through the blocks too (one array layout).  The per-ray helpers (_hit_prim, _pair_hit, _plane_point) stay
# inlined: called per ray across a function boundary they measured several times slower.
@njit(cache=True, error_model="numpy")
def _cast_prims(prims, prim_offset, bx, by, bz, n, br, bp):
    """Every primitive, in table order, against ``n`` rays given as x, y, z arrays."""
    m = np.int64(0)     # not the literal 0: the callees given ``m`` would also compile for Literal[int](0)
    while m < prims.shape[0]:
        kind = int(prims[m, 0])
        if kind == RECT and _opposed_rects(prims, m):
            if _opposed_rects(prims, m + 2) and _opposed_rects(prims, m + 4):
                # A room (floor, ceiling, four walls): its three pairs in one pass over the rays.
                _cast_room_block(_pair_constants(prims, m), _pair_constants(prims, m + 2),
                                 _pair_constants(prims, m + 4), prim_offset + m, bx, by, bz, n, br, bp)
                m += 6
            else:
                _cast_pair_block(_pair_constants(prims, m), prim_offset + m, bx, by, bz, n, br, bp)
                m += 2
            continue
        if kind == PLANE or kind == RECT or kind == DISK:
            _cast_flat_block(prims, m, kind, prim_offset + m, bx, by, bz, n, br, bp)
        else:
            for i in range(n):
                t = _hit_prim(prims, m, 0.0, 0.0, 0.0, bx[i], by[i], bz[i])
                if t < br[i]:
                    br[i] = t
                    bp[i] = prim_offset + m
        m += 1


@njit(cache=True)
def _opposed_rects(prims, m):
    """Rows ``m`` and ``m + 1`` are rectangles on parallel planes with exactly opposite normals and
    the origin strictly between them (a room's opposite walls, or its floor and ceiling): a ray from
    the origin can then hit only the one it heads toward (:func:`_pair_hit`)."""
    if m + 1 >= prims.shape[0] or int(prims[m, 0]) != RECT or int(prims[m + 1, 0]) != RECT:
        return False
    if not (prims[m + 1, 7] == -prims[m, 7] and prims[m + 1, 8] == -prims[m, 8] and prims[m + 1, 9] == -prims[m, 9]):
        return False
    num_a = prims[m, 7] * prims[m, 1] + prims[m, 8] * prims[m, 2] + prims[m, 9] * prims[m, 3]
    num_b = prims[m + 1, 7] * prims[m + 1, 1] + prims[m + 1, 8] * prims[m + 1, 2] + prims[m + 1, 9] * prims[m + 1, 3]
    return (num_a > _EPS and num_b > _EPS) or (num_a < -_EPS and num_b < -_EPS)


@njit(cache=True)
def _rect_constants(prims, m):
    """What :func:`_cast_flat_block` hoists for rectangle ``m``: ``num = n . c``, the centre, the
    in-plane axes u and v = n x u, the half sizes."""
    nx, ny, nz = prims[m, 7], prims[m, 8], prims[m, 9]
    ux, uy, uz = prims[m, 10], prims[m, 11], prims[m, 12]
    return (nx * prims[m, 1] + ny * prims[m, 2] + nz * prims[m, 3], prims[m, 1], prims[m, 2], prims[m, 3],
            ux, uy, uz, ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux, prims[m, 4], prims[m, 5])


@njit(cache=True)
def _pair_constants(prims, m):
    """Rectangle ``m``'s normal, whether its plane lies on the positive side (``num > 0``), and
    both rectangles' :func:`_rect_constants`."""
    return (prims[m, 7], prims[m, 8], prims[m, 9], _rect_constants(prims, m)[0] > 0.0,
            _rect_constants(prims, m), _rect_constants(prims, m + 1))


@njit(cache=True, inline="always", error_model="numpy")
def _pair_hit(K, dx, dy, dz):
    """Range to the pair ``K`` (:func:`_pair_constants`) along ``d`` and whether it is a hit of the
    first rectangle, the second, or neither (-1).

    With the origin between the planes, ``t = num / den`` is positive for at most one of them
    (``den_b = -den_a`` exactly and both ``num`` have one sign), so the ray is tested against the one
    whose ``num`` has the sign of its ``den`` only, with :func:`_cast_flat_block`'s arithmetic for
    it: the same ranges and ids, to the bit, as testing both (the other cannot hit)."""
    nx, ny, nz, pos_a, A, B = K
    den_a = nx * dx + ny * dy + nz * dz
    on_a = (den_a > 0.0) == pos_a             # t_a = num_a / den_a > 0: heading for the first
    R = A if on_a else B
    den = den_a if on_a else -den_a           # the second's n . d, exactly
    num, cx, cy, cz, ux, uy, uz, vx, vy, vz, h_u, h_v = R
    t = num / den
    px = dx * t - cx
    py = dy * t - cy
    pz = dz * t - cz
    ok = ((abs(den) >= _EPS) & (t > _EPS)
          & (abs(px * ux + py * uy + pz * uz) <= h_u) & (abs(px * vx + py * vy + pz * vz) <= h_v))
    return t, (0 if on_a else 1) if ok else -1


@njit(cache=True, error_model="numpy")
def _cast_pair_block(K, label, bx, by, bz, n, br, bp):
    """Two opposed rectangles (:func:`_opposed_rects`) against a block: one plane test per ray."""
    for i in range(n):
        t, w = _pair_hit(K, bx[i], by[i], bz[i])
        hit = (w >= 0) & (t < br[i])
        br[i] = t if hit else br[i]
        bp[i] = label + w if hit else bp[i]


@njit(cache=True, error_model="numpy")
def _cast_room_block(K0, K1, K2, label, bx, by, bz, n, br, bp):
    """Three opposed pairs (a room) against a block in one pass, pair by pair for each ray (table
    order, as casting them one by one): the ray's range and id stay in registers between them."""
    for i in range(n):
        dx, dy, dz = bx[i], by[i], bz[i]
        r = br[i]
        p = bp[i]
        t, w = _pair_hit(K0, dx, dy, dz)
        hit = (w >= 0) & (t < r)
        r = t if hit else r
        p = label + w if hit else p
        t, w = _pair_hit(K1, dx, dy, dz)
        hit = (w >= 0) & (t < r)
        r = t if hit else r
        p = label + 2 + w if hit else p
        t, w = _pair_hit(K2, dx, dy, dz)
        hit = (w >= 0) & (t < r)
        br[i] = t if hit else r
        bp[i] = label + 4 + w if hit else p


@njit(cache=True, error_model="numpy")
def _cast_flat_block(prims, m, kind, label, bx, by, bz, n, br, bp):
    """Plane, rectangle or disk ``m`` against the ``n`` rays of a block, updating the block's
    nearest range ``br`` and primitive ``bp``.  One loop per kind and ``&`` instead of ``and``: a
    branch in the loop body would stop LLVM vectorising it."""
    cx, cy, cz = prims[m, 1], prims[m, 2], prims[m, 3]
    nx, ny, nz = prims[m, 7], prims[m, 8], prims[m, 9]
    num = nx * cx + ny * cy + nz * cz
    # rectangle: in-plane axes u and v = n x u, half sizes; disk: radius
    ux, uy, uz = prims[m, 10], prims[m, 11], prims[m, 12]
    vx = ny * uz - nz * uy
    vy = nz * ux - nx * uz
    vz = nx * uy - ny * ux
    h_u, h_v, r2 = prims[m, 4], prims[m, 5], prims[m, 4] * prims[m, 4]
    if kind == PLANE:
        for i in range(n):
            den = nx * bx[i] + ny * by[i] + nz * bz[i]
            t = num / den
            hit = (abs(den) >= _EPS) & (t > _EPS) & (t < br[i])
            br[i] = t if hit else br[i]
            bp[i] = label if hit else bp[i]
    elif kind == RECT:
        for i in range(n):
            den, t, px, py, pz = _plane_point(bx[i], by[i], bz[i], nx, ny, nz, num, cx, cy, cz)
            hit = ((abs(den) >= _EPS) & (t > _EPS) & (t < br[i])
                   & (abs(px * ux + py * uy + pz * uz) <= h_u) & (abs(px * vx + py * vy + pz * vz) <= h_v))
            br[i] = t if hit else br[i]
            bp[i] = label if hit else bp[i]
    else:
        for i in range(n):
            den, t, px, py, pz = _plane_point(bx[i], by[i], bz[i], nx, ny, nz, num, cx, cy, cz)
            hit = (abs(den) >= _EPS) & (t > _EPS) & (t < br[i]) & (px * px + py * py + pz * pz <= r2)
            br[i] = t if hit else br[i]
            bp[i] = label if hit else bp[i]


@njit(cache=True, inline="always", error_model="numpy")
def _plane_point(dx, dy, dz, nx, ny, nz, num, cx, cy, cz):
    """Where the ray ``d`` from the origin meets the plane ``n . x = num`` through ``c``: the
    denominator ``n . d``, the range ``t`` and the hit point relative to ``c``."""
    den = nx * dx + ny * dy + nz * dz
    t = num / den
    return den, t, dx * t - cx, dy * t - cy, dz * t - cz


@njit(cache=True, inline="always")
def _ray_in_body(d_world, j, pos, yaw, i):
    """Ray ``j`` (from the origin along ``d_world[j]``) in the frame of a body at ``pos[i]`` with heading
    ``yaw[i]`` [rad] about +Z: :math:`o' = R^T(0 - p)`, :math:`d' = R^T d`, as ``(ox, oy, oz, dx, dy, dz)``."""
    c = math.cos(yaw[i])
    s = math.sin(yaw[i])
    px = -pos[i, 0]
    py = -pos[i, 1]
    pz = -pos[i, 2]
    wx = d_world[j, 0]
    wy = d_world[j, 1]
    return (c * px + s * py, -s * px + c * py, pz,
            c * wx + s * wy, -s * wx + c * wy, d_world[j, 2])


@njit(cache=True, nogil=True)
def cast_moving_kernel(idx, d_world, pos, yaw, prims, prim_offset, out_range, out_prim):
    """Nearest hit of rays ``idx`` against a moving rigid body, each ray at its own time.

    The body is at ``pos[i]`` with heading ``yaw[i]`` [rad] (rotation about +Z) for ray ``idx[i]``;
    the ray is moved into the body frame, :math:`o' = R^T(0 - p)`, :math:`d' = R^T d`, and traced
    against the body's primitives.  Hits record ``prim_offset + m``.
    """
    for i in range(idx.shape[0]):
        j = idx[i]
        ox, oy, oz, dx, dy, dz = _ray_in_body(d_world, j, pos, yaw, i)
        for m in range(prims.shape[0]):
            t = _hit_prim(prims, m, ox, oy, oz, dx, dy, dz)
            if t < out_range[j]:
                out_range[j] = t
                out_prim[j] = prim_offset + m


@njit(cache=True, nogil=True)
def cast_straight_kernel(idx, start, bodies, d_world, t_ray, start_m, velocity_m_s, yaw, prims, prim_start, out_range,
                         out_prim):
    """:func:`cast_moving_kernel` for bodies on straight passes (:class:`sim.world.trajectories.Straight`),
    several in one call: body ``k = bodies[q]`` takes the rays ``idx[start[k]:start[k + 1]]`` (as
    :func:`bodies_candidates_kernel` gives them), each at
    its own time ``t_ray[j]``, where it is at ``start_m[k] + t velocity_m_s[k]`` (the straight
    pass's own expression, :func:`straight_position_kernel`) with the yaw ``yaw[k]`` of its velocity,
    and its primitives are the rows ``prim_start[k]:prim_start[k + 1]`` of ``prims``, recorded by
    their row.  The bodies one after another in the order given, as the calls it replaces (one per
    body, whose positions were an array of their own): the same ranges and ids (numpy twin:
    ``cast_straight_twin`` in ``tests/world_twins.py``).  ``t_ray`` [s], or int64 [ns] as for
    :func:`bodies_candidates_kernel`."""
    pos = np.empty((1, 3))
    one_yaw = np.empty(1)
    for q in range(bodies.shape[0]):
        k = bodies[q]
        one_yaw[0] = yaw[k]
        for i in range(start[k], start[k + 1]):
            j = idx[i]
            t = _seconds(t_ray[j])
            for a in range(3):
                pos[0, a] = start_m[k, a] + t * velocity_m_s[k, a]
            ox, oy, oz, dx, dy, dz = _ray_in_body(d_world, j, pos, one_yaw, 0)
            for m in range(prim_start[k], prim_start[k + 1]):
                t_hit = _hit_prim(prims, m, ox, oy, oz, dx, dy, dz)
                if t_hit < out_range[j]:
                    out_range[j] = t_hit
                    out_prim[j] = m


@njit(cache=True, inline="always")
def _cos_incidence(prims, m, px, py, pz, dx, dy, dz):
    """|cos| of the angle between the ray ``d`` (unit) and the outward normal of primitive ``m`` at
    the hit point ``p`` (both in the primitive's frame): a sphere's radial direction, a box's face
    whose axis offset is largest relative to its half extent, a flat kind's normal."""
    kind = int(prims[m, 0])
    cx = px - prims[m, 1]
    cy = py - prims[m, 2]
    cz = pz - prims[m, 3]
    if kind == SPHERE:
        n = math.sqrt(cx * cx + cy * cy + cz * cz)
        if n == 0.0:
            return 1.0
        return abs(cx * dx + cy * dy + cz * dz) / n
    if kind == BOX:
        ux, uy, uz, vx, vy, vz, wx, wy, wz = _box_axes(prims, m)
        eu = abs(ux * cx + uy * cy + uz * cz) / prims[m, 4]
        ev = abs(vx * cx + vy * cy + vz * cz) / prims[m, 5]
        ew = abs(wx * cx + wy * cy + wz * cz) / prims[m, 6]
        if eu >= ev and eu >= ew:
            return abs(ux * dx + uy * dy + uz * dz)
        if ev >= ew:
            return abs(vx * dx + vy * dy + vz * dz)
        return abs(wx * dx + wy * dy + wz * dz)
    return abs(prims[m, 7] * dx + prims[m, 8] * dy + prims[m, 9] * dz)


@njit(cache=True, nogil=True)
def cos_incidence_static_kernel(d_world, range_m, prim, prims, prim_offset, out_cos):
    """``out_cos[j]``: |cos| of the incidence angle for each ray ``j`` whose hit is one of the static
    primitives ``prims`` (ids ``prim_offset + m``; ``range_m[j]`` along ``d_world[j]`` from the
    origin); other rays are left as they are (effect ``incidence``, :mod:`sim.effects`)."""
    for j in range(d_world.shape[0]):
        m = prim[j] - prim_offset
        if m < 0 or m >= prims.shape[0]:
            continue
        dx, dy, dz = d_world[j, 0], d_world[j, 1], d_world[j, 2]
        r = range_m[j]
        out_cos[j] = _cos_incidence(prims, m, dx * r, dy * r, dz * r, dx, dy, dz)


@njit(cache=True, nogil=True)
def cos_incidence_moving_kernel(idx, d_world, pos, yaw, range_m, prim, prims, prim_offset, out_cos):
    """:func:`cos_incidence_static_kernel` for the rays ``idx`` against a moving body at ``pos[i]``,
    ``yaw[i]`` (as :func:`cast_moving_kernel`): the hit point and the ray taken into the body frame."""
    for i in range(idx.shape[0]):
        j = idx[i]
        m = prim[j] - prim_offset
        if m < 0 or m >= prims.shape[0]:
            continue
        ox, oy, oz, dx, dy, dz = _ray_in_body(d_world, j, pos, yaw, i)
        r = range_m[j]
        out_cos[j] = _cos_incidence(prims, m, ox + dx * r, oy + dy * r, oz + dz * r, dx, dy, dz)


@njit(cache=True, nogil=True)
def cone_candidates_kernel(d_world, status, cx, cy, cz, radius, out_idx):
    """Indices of the valid rays (``status == RAY_OK``) passing within ``radius`` of the point c (and in
    front of the origin): the cheap cull that keeps a one-UAV scene from tracing the whole cloud.
    Writes them in order to ``out_idx`` and returns how many there are.  The sensor culls with
    :func:`bodies_candidates_kernel` (this test for many bodies at once, on blocks of rays); this one
    is the test's reference there (``tests/world``)."""
    n = 0
    r2 = radius * radius
    c2 = cx * cx + cy * cy + cz * cz
    for j in range(d_world.shape[0]):
        b = d_world[j, 0] * cx + d_world[j, 1] * cy + d_world[j, 2] * cz
        if (c2 - b * b <= r2) and (b > -radius) and status[j] == RAY_OK:
            out_idx[n] = j
            n += 1
    return n


@njit(cache=True, nogil=True)
def moving_cull_kernel(idx, d_world, t_ray, t_mid, c, v, radius, accel, v_max, out_idx):
    """Of the rays ``idx`` (a body's cone candidates, :func:`cone_candidates_kernel`), those that can
    meet the body at the ray's own time ``t_ray[j]`` (``dt = t_ray[j] - t_mid``), kept in order in
    ``out_idx``; returns how many.  The body lies within ``radius`` of its position p(t), and

    * with an acceleration bound (``accel >= 0``): ``|p(t) - (c + v dt)| <= accel dt^2 / 2`` (``c``,
      ``v`` its position and velocity at ``t_mid``) -- the test is against that predicted point;
    * without (``accel < 0``): ``|p(t) - c| <= v_max |dt|``.

    The cone test covers the whole frame (``v_max`` times half its length); this one the ray's
    instant, so a bird at 8 m/s keeps a fifth of the rays (a flock of 20: 600 -> ~130 a frame) and the
    poses are evaluated for those only.  Conservative by construction (1 % and 1 mm added, as the cone's
    reach): a ray it drops cannot meet the body, so the cast is the same bits.  The sensor runs this
    test inside :func:`bodies_candidates_kernel`; this one is its reference there (``tests/world``)."""
    n = 0
    for i in range(idx.shape[0]):
        j = idx[i]
        if _meets_at_instant(d_world, j, t_ray[j] - t_mid, c[0], c[1], c[2], v[0], v[1], v[2], radius, accel, v_max):
            out_idx[n] = j
            n += 1
    return n


@njit(cache=True, inline="always")
def _meets_at_instant(d_world, j, dt, cx, cy, cz, vx, vy, vz, radius, accel, v_max):
    """Whether ray ``j`` can meet, ``dt`` after the mid time, a body at ``c`` moving at ``v`` then
    (:func:`moving_cull_kernel`'s test)."""
    if accel >= 0.0:
        qx = cx + vx * dt
        qy = cy + vy * dt
        qz = cz + vz * dt
        reach = (radius + 0.5 * accel * dt * dt) * 1.01 + 1e-3
    else:
        qx = cx
        qy = cy
        qz = cz
        reach = (radius + v_max * abs(dt)) * 1.01 + 1e-3
    b = d_world[j, 0] * qx + d_world[j, 1] * qy + d_world[j, 2] * qz
    return (qx * qx + qy * qy + qz * qz) - b * b <= reach * reach and b > -reach


# The cull's direction bounds (ray_blocks_kernel): rays per block.  A Mid-40 frame's 32 consecutive
# rays span ~1.5 deg of its rosette, so a drone's cone at 40 m meets 1-3 % of the blocks: the rays of
# the others are never tested against it (five drones' cones: 36 -> ~10 us a frame).
CULL_BLOCK = 32
_BLOCK_EMPTY = 2.0     # block_cos of a block without a valid ray: no ray of it passes a cone test
_BLOCK_ANY = -2.0      # block_cos of a block not bounded (rays off length 1, or spread wide): all tested


@njit(cache=True, nogil=True)
def ray_blocks_kernel(d_world, status, out_axis, out_cos, out_sin):
    """Bounds on the directions of the rays in blocks of ``CULL_BLOCK`` (block b: rays ``b CULL_BLOCK``
    on), for the cone tests of :func:`bodies_candidates_kernel`:
    every valid ray (``status == RAY_OK``) of block b lies within the angle ``theta_b`` of the unit
    axis ``out_axis[b]``, ``out_cos[b] = cos theta_b``, ``out_sin[b] = sin theta_b``.

    The axis is the block's first, middle and last rays summed and normalised (any axis is sound;
    this one is near the middle of the block's arc); ``cos theta_b`` the least ``d . axis`` of its
    valid rays less 4e-6, which covers a ray's length off 1 by up to 1e-6 in ``|d|^2`` and the
    rounding.  A block with a valid ray whose ``|d|^2`` is further from 1, or spread wider than
    60 deg (or with a non-finite axis) gets ``out_cos[b] = _BLOCK_ANY`` (its rays are all tested); one
    without a valid ray ``_BLOCK_EMPTY`` (none can pass).  Numpy twin: ``ray_blocks_twin`` in
    ``tests/world_twins.py``."""
    n = d_world.shape[0]
    flat = d_world.reshape(-1)      # rows end to end: the stride-3 loads vectorise (see _rows_to_xyz)
    w = np.empty(CULL_BLOCK)
    for b in range(out_cos.shape[0]):
        j0 = b * CULL_BLOCK
        m = min(CULL_BLOCK, n - j0)
        jm = j0 + m // 2
        jl = j0 + m - 1
        ax = flat[3 * j0] + flat[3 * jm] + flat[3 * jl]
        ay = flat[3 * j0 + 1] + flat[3 * jm + 1] + flat[3 * jl + 1]
        az = flat[3 * j0 + 2] + flat[3 * jm + 2] + flat[3 * jl + 2]
        an = math.sqrt(ax * ax + ay * ay + az * az)
        out_cos[b] = _BLOCK_ANY
        out_sin[b] = 1.0
        if not (an > 0.5 and an < math.inf):
            out_axis[b, 0] = 0.0
            out_axis[b, 1] = 0.0
            out_axis[b, 2] = 0.0
            continue
        ax /= an
        ay /= an
        az /= an
        out_axis[b, 0] = ax
        out_axis[b, 1] = ay
        out_axis[b, 2] = az
        blk = flat[3 * j0:3 * (j0 + m)]
        st = status[j0:j0 + m]
        for i in range(m):      # branch-free: selects only (a ray off length 1: -10, not valid: 10)
            x = blk[3 * i]
            y = blk[3 * i + 1]
            z = blk[3 * i + 2]
            c = x * ax + y * ay + z * az
            c = c if abs(x * x + y * y + z * z - 1.0) <= 1e-6 else -10.0
            w[i] = c if st[i] == RAY_OK else 10.0
        # the least of them in four chains (one chain waits on each comparison)
        lo0 = 10.0
        lo1 = 10.0
        lo2 = 10.0
        lo3 = 10.0
        i = 0
        while i + 4 <= m:
            lo0 = min(lo0, w[i])
            lo1 = min(lo1, w[i + 1])
            lo2 = min(lo2, w[i + 2])
            lo3 = min(lo3, w[i + 3])
            i += 4
        while i < m:
            lo0 = min(lo0, w[i])
            i += 1
        cb = min(min(lo0, lo1), min(lo2, lo3)) - 4e-6
        if cb > 1.0:
            out_cos[b] = _BLOCK_EMPTY
        elif cb > 0.5:
            out_cos[b] = cb
            out_sin[b] = math.sqrt(1.0 - cb * cb)


@njit(cache=True, inline="always")
def _cone_bound(cx, cy, cz, reach):
    """What the block test of :func:`bodies_candidates_kernel` needs of a cone of radius ``reach``
    about ``c``: ``(bounded, ux, uy, uz, cos a, sin a)``, ``u = c / |c|`` and ``a`` the half-angle
    within which a ray passing the cone's test points: ``sin^2 a = reach^2 / |c|^2 + 4e-6`` (a ray's
    |d|^2 off 1 by up to 1e-6 and the rounding of the test).  Not bounded (every block tested):
    ``|c|`` not above twice ``reach`` (then a ray behind the origin's side might pass), non-finite,
    or ``a`` over 30 deg.

    The block test: a ray within ``theta_b`` of block b's axis (:func:`ray_blocks_kernel`) and within
    ``a`` of ``u`` has the two directions within ``theta_b + a`` (< 90 deg) of each other, so a block
    whose axis is further from ``u`` -- ``axis . u < cos theta_b cos a - sin theta_b sin a``, with
    1e-9 in the cosine to spare -- has no ray that passes."""
    c2 = cx * cx + cy * cy + cz * cz
    cn = math.sqrt(c2)
    if not (cn > 2.0 * reach and cn < math.inf and reach >= 0.0):
        return False, 0.0, 0.0, 0.0, 1.0, 0.0
    s2 = (reach * reach) / c2 + 4e-6
    if not s2 <= 0.25:
        return False, 0.0, 0.0, 0.0, 1.0, 0.0
    return True, cx / cn, cy / cn, cz / cn, math.sqrt(1.0 - s2), math.sqrt(s2)


@njit(cache=True, nogil=True)
def bodies_candidates_kernel(d_world, status, t_ray, t_mid, centres, velocities, reach, radius, accel, v_max, instant,
                             block_axis, block_cos, block_sin):
    """:func:`cone_candidates_kernel` (body k at ``centres[k]``, its cone's radius ``reach[k]``) and,
    with ``instant``, :func:`moving_cull_kernel` of its candidates (``velocities[k]``, ``radius[k]``,
    ``accel[k]`` (< 0: no bound), ``v_max[k]``) for K bodies in one call: returns ``(idx, start)``, body
    k's rays ``idx[start[k]:start[k + 1]]`` in order.  A body's rays are tested in the blocks whose
    direction bounds (``block_*``, :func:`ray_blocks_kernel` of these rays) its cone may meet
    (:func:`_cone_bound`): the others hold no ray that passes.  Each test with the arithmetic of
    the kernels it stands for, so the same rays (numpy twin: ``bodies_candidates_twin`` in
    ``tests/world_twins.py``).  ``t_ray``: the rays' times [s], or their int64 times [ns] (then a
    ray's time is ``t_ns * 1e-9``, formed here for the rays tested: the bits of an array of it)."""
    n = d_world.shape[0]
    n_bodies = centres.shape[0]
    nb = block_cos.shape[0]
    # The blocks' bounds as columns, a block not bounded made to pass every body's test (axis 0,
    # cosine -2) and one without a valid ray to fail it (axis 0, cosine 2; a cone's cos a >= 0.86):
    # the block test of _cone_bound without branches, so that the loop over the blocks vectorises.
    bx = np.empty(nb)
    by = np.empty(nb)
    bz = np.empty(nb)
    bc = np.empty(nb)
    bs = np.empty(nb)
    for b in range(nb):
        c = block_cos[b]
        plain = c != _BLOCK_EMPTY and c != _BLOCK_ANY
        bx[b] = block_axis[b, 0] if plain else 0.0
        by[b] = block_axis[b, 1] if plain else 0.0
        bz[b] = block_axis[b, 2] if plain else 0.0
        bc[b] = c
        bs[b] = block_sin[b] if plain else 0.0
    near = np.empty((n_bodies, nb), dtype=np.uint8)
    total = 0
    for k in range(n_bodies):
        bounded, ux, uy, uz, ca, sa = _cone_bound(centres[k, 0], centres[k, 1], centres[k, 2], reach[k])
        row = near[k]
        count = 0
        if bounded:
            for b in range(nb):
                v = np.uint8(bx[b] * ux + by[b] * uy + bz[b] * uz >= bc[b] * ca - bs[b] * sa - 1e-9)
                row[b] = v
                count += int(v)     # (int: run as Python, an int plus a uint8 stays a uint8 and wraps at 256)
        else:
            for b in range(nb):
                v = np.uint8(bc[b] != _BLOCK_EMPTY)
                row[b] = v
                count += int(v)
        total += count * CULL_BLOCK
    idx = np.empty(total, dtype=np.int64)
    start = np.zeros(n_bodies + 1, dtype=np.int64)
    p = 0
    for k in range(n_bodies):
        cx = centres[k, 0]
        cy = centres[k, 1]
        cz = centres[k, 2]
        rk = reach[k]
        r2 = rk * rk
        c2 = cx * cx + cy * cy + cz * cz
        for b in range(nb):
            if not near[k, b]:
                continue
            for j in range(b * CULL_BLOCK, min(n, (b + 1) * CULL_BLOCK)):
                bj = d_world[j, 0] * cx + d_world[j, 1] * cy + d_world[j, 2] * cz
                if (c2 - bj * bj <= r2) and (bj > -rk) and status[j] == RAY_OK:
                    if not instant or _meets_at_instant(d_world, j, _seconds(t_ray[j]) - t_mid, cx, cy, cz,
                                                        velocities[k, 0], velocities[k, 1], velocities[k, 2],
                                                        radius[k], accel[k], v_max[k]):
                        idx[p] = j
                        p += 1
        start[k + 1] = p
    return idx[:p], start


@njit(cache=True, nogil=True)
def wander_arg_kernel(t_s, member, omega, phase, out):
    """``out[i] = t_s[i] * omega[member[i]] + phase[member[i]]`` (N, K, 3): the arguments of a flock's
    wander sines (:class:`sim.world.sky.FlockPoses`), numpy's ``t[:, None, None] * omega[m] +
    phase[m]`` element for element."""
    for i in range(t_s.shape[0]):
        m = member[i]
        t = t_s[i]
        for k in range(omega.shape[1]):
            for a in range(3):
                out[i, k, a] = t * omega[m, k, a] + phase[m, k, a]


@njit(cache=True, nogil=True)
def wander_sum_kernel(base, slot, member, amp, trig, out):
    """``out[i] = base[i] + slot[member[i]] + sum_k amp[member[i], k] * trig[i, k]`` (N, 3): a flock's
    positions (the centre's path, the bird's slot, its wander's sines) or, with ``slot`` empty (0, 3),
    velocities; numpy's ``base + slot[m] + (amp[m] * trig).sum(axis=1)``, its sum from 0.0 in order
    of k (numpy twins: ``flock_positions_twin``, ``flock_velocities_twin`` in ``tests/world_twins.py``)."""
    with_slot = slot.shape[0] > 0
    for i in range(base.shape[0]):
        m = member[i]
        for a in range(3):
            s = 0.0
            for k in range(amp.shape[1]):
                s += amp[m, k, a] * trig[i, k, a]
            x = base[i, a] + slot[m, a] if with_slot else base[i, a]
            out[i, a] = x + s


@njit(cache=True, nogil=True)
def wander_rows_kernel(base_p, base_v, slot, member, amp, amp_omega, sin_arg, cos_arg, out_p, out_v):
    """:func:`wander_sum_kernel` for a flock's positions (``base_p``, ``slot``, ``amp``, the sines) and
    velocities (``base_v``, no slot, ``amp_omega``, the cosines) in one call from Python (the calls
    cost more than the sums): that kernel twice, so each element's arithmetic is its own (numpy
    twins as there: ``flock_positions_twin``, ``flock_velocities_twin`` in ``tests/world_twins.py``)."""
    wander_sum_kernel(base_p, slot, member, amp, sin_arg, out_p)
    wander_sum_kernel(base_v, slot[:0], member, amp_omega, cos_arg, out_v)


@njit(cache=True, nogil=True)
def wing_phase_kernel(t_s, member, seg_lo, seg_hi, starts, two_pi_f, out_bout, out_phase):
    """Per ray, the flapping bout its time falls in and the wingbeat's phase in it.

    The bout: ``numpy.searchsorted(starts[lo:hi], t, "right") - 1 + lo`` for its member's segment
    ``[lo, hi)`` of the members' concatenated, each sorted, bout starts, and ``lo`` before the first
    (``FlapSchedule.angle_rad``'s clip), by comparisons only; the phase: ``two_pi_f[member] * (t -
    starts[bout])`` (numpy twins: ``bout_index_twin``, ``flock_wing_angles_twin`` in
    ``tests/world_twins.py``)."""
    for i in range(t_s.shape[0]):
        m = member[i]
        lo = seg_lo[m]
        a = lo
        b = seg_hi[m]
        t = t_s[i]
        while a < b:
            mid = (a + b) // 2
            if starts[mid] <= t:
                a = mid + 1
            else:
                b = mid
        k = a - 1 if a - 1 >= lo else lo
        out_bout[i] = k
        out_phase[i] = two_pi_f[m] * (t - starts[k])


@njit(cache=True, nogil=True)
def wing_angle_kernel(bout, member, flaps, phi0, amp, sin_phase, out):
    """Per ray, the wing angle: ``phi0 + amp * sin(phase)`` of its member in a flapping bout, ``phi0``
    in a glide (``FlapSchedule.angle_rad``; ``sin_phase`` numpy's sine of
    :func:`wing_phase_kernel`'s phase)."""
    for i in range(bout.shape[0]):
        m = member[i]
        out[i] = phi0[m] + amp[m] * sin_phase[i] if flaps[bout[i]] else phi0[m]


@njit(cache=True)
def rotate_pan_tilt_grid_kernel(d_lidar, t_s, t0_s, dt_s, pan_rad, tilt_rad, out):
    """:func:`rotate_pan_tilt_kernel` with the head pose linearly interpolated from a time grid.

    ``pan_rad``/``tilt_rad`` hold the true pose at ``t0_s + i dt_s`` (pan unwrapped).  Between
    nodes the pose is linear; for a grid of 1 ms and head accelerations <= 100 deg/s^2 the
    interpolation error is below ``a dt^2 / 8 = 1.25e-5 deg``, far below the beam divergence.  The
    trigonometry is done once per node; a point adds a tiny angle ``delta`` with the series
    ``cos = 1 - d^2/2 + d^4/24``, ``sin = d - d^3/6 + d^5/120`` (exact to 1e-20 for |d| < 1e-3).
    """
    n_grid = pan_rad.shape[0]
    n = d_lidar.shape[0]
    inv_dt = 1.0 / dt_s   # multiplications, not divisions, in the inner loop (2x faster)
    # Points come in time order (they may not: then each run of points in one interval is handled
    # on its own, same result).  Walking the grid interval by interval keeps the node's values
    # constant in the inner loop, which LLVM vectorises; the per-point formulas are unchanged.
    j = 0
    while j < n:
        i, j_end = _interval_run(t_s, j, t0_s, inv_dt, n_grid)
        cpi = math.cos(pan_rad[i])
        spi = math.sin(pan_rad[i])
        cti = math.cos(tilt_rad[i])
        sti = math.sin(tilt_rad[i])
        dpan = pan_rad[i + 1] - pan_rad[i]
        dtilt = tilt_rad[i + 1] - tilt_rad[i]
        t_run = t_s[j:j_end]      # slices: see rotate_head_pieces_kernel
        d_run = d_lidar[j:j_end]
        out_run = out[j:j_end]
        for k in range(j_end - j):
            f = (t_run[k] - t0_s) * inv_dt - i
            dp = f * dpan
            dq = f * dtilt
            _turn_beam(d_run, out_run, k, cpi, spi, cti, sti, dp, dq)
        j = j_end


_INV6, _INV24, _INV120 = 1.0 / 6.0, 1.0 / 24.0, 1.0 / 120.0


@njit(cache=True, inline="always")
def _turn_beam(d_lidar, out, k, cpi, spi, cti, sti, dp, dq):
    """``out[k]`` = beam ``k`` turned by pan ``p + dp`` and tilt ``q + dq`` (see :func:`_turn_xyz`)."""
    x, y, z = _turn_xyz(d_lidar[k, 0], d_lidar[k, 1], d_lidar[k, 2], cpi, spi, cti, sti, dp, dq)
    out[k, 0] = x
    out[k, 1] = y
    out[k, 2] = z


@njit(cache=True, inline="always")
def _turn_xyz(x, y, z, cpi, spi, cti, sti, dp, dq):
    """The beam ``(x, y, z)`` turned by pan ``p + dp`` and tilt ``q + dq`` given the cos/sin of the
    node angles ``p, q`` and small steps (|d| < 2e-3 rad): ``cos d = 1 - d^2/2 + d^4/24``,
    ``sin d = d - d^3/6 + d^5/120`` (truncation < 1e-20), then the angle-sum formulas."""
    dp2 = dp * dp
    dq2 = dq * dq
    cdp = 1.0 - dp2 * (0.5 - dp2 * _INV24)
    sdp = dp * (1.0 - dp2 * (_INV6 - dp2 * _INV120))
    cdq = 1.0 - dq2 * (0.5 - dq2 * _INV24)
    sdq = dq * (1.0 - dq2 * (_INV6 - dq2 * _INV120))
    cp = cpi * cdp - spi * sdp
    sp = spi * cdp + cpi * sdp
    ct = cti * cdq - sti * sdq
    st = sti * cdq + cti * sdq
    x1 = x * ct - z * st
    z1 = x * st + z * ct
    return x1 * cp - y * sp, x1 * sp + y * cp, z1


@njit(cache=True, inline="always")
def _rows_to_xyz(flat, m, bx, by, bz):
    """``m`` rows (x, y, z) given end to end (``flat``, a C-contiguous (m, 3) block reshaped) into
    three arrays.  Indexed in the flat array, LLVM vectorises the stride-3 loads (interleaved
    access); indexed as rows ``a[k, c]`` it does not (measured: the copies in and out of 10 000
    beams, 17 -> 8 us)."""
    for k in range(m):
        bx[k] = flat[3 * k]
        by[k] = flat[3 * k + 1]
        bz[k] = flat[3 * k + 2]


@njit(cache=True, inline="always")
def _xyz_to_rows(bx, by, bz, m, flat):
    """:func:`_rows_to_xyz` back: three arrays into ``m`` rows end to end."""
    for k in range(m):
        flat[3 * k] = bx[k]
        flat[3 * k + 1] = by[k]
        flat[3 * k + 2] = bz[k]


@njit(cache=True, inline="always")
def _interval_run(t_s, j, t0_s, inv_dt, n_grid):
    """The grid interval of point ``j`` and the end of the run of points ``j ..`` in it."""
    i = _grid_interval((t_s[j] - t0_s) * inv_dt, n_grid)
    j_end = j + 1
    while j_end < t_s.shape[0] and _grid_interval((t_s[j_end] - t0_s) * inv_dt, n_grid) == i:
        j_end += 1
    return i, j_end


def _seconds(t):
    """A time in seconds from seconds (as is) or from integer nanoseconds (``t * 1e-9``, the
    expression of the loop's float array of the times: the same bits without the array)."""
    return t * 1e-9 if isinstance(t, (int, np.integer)) else t


@overload(_seconds, inline="always")
def _seconds_nb(t):
    if isinstance(t, types.Integer):
        return lambda t: t * 1e-9
    return lambda t: t


@njit(cache=True, inline="always")
def _interval_run_sorted(times, j, t0_s, inv_dt, n_grid):
    """:func:`_interval_run` for times in order (seconds or integer ns, :func:`_seconds`), by
    bisection (the interval grows with the time): ~log2(n) interval tests per run instead of one
    per point."""
    i = _grid_interval((_seconds(times[j]) - t0_s) * inv_dt, n_grid)
    lo = j + 1
    hi = times.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if _grid_interval((_seconds(times[mid]) - t0_s) * inv_dt, n_grid) == i:
            lo = mid + 1
        else:
            hi = mid
    return i, lo


@njit(cache=True, inline="always")
def _grid_interval(u, n_grid):
    """Index of the grid interval holding the normalised time ``u`` (clamped to the grid)."""
    i = int(math.floor(u))
    if i < 0:
        return 0
    if i > n_grid - 2:
        return n_grid - 2
    return i


@njit(cache=True, inline="always")
def _piece_angle_rad(pieces, i, t):
    """Exact angle [rad] at ``t`` in constant-acceleration piece ``i`` (rows t_start, deg, deg/s,
    deg/s^2): the head model's own expression, then numpy's degrees-to-radians factor."""
    return _poly_angle_rad(pieces[0, i], pieces[1, i], pieces[2, i], pieces[3, i], t)


@njit(cache=True, inline="always")
def _poly_angle_rad(t_start, angle_deg, speed_deg_s, accel_deg_s2, t):
    """:func:`_piece_angle_rad` with the piece's row already read: loop-invariant locals, which the
    compiler cannot hoist itself (the loop's stores might alias the pieces)."""
    d = t - t_start
    return (angle_deg + speed_deg_s * d + 0.5 * accel_deg_s2 * d * d) * _RAD_PER_DEG


@njit(cache=True, inline="always")
def _advance_piece(pieces, i, t):
    while i + 1 < pieces.shape[1] and pieces[0, i + 1] <= t:
        i += 1
    return i


@njit(cache=True, nogil=True)
def rotate_head_pieces_kernel(d_lidar, times, t0_s, dt_s, n_nodes, pan_pieces, tilt_pieces, out):
    """:func:`rotate_pan_tilt_kernel` with the head pose exact at every point's own time.

    The head moves in constant-acceleration pieces (``gimbal.pts303h.PTS303H.pose_segments``:
    rows ``t_start_s, angle_deg, speed_deg_s, accel_deg_s2``); a point's pan and tilt are those
    polynomials at its time — no interpolation.  The trigonometry is done once per node of a
    ``dt_s`` grid (``n_nodes`` nodes from ``t0_s``); a point turns by the small exact difference
    ``delta`` from its node (|delta| <= head speed x dt: 1.7e-3 rad at 100 deg/s and 1 ms) with the
    series of :func:`rotate_pan_tilt_grid_kernel` (truncation < 1e-23 rad).  Points in time order;
    ``times``: float64 [s], or the points' int64 [ns] (then the time [s] is ``t_ns * 1e-9``, formed
    here: the same bits as an array of it, which the loop need not make).
    """
    n = d_lidar.shape[0]
    inv_dt = 1.0 / dt_s
    d_flat = d_lidar.reshape(-1)     # rows (x, y, z) end to end: see _rows_to_xyz
    out_flat = out.reshape(-1)
    bx = np.empty(_BLOCK)
    by = np.empty(_BLOCK)
    bz = np.empty(_BLOCK)
    ip_node = 0
    it_node = 0
    ip = 0
    it = 0
    j = 0
    while j < n:
        i, j_end = _interval_run_sorted(times, j, t0_s, inv_dt, n_nodes)
        tn = t0_s + i * dt_s
        ip_node = _advance_piece(pan_pieces, ip_node, tn)
        it_node = _advance_piece(tilt_pieces, it_node, tn)
        pan_ref = _piece_angle_rad(pan_pieces, ip_node, tn)
        tilt_ref = _piece_angle_rad(tilt_pieces, it_node, tn)
        cpi = math.cos(pan_ref)
        spi = math.sin(pan_ref)
        cti = math.cos(tilt_ref)
        sti = math.sin(tilt_ref)
        t_last = _seconds(times[j_end - 1])
        t_first = _seconds(times[j])
        ip = _advance_piece(pan_pieces, ip, t_first)
        it = _advance_piece(tilt_pieces, it, t_first)
        # Usually no piece starts inside the interval: then the pieces are constants of the inner
        # loop (which vectorises); otherwise the pointers advance point by point.
        steady = (_advance_piece(pan_pieces, ip, t_last) == ip and _advance_piece(tilt_pieces, it, t_last) == it)
        # Slices, so that the loops index from 0: numba's wrap-around test for a possibly negative
        # index (k = j + ...) would otherwise stop LLVM vectorising the loop (4x slower).
        t_run = times[j:j_end]
        d_run = d_lidar[j:j_end]
        out_run = out[j:j_end]
        if steady and j_end - j <= _BLOCK:
            # a branch inside the loop would also stop the vectorisation: one loop per case; the
            # beams go through x, y, z blocks (the rows' stride-3 layout does not vectorise)
            p0, p1, p2, p3 = pan_pieces[0, ip], pan_pieces[1, ip], pan_pieces[2, ip], pan_pieces[3, ip]
            q0, q1, q2, q3 = tilt_pieces[0, it], tilt_pieces[1, it], tilt_pieces[2, it], tilt_pieces[3, it]
            m = j_end - j
            _rows_to_xyz(d_flat[3 * j:3 * j_end], m, bx, by, bz)
            for k in range(m):
                t = _seconds(t_run[k])
                dp = _poly_angle_rad(p0, p1, p2, p3, t) - pan_ref
                dq = _poly_angle_rad(q0, q1, q2, q3, t) - tilt_ref
                bx[k], by[k], bz[k] = _turn_xyz(bx[k], by[k], bz[k], cpi, spi, cti, sti, dp, dq)
            _xyz_to_rows(bx, by, bz, m, out_flat[3 * j:3 * j_end])
        else:
            for k in range(j_end - j):
                t = _seconds(t_run[k])
                ip = _advance_piece(pan_pieces, ip, t)
                it = _advance_piece(tilt_pieces, it, t)
                dp = _piece_angle_rad(pan_pieces, ip, t) - pan_ref
                dq = _piece_angle_rad(tilt_pieces, it, t) - tilt_ref
                _turn_beam(d_run, out_run, k, cpi, spi, cti, sti, dp, dq)
        j = j_end


_RAD_PER_DEG = math.pi / 180.0


@njit(cache=True)
def piece_angle_deg_kernel(pieces, t):
    """The angle [deg] at one time ``t`` from a head's pieces (see
    :func:`rotate_head_pieces_kernel`): the head model's own expression, the same bits."""
    i = _advance_piece(pieces, 0, t)
    d = t - pieces[0, i]
    return pieces[1, i] + pieces[2, i] * d + 0.5 * pieces[3, i] * d * d


@njit(cache=True, nogil=True)
def straight_position_kernel(start_m, velocity_m_s, t_s, out):
    """``out[j] = start + t_s[j] * velocity`` (N, 3) [m]: a straight pass at the points' times
    (:meth:`sim.world.trajectories.Straight.position`), numpy's ``start + t[:, None] * velocity``
    element for element (the same bits), without its broadcasting over rows of three (~6 us for
    300 times, ~1 here)."""
    for j in range(t_s.shape[0]):
        t = t_s[j]
        for i in range(3):
            out[j, i] = start_m[i] + t * velocity_m_s[i]


@njit(cache=True, nogil=True)
def circle_rows_kernel(cos, sin, cx, cy, cz, radius, speed, out_position, out_velocity):
    """A circle's rows from its phase's cosines and sines (N,): positions ``(cx + r cos, cy + r sin,
    cz + r 0.0)`` into ``out_position`` and velocities ``(speed (-sin), speed cos, speed 0.0)`` into
    ``out_velocity`` (either (0, 3): not asked), numpy's column forms element for element
    (:class:`sim.world.trajectories.Circle`; twin: its columns under ``numpy_paths``,
    ``tests/world/test_trajectories.py``)."""
    for i in range(out_position.shape[0]):
        out_position[i, 0] = cx + radius * cos[i]
        out_position[i, 1] = cy + radius * sin[i]
        out_position[i, 2] = cz + radius * 0.0
    for i in range(out_velocity.shape[0]):
        out_velocity[i, 0] = speed * -sin[i]
        out_velocity[i, 1] = speed * cos[i]
        out_velocity[i, 2] = speed * 0.0


@njit(cache=True, nogil=True)
def hover_heading_kernel(velocity, default, yaw):
    """``yaw[j] = default`` where the body hovers: ``not vx^2 + vy^2 > 1e-8`` [m^2/s^2] (NaN too),
    row ``j`` of ``velocity`` (N, 3) [m/s]; :func:`sim.world.trajectories.heading_rad`'s mask in one
    pass instead of six numpy operations (the same comparisons of the same IEEE products)."""
    for j in range(velocity.shape[0]):
        vx = velocity[j, 0]
        vy = velocity[j, 1]
        if not vx * vx + vy * vy > 1e-8:
            yaw[j] = default


@njit(cache=True, nogil=True)
def cast_flapping_kernel(idx, d_world, pos, yaw, flap_rad, prims, hinge, prim_offset, out_range, out_prim):
    """:func:`cast_moving_kernel` for a body with hinged parts (a bird's wings, :mod:`sim.world.sky`),
    each ray at its own time and wing angle ``flap_rad[i]``.

    ``hinge`` (M, 3): per primitive ``(sign, y_h, z_h)``; a primitive with sign 0 is traced in the
    body frame as :func:`cast_moving_kernel` traces it; one with sign ``s`` is turned by ``s * phi``
    about the body's x axis through ``(0, y_h, z_h)``, so the ray is moved by the inverse turn into
    the part's rest frame: :math:`o'' = R_x(-s\\phi)(o' - h) + h`, :math:`d'' = R_x(-s\\phi) d'`
    (a rigid motion: the range along the unit ray is unchanged).  Numpy twin:
    ``tests/world_twins.py`` ``cast_flapping_twin``."""
    for i in range(idx.shape[0]):
        _cast_flapping_ray(idx[i], d_world, pos, yaw, flap_rad, i, prims, hinge, 0, prims.shape[0], prim_offset,
                           out_range, out_prim)


@njit(cache=True, nogil=True)
def cast_flock_kernel(idx, member, d_world, pos, yaw, flap_rad, prims, hinge, prim_start, prim_offset, out_range,
                      out_prim):
    """:func:`cast_flapping_kernel` for the birds of a flock in one call: ray ``idx[i]`` against bird
    ``member[i]``, whose primitives are the rows ``prim_start[k]:prim_start[k + 1]`` of ``prims`` and
    ``hinge`` (the birds' tables one after another) and record ``prim_offset`` plus their row.  The
    rays in the order of the calls it replaces (one per bird, bird after bird), so every range and
    id is the same (``tests/world/test_sky.py``; numpy twin ``cast_flock_twin`` in
    ``tests/world_twins.py``)."""
    for i in range(idx.shape[0]):
        k = member[i]
        _cast_flapping_ray(idx[i], d_world, pos, yaw, flap_rad, i, prims, hinge, prim_start[k], prim_start[k + 1],
                           prim_offset, out_range, out_prim)


@njit(cache=True, inline="always")
def _cast_flapping_ray(j, d_world, pos, yaw, flap_rad, i, prims, hinge, m_lo, m_hi, prim_offset, out_range, out_prim):
    """Ray ``j`` against the primitives ``m_lo:m_hi`` of a flapping body posed by ``pos[i]``, ``yaw[i]``,
    ``flap_rad[i]`` (:func:`cast_flapping_kernel`)."""
    ox, oy, oz, dx, dy, dz = _ray_in_body(d_world, j, pos, yaw, i)
    cf = math.cos(flap_rad[i])
    sf = math.sin(flap_rad[i])
    for m in range(m_lo, m_hi):
        sign = hinge[m, 0]
        if sign == 0.0:
            t = _hit_prim(prims, m, ox, oy, oz, dx, dy, dz)
        else:
            # R_x(a) with a = -sign * phi: cos a = cf, sin a = -sign * sf
            sa = -sign * sf
            hy = hinge[m, 1]
            hz = hinge[m, 2]
            ry = oy - hy
            rz = oz - hz
            oy2 = ry * cf - rz * sa + hy
            oz2 = ry * sa + rz * cf + hz
            dy2 = dy * cf - dz * sa
            dz2 = dy * sa + dz * cf
            t = _hit_prim(prims, m, ox, oy2, oz2, dx, dy2, dz2)
        if t < out_range[j]:
            out_range[j] = t
            out_prim[j] = prim_offset + m


@njit(cache=True, inline="always")
def _ppoly_interval(x, xval):
    """scipy's ``find_interval_ascending`` (``scipy/interpolate/_ppoly.pyx``) with extrapolation, on
    strictly increasing breakpoints ``x``: the piece of ``xval`` (the last one at ``x[-1]``), the
    first or last piece outside, -1 for NaN.  scipy's search starts from the previous point's piece;
    on distinct breakpoints every search finds the one piece whose ``[x[i], x[i + 1])`` holds ``xval``."""
    nx = x.shape[0]
    a = x[0]
    b = x[nx - 1]
    if not (a <= xval <= b):
        if xval < a:
            return 0
        if xval > b:
            return nx - 2
        return -1
    if xval == b:
        return nx - 2
    lo = 0
    hi = nx - 2
    while lo < hi:        # the last piece whose start is <= xval
        mid = (lo + hi + 1) // 2
        if x[mid] <= xval:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True, inline="always")
def _ppoly_value(c, k, j, s, dx):
    """scipy's ``evaluate_poly1`` (``_ppoly.pyx``): the ``dx``-th derivative (0 or more) of local
    polynomial ``c[:, k, j]`` (highest power first) at ``s``, the same products and sums in the same
    order (``res + c z prefactor``, ``z`` the power of ``s``)."""
    kc = c.shape[0]
    res = 0.0
    z = 1.0
    for kp in range(kc):
        prefactor = 1.0
        if dx > 0:
            if kp < dx:
                continue
            for q in range(kp, kp - dx, -1):
                prefactor *= q
        res = res + c[kc - kp - 1, k, j] * z * prefactor
        if kp < kc - 1 and kp >= dx:
            z *= s
    return res


@njit(cache=True, nogil=True)
def spline_rows_kernel(c, x, t_s, t_end, out_position, out_velocity):
    """A cubic path's positions and velocities (:class:`sim.world.trajectories.Manual`,
    ``Waypoints``, :class:`sim.world.sky.SplinePath`): each time clipped to ``[0, t_end]`` as
    ``np.clip`` does (NaN kept), the spline (scipy's ``PPoly`` coefficients ``c`` (K, m, 3), breakpoints
    ``x`` (m + 1,)) and its first derivative there as ``PPoly._evaluate`` computes them, the velocity
    0 where ``t < 0`` or ``t > t_end``.  Rows into ``out_position`` / ``out_velocity`` (N, 3), either
    (0, 3): not asked.  Twin: the paths' numpy and scipy calls under ``numpy_paths``
    (``tests/world/test_spline_rows_kernel.py``)."""
    n = t_s.shape[0]
    want_p = out_position.shape[0] > 0
    want_v = out_velocity.shape[0] > 0
    for i in range(n):
        t = t_s[i]
        h = t
        if not np.isnan(h):     # numpy's clip: min(max(t, lo), hi), a NaN kept
            h = h if h > 0.0 else 0.0
            h = h if h < t_end else t_end
        k = _ppoly_interval(x, h)
        if k < 0:
            for j in range(3):
                if want_p:
                    out_position[i, j] = np.nan
                if want_v:
                    out_velocity[i, j] = np.nan
            continue
        s = h - x[k]
        if want_p:
            for j in range(3):
                out_position[i, j] = _ppoly_value(c, k, j, s, 0)
        if want_v:
            outside = t < 0 or t > t_end
            for j in range(3):
                out_velocity[i, j] = 0.0 if outside else _ppoly_value(c, k, j, s, 1)
