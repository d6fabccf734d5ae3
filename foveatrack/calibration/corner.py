"""The tracked feature: a room corner found in a frame's points (three RANSAC planes, their
intersection), and the geometry of turning points about an axis (paper Appendix D.4)."""

from __future__ import annotations

import numpy as np

from foveatrack.calibration.plan import FeatureSpec

def _fit_plane(p: np.ndarray) -> tuple[np.ndarray, float]:
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c, full_matrices=False)
    n = vt[-1]
    return n, float(n @ c)


def find_corner(xyz: np.ndarray, center: np.ndarray, spec: FeatureSpec, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """Corner (intersection of three planes) near ``center``; returns (corner, inlier mask) or None.

    Sequential RANSAC for three planes (inliers within ``plane_tol_m``), each refined by SVD; then
    each plane is refitted on the points near it but away from the other two."""
    d = np.linalg.norm(xyz - center, axis=1)
    sel = np.flatnonzero(d <= spec.radius_m)
    if sel.size < 3 * spec.min_plane_points:
        return None
    pts = xyz[sel]
    remaining = np.arange(len(pts))
    planes, used = [], np.zeros(len(pts), bool)
    for _ in range(3):
        P = pts[remaining]
        if len(P) < spec.min_plane_points:
            return None
        idx = rng.integers(0, len(P), size=(spec.ransac_iters, 3))
        a, b, c = P[idx[:, 0]], P[idx[:, 1]], P[idx[:, 2]]
        n = np.cross(b - a, c - a)
        nn = np.linalg.norm(n, axis=1)
        ok = nn > 1e-9
        n = n[ok] / nn[ok, None]
        off = np.einsum("ij,ij->i", n, a[ok])
        dist = np.abs(P @ n.T - off)                      # (len(P), hyps)
        counts = (dist < spec.plane_tol_m).sum(axis=0)
        if counts.size == 0:
            return None
        best = int(np.argmax(counts))
        inl = dist[:, best] < spec.plane_tol_m
        if inl.sum() < spec.min_plane_points:
            return None
        nrm, o = _fit_plane(P[inl])
        inl = np.abs(P @ nrm - o) < spec.plane_tol_m          # re-select with the refined plane
        nrm, o = _fit_plane(P[inl])
        planes.append((nrm, o))
        used[remaining[inl]] = True
        remaining = remaining[~inl]
    # final refinement: each plane from the points near it and away from the other two (points along
    # the corner's edges would otherwise pull a plane toward its neighbours)
    N = np.array([p[0] for p in planes])
    D = np.array([p[1] for p in planes])
    dist = np.abs(pts @ N.T - D)                          # (n, 3)
    for i in range(3):
        own = (dist[:, i] < spec.plane_tol_m) & np.all(np.delete(dist, i, axis=1) > spec.plane_tol_m, axis=1)
        if own.sum() >= spec.min_plane_points:
            N[i], D[i] = _fit_plane(pts[own])
    # normals well separated (a corner, not two parallel walls)
    g = np.abs(N @ N.T)[np.triu_indices(3, 1)]
    if g.max() > 0.5 or abs(np.linalg.det(N)) < 0.3:
        return None
    corner = np.linalg.solve(N, D)
    if np.linalg.norm(corner - center) > spec.radius_m:
        return None
    mask = np.zeros(len(xyz), bool)
    mask[sel[used]] = True
    return corner, mask


def _rotate_about(p: np.ndarray, axis: np.ndarray, ang_rad: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of points p (n,3) about a unit axis by per-point angles."""
    c, s = np.cos(ang_rad)[:, None], np.sin(ang_rad)[:, None]
    k = axis[None, :]
    return p * c + np.cross(k, p) * s + k * (p @ axis)[:, None] * (1 - c)


def _angle_about(q: np.ndarray, axis: np.ndarray, ref: np.ndarray) -> np.ndarray:
    e1 = ref - (ref @ axis) * axis
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    return np.degrees(np.arctan2(q @ e2, q @ e1))


def _angle_about_unwrapped(q: np.ndarray, axis: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """:func:`_angle_about` [deg] unwrapped along the samples (no 360 deg jump where it crosses 180)."""
    return np.degrees(np.unwrap(np.radians(_angle_about(q, axis, ref))))


_SIGN = {"pan": -1.0, "tilt": +1.0}   # head speed = sign * d(angle of corner about axis)/dt
