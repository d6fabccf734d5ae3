"""Plain-numpy twins of the kernels in :mod:`sim.world.kernels` (written independently, vectorised)."""

from __future__ import annotations

import numpy as np

from sim.world.kernels import BOX, DISK, PLANE, RECT, SPHERE

EPS = 1e-12


def rotate_twin(d, pan, tilt):
    ct, st, cp, sp = np.cos(tilt), np.sin(tilt), np.cos(pan), np.sin(pan)
    out = np.empty_like(d)
    for j in range(len(d)):
        ry = np.array([[ct[j], 0, -st[j]], [0, 1, 0], [st[j], 0, ct[j]]])  # R_y(-tilt)
        rz = np.array([[cp[j], -sp[j], 0], [sp[j], cp[j], 0], [0, 0, 1]])
        out[j] = rz @ ry @ d[j]
    return out


def hit_twin(prim, o, d):
    """Distances (N,) along rays o + t d (arrays (N,3)) to one primitive, inf when missed."""
    kind = int(prim[0])
    c = prim[1:4] - o
    n_rays = len(d)
    inf = np.full(n_rays, np.inf)
    if kind == SPHERE:
        b = np.einsum("ij,ij->i", c, d)
        disc = b * b - (np.einsum("ij,ij->i", c, c) - prim[4] ** 2)
        s = np.sqrt(np.maximum(disc, 0))
        t1, t2 = b - s, b + s
        t = np.where(t1 > EPS, t1, np.where(t2 > EPS, t2, np.inf))
        return np.where(disc >= 0, t, inf)
    if kind == BOX:
        u, v = prim[7:10], prim[10:13]
        axes = np.stack([u, v, np.cross(u, v)])
        lo = np.full(n_rays, -np.inf)
        hi = np.full(n_rays, np.inf)
        ok = np.ones(n_rays, bool)
        for a, h in zip(axes, prim[4:7]):
            e = c @ a
            f = d @ a
            par = np.abs(f) <= EPS
            ok &= ~(par & ((-e - h > 0) | (-e + h < 0)))
            with np.errstate(divide="ignore", invalid="ignore"):
                t1 = np.where(par, -np.inf, (e - h) / f)
                t2 = np.where(par, np.inf, (e + h) / f)
            lo = np.maximum(lo, np.minimum(t1, t2))
            hi = np.minimum(hi, np.maximum(t1, t2))
        ok &= (lo <= hi) & (hi >= EPS)
        t = np.where(lo > EPS, lo, np.where(hi > EPS, hi, np.inf))
        return np.where(ok, t, inf)
    nrm = prim[7:10]
    den = d @ nrm
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.abs(den) < EPS, np.inf, (c @ nrm) / den)
    t = np.where(t > EPS, t, np.inf)
    if kind == PLANE:
        return t
    p = d * np.where(np.isfinite(t), t, 0)[:, None] - c
    if kind == DISK:
        return np.where(np.einsum("ij,ij->i", p, p) <= prim[4] ** 2, t, inf)
    assert kind == RECT
    u = prim[10:13]
    v = np.cross(nrm, u)
    return np.where((np.abs(p @ u) <= prim[4]) & (np.abs(p @ v) <= prim[5]), t, inf)


def cast_static_twin(d, prims):
    o = np.zeros_like(d)
    ts = np.stack([hit_twin(p, o, d) for p in prims], axis=1)
    best = np.argmin(ts, axis=1)
    rng = ts[np.arange(len(d)), best]
    return rng, np.where(np.isfinite(rng), best, -1)


def cast_moving_twin(d, pos, yaw, prims):
    c, s = np.cos(yaw), np.sin(yaw)
    rt = np.stack([np.stack([c, s, np.zeros_like(c)], 1), np.stack([-s, c, np.zeros_like(c)], 1),
                   np.tile([0.0, 0.0, 1.0], (len(c), 1))], 1)  # R^T per ray
    o = np.einsum("nij,nj->ni", rt, -pos)
    dl = np.einsum("nij,nj->ni", rt, d)
    ts = np.stack([hit_twin(p, o, dl) for p in prims], axis=1)
    best = np.argmin(ts, axis=1)
    rng = ts[np.arange(len(d)), best]
    return rng, np.where(np.isfinite(rng), best, -1)


def cast_straight_twin(d, idx, start, bodies, t_ray, start_m, velocity, yaw, prims, prim_start, out_range, out_prim):
    """``cast_straight_kernel``: :func:`cast_moving_twin` body by body, each at its straight pass's
    positions at its rays' times, each ray's nearest hit kept (ids: rows of ``prims``)."""
    out_range, out_prim = out_range.copy(), out_prim.copy()
    for k in bodies:
        rays = idx[start[k]:start[k + 1]]
        if rays.size == 0:
            continue
        pos = straight_position_twin(start_m[k], velocity[k], t_ray[rays])
        lo, hi = prim_start[k], prim_start[k + 1]
        r, p = cast_moving_twin(d[rays], pos, np.full(rays.size, yaw[k]), prims[lo:hi])
        for j, rr, pp in zip(rays, r, p):
            if rr < out_range[j]:
                out_range[j], out_prim[j] = rr, lo + pp
    return out_range, out_prim


def straight_position_twin(start, velocity, t):
    """``Straight.position`` as numpy computes it: ``start + t[:, None] * velocity``."""
    return np.asarray(start) + np.asarray(t, float).reshape(-1, 1) * np.asarray(velocity)


def heading_twin(velocity, default=0.0):
    """``heading_rad`` with numpy's mask: ``default`` where ``not vx^2 + vy^2 > 1e-8``."""
    vx, vy = velocity[:, 0], velocity[:, 1]
    yaw = np.arctan2(vy, vx)
    yaw[~(vx * vx + vy * vy > 1e-8)] = default
    return yaw


def cast_flapping_twin(d, pos, yaw, flap, prims, hinge):
    """``cast_flapping_kernel`` with matrices: the ray into the body frame (``R_z(yaw)^T``), then for a
    hinged primitive of sign ``s`` into its rest frame by ``R_x(-s phi)`` about its hinge point."""
    c, s = np.cos(yaw), np.sin(yaw)
    rt = np.stack([np.stack([c, s, np.zeros_like(c)], 1), np.stack([-s, c, np.zeros_like(c)], 1),
                   np.tile([0.0, 0.0, 1.0], (len(c), 1))], 1)  # R^T per ray
    o = np.einsum("nij,nj->ni", rt, -pos)
    dl = np.einsum("nij,nj->ni", rt, d)
    cols = []
    for p, (sign, hy, hz) in zip(prims, hinge):
        if sign == 0:
            cols.append(hit_twin(p, o, dl))
            continue
        a = -sign * flap
        ca, sa = np.cos(a), np.sin(a)
        rx = np.stack([np.stack([np.ones_like(a), np.zeros_like(a), np.zeros_like(a)], 1),
                       np.stack([np.zeros_like(a), ca, -sa], 1), np.stack([np.zeros_like(a), sa, ca], 1)], 1)
        h = np.array([0.0, hy, hz])
        o2 = np.einsum("nij,nj->ni", rx, o - h) + h
        d2 = np.einsum("nij,nj->ni", rx, dl)
        cols.append(hit_twin(p, o2, d2))
    ts = np.stack(cols, axis=1)
    best = np.argmin(ts, axis=1)
    rng = ts[np.arange(len(d)), best]
    return rng, np.where(np.isfinite(rng), best, -1)


def cos_incidence_twin(prim, p, d):
    """|cos| between rays ``d`` (N,3) and the outward normal of one primitive at hit points ``p``
    (N,3), both in the primitive's frame (written from the geometry, not the kernel)."""
    kind = int(prim[0])
    c = p - prim[1:4]
    if kind == SPHERE:
        n = c / np.linalg.norm(c, axis=1, keepdims=True)
    elif kind == BOX:
        u, v = prim[7:10], prim[10:13]
        axes = np.stack([u, v, np.cross(u, v)])                   # (3, 3)
        rel = np.abs(c @ axes.T) / prim[4:7]                      # offset / half extent per axis
        n = axes[np.argmax(rel, axis=1)]                          # ties: the first axis, as the kernel
    else:
        n = np.tile(prim[7:10], (len(p), 1))
    return np.abs(np.einsum("ij,ij->i", n, d))


def cone_candidates_twin(d, status, c, radius, ok_status=0):
    """Indices of the rays with ``status == ok_status`` passing within ``radius`` of ``c`` (and in
    front of the origin), in order: the distance of c from the ray's line by Pythagoras."""
    b = d[:, 0] * c[0] + d[:, 1] * c[1] + d[:, 2] * c[2]
    c2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
    return np.flatnonzero((c2 - b * b <= radius * radius) & (b > -radius) & (status == ok_status))



def moving_cull_twin(idx, d, t_ray, t_mid, c, v, radius, accel, v_max):
    """The rays of ``idx`` within reach of the body at their own times (kernel's docstring), in order."""
    dt = t_ray[idx] - t_mid
    if accel >= 0.0:
        q = c[None, :] + v[None, :] * dt[:, None]
        reach = (radius + 0.5 * accel * dt * dt) * 1.01 + 1e-3
    else:
        q = np.repeat(np.asarray(c, float)[None, :], idx.size, axis=0)
        reach = (radius + v_max * np.abs(dt)) * 1.01 + 1e-3
    dd = d[idx]
    b = dd[:, 0] * q[:, 0] + dd[:, 1] * q[:, 1] + dd[:, 2] * q[:, 2]
    q2 = q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1] + q[:, 2] * q[:, 2]
    return idx[(q2 - b * b <= reach * reach) & (b > -reach)]

def ray_blocks_twin(d, status, block):
    """``ray_blocks_kernel``: per block of ``block`` rays, the unit axis (its first, middle and last
    rays summed) and the cosine and sine of the widest angle of a valid ray from it, 4e-6 off the
    cosine; -2 (not bounded) for a ray off length 1 by over 1e-6 in |d|^2, a spread over 60 deg or a
    non-finite axis, 2 for a block without a valid ray."""
    n = d.shape[0]
    nb = -(-n // block)
    axis, cos, sin = np.zeros((nb, 3)), np.full(nb, -2.0), np.ones(nb)
    for b in range(nb):
        rows = d[b * block:(b + 1) * block]
        ok = status[b * block:(b + 1) * block] == 0
        a = rows[0] + rows[rows.shape[0] // 2] + rows[-1]
        an = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        if not (an > 0.5 and np.isfinite(an)):
            continue
        axis[b] = a / an
        if not ok.any():
            cos[b] = 2.0
            continue
        v = rows[ok]
        unit = np.abs(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2] - 1.0) <= 1e-6
        dots = v[:, 0] * axis[b, 0] + v[:, 1] * axis[b, 1] + v[:, 2] * axis[b, 2]
        cb = np.min(np.where(unit, dots, -10.0)) - 4e-6
        if cb > 0.5:
            cos[b], sin[b] = cb, np.sqrt(1.0 - cb * cb)
    return axis, cos, sin


def bodies_candidates_twin(d, status, t_ray, t_mid, centres, velocities, reach, radius, accel, v_max, instant):
    """``bodies_candidates_kernel`` as the sensor culled each body before it: its cone's rays, then
    (``instant``) those that can meet it at their own instant; ``(idx, start)``, body by body."""
    per = []
    for c, v, r, rad, acc, vm in zip(centres, velocities, reach, radius, accel, v_max):
        idx = cone_candidates_twin(d, status, c, r)
        per.append(moving_cull_twin(idx, d, t_ray, t_mid, c, v, rad, acc, vm) if instant else idx)
    return (np.concatenate(per) if per else np.zeros(0, np.int64)), np.cumsum([0] + [p.size for p in per])


def bout_index_twin(t, member, starts_per_member):
    """Per time, the bout index (into the members' concatenated starts) numpy's searchsorted finds."""
    out = np.empty(t.size, np.int64)
    lo = 0
    for k, starts in enumerate(starts_per_member):
        rows = member == k
        out[rows] = lo + np.clip(np.searchsorted(starts, t[rows], side="right") - 1, 0, starts.size - 1)
        lo += starts.size
    return out


def flock_candidates_twin(d, status, t_ray, t_mid, centres, velocities, reach, radius, accel, v_max):
    """A flock's cull as the sensor made it before ``bodies_candidates_kernel`` (which is tested
    against this): the rays in the flock's cone (numpy's mean, norms and max), then each bird's cone
    among them and of those the rays that can meet it at their own instant, concatenated bird by bird."""
    g = centres.mean(axis=0)
    off = centres - g
    outer = float(np.max(np.sqrt((off * off).sum(axis=1)) + reach)) * (1.0 + 1e-9) + 1e-6
    sub = cone_candidates_twin(d, status, g, outer)
    per = [moving_cull_twin(sub[cone_candidates_twin(d[sub], status[sub], c, r)], d, t_ray, t_mid, c, v, rad, acc, vm)
           for c, v, r, rad, acc, vm in zip(centres, velocities, reach, radius, accel, v_max)]
    return np.concatenate(per), np.repeat(np.arange(len(per)), [p.size for p in per])


def cast_flock_twin(d, idx, member, pos, yaw, flap, prims, hinge, prim_start, prim_offset, out_range, out_prim):
    """``cast_flock_kernel``: :func:`cast_flapping_twin` bird by bird, each ray's nearest hit kept."""
    out_range, out_prim = out_range.copy(), out_prim.copy()
    for k in range(prim_start.size - 1):
        rows = np.flatnonzero(member == k)
        lo, hi = prim_start[k], prim_start[k + 1]
        r, p = cast_flapping_twin(d[idx[rows]], pos[rows], yaw[rows], flap[rows], prims[lo:hi], hinge[lo:hi])
        for j, rr, pp in zip(idx[rows], r, p):
            if rr < out_range[j]:
                out_range[j], out_prim[j] = rr, prim_offset + lo + pp
    return out_range, out_prim


def _wander_arg_twin(flock, m, t):
    return t[:, None, None] * flock.omega[m] + flock.phase[m]


def flock_positions_twin(flock, m, t):
    """``FlockPoses.positions`` by numpy (``wander_arg_kernel``, ``wander_sum_kernel``): the centre's
    path, the bird's slot and the sum of its wander's sines."""
    return flock.path.position(t) + flock.slot[m] + (flock.amp[m] * np.sin(_wander_arg_twin(flock, m, t))).sum(axis=1)


def flock_velocities_twin(flock, m, t):
    """``FlockPoses.velocities`` by numpy: the centre's velocity and the wander's derivative."""
    return flock.path.velocity(t) + (flock.amp_omega[m] * np.cos(_wander_arg_twin(flock, m, t))).sum(axis=1)


def flock_wing_angles_twin(flock, m, t):
    """``FlockPoses.wing_angles`` by numpy (``wing_phase_kernel``, ``wing_angle_kernel``)."""
    k = bout_index_twin(t, m, [flock.bout_start[lo:hi] for lo, hi in zip(flock.seg_lo, flock.seg_hi)])
    phase = flock.two_pi_f[m] * (t - flock.bout_start[k])
    phi0 = flock.phi0[m]
    return np.where(flock.bout_flaps[k], phi0 + flock.flap_amp[m] * np.sin(phase), phi0)
