"""The lidar's relative transform between two static poses: point-to-plane ICP on scipy's cKDTree.

Paper Section IV.A registers the two accumulated scans with NDT (its ref. [32]) and names ICP as an
alternative.  We use point-to-plane ICP (Chen & Medioni 1992; the linearised least-squares step of
Low 2004, "Linear least-squares optimization for point-to-plane ICP surface registration", UNC
TR04-004) against an NDT-like target model: the target cloud is cut into cubic cells, and each cell
whose points are planar keeps its mean and normal (PCA of the raw points in it, as NDT keeps its
cells' normal distributions; Biber & Strasser 2003).  Why this and not plain NDT or centroid ICP:

* the calibration scenes are rooms and yards made of planes, where point-to-plane converges in a few
  iterations and its 6 x 6 normal matrix tells which directions the scene constrains (a 16-line
  lidar whose rings give line-like cells leaves directions loose: the paper's Fig. 10a point);
* source points stay raw (zero-mean range noise averages out in the least squares), and the target's
  planes are fitted to raw points in cells much larger than the noise: voxel *centroids* of small
  cells (5 cm against 2 cm of range noise) are pulled toward each cloud's own voxel grid, a bias
  that did not average out and grew with accumulation (measured: 1 deg, 8 cm after 2 s on the
  Mid-40; noise-free data registered to 0.01-0.04 deg);
* no well-kept pure-Python registration library is among our dependencies (Open3D is a large binary
  dependency for two functions); scipy's cKDTree does the nearest-neighbour work.

A direction the planes in view do not face is not measured, and ICP must not walk along it: a
Horizon level in a room (25 deg of vertical view) sees the walls and the boxes' sides but neither
floor nor ceiling, and from a seed 0.7 cm off along it ICP drifted 53 cm down, each step nudged by the few
points on edges.  Where the normal matrix's translation block gives a direction less than
:data:`FREE_TRANSLATION_SHARE` of the best-fixed one's information, the steps leave it alone (the
seed's value stays) and :attr:`Registration.free_directions` names it, so that the hand-eye solve
does not take the seed's value there for evidence (:func:`~foveatrack.imu_calib.handeye.solve_handeye`).

Every step is deterministic (source subsampling is a fixed stride).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from foveatrack.imu_calib.se3 import so3_exp, transform_points

# (cell [m], max correspondence distance [m], iterations) per stage, coarse to fine.
DEFAULT_STAGES = ((0.5, 0.30, 15), (0.25, 0.10, 10), (0.25, 0.05, 20))
MAX_SOURCE_POINTS = 15_000    # fixed strides beyond these (cost); the planes keep every point
MAX_ANCHOR_POINTS = 120_000
MAX_NORMAL_ANGLE_DEG = 15.0   # source and target planes of a correspondence must agree this well
_COS_NORMAL = float(np.cos(np.radians(MAX_NORMAL_ANGLE_DEG)))
MAX_PLANE_POINTS = 1_000_000  # per cloud for the plane fits (a fixed stride beyond): compute time
_SELF_AND_FACES = ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))
#: A translation direction whose information (eigenvalue of the normal matrix's translation block) is
#: below this share of the best-fixed direction's is not measured: the planes in view barely face it.
#: A Horizon level in a room (25 deg of vertical view) sees walls and boxes' sides but no floor or
#: ceiling: the vertical's share fell to 3e-4 and 1e-3 in the two pairs where ICP walked 53 and 42 cm
#: along it from a seed ~1 cm off (the live rig's 2 s clouds, scenes/imu-calibration-head.toml; the
#: median share 0.25).  Not higher: at 1e-2 the VLP-16's weak horizontal in the room (shares 3e-3 to
#: 1e-2 in half its pairs) was held at the seed, and its extrinsic at 10 s went from 0.15 to 0.35 deg:
#: information that weak still beat a seed through the nominal mount (docs/imu-calibration.md).
FREE_TRANSLATION_SHARE = 2e-3


def _cell_keys(points: np.ndarray, cell_m: float):
    keys = np.floor(points / cell_m).astype(np.int64)
    lo = keys.min(axis=0)
    keys -= lo
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    return keys, lo, flat


def voxel_downsample(points: np.ndarray, voxel_m: float, min_points: int = 1) -> np.ndarray:
    """Centroids of the points in each occupied cubic voxel of edge ``voxel_m`` [m] (sorted by
    voxel key, so the result does not depend on the order of the input points)."""
    if len(points) == 0:
        return np.zeros((0, 3))
    _, _, flat = _cell_keys(points, voxel_m)
    uniq, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    cent = np.column_stack([np.bincount(inverse, points[:, i], len(uniq)) for i in range(3)]) / counts[:, None]
    return cent[counts >= min_points]


@dataclass(frozen=True)
class PlaneCells:
    """Planar cells of a cloud: mean [m], unit normal, and point count."""

    mean_m: np.ndarray
    normal: np.ndarray
    count: np.ndarray
    label: np.ndarray    # per input point: its planar cell's index, or -1

    def __len__(self) -> int:
        return len(self.mean_m)


def _moments(local: np.ndarray, idx: np.ndarray, n: int, w: np.ndarray | None = None):
    """Per-cell count, first and second moments of ``local`` points (cell ``idx``), by bincount."""
    cnt = np.bincount(idx, w, n)
    s1 = np.column_stack([np.bincount(idx, local[:, i] if w is None else local[:, i] * w, n) for i in range(3)])
    s2 = np.empty((n, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            v = local[:, i] * local[:, j]
            s2[:, i, j] = s2[:, j, i] = np.bincount(idx, v if w is None else v * w, n)
    return cnt, s1, s2


def _pca(cnt, s1, s2):
    c = np.maximum(cnt, 1)[:, None]
    mu = s1 / c
    cov = s2 / c[:, :, None] - mu[:, :, None] * mu[:, None, :]
    lam, vec = np.linalg.eigh(cov)
    return mu, np.maximum(lam, 0.0), vec


def plane_cells(points: np.ndarray, cell_m: float, min_points: int = 8, max_flatness: float = 0.2,
                min_extent: float = 0.05, band_m: float = 0.1, min_coplanar_neighbours: int = 0) -> PlaneCells:
    """Cells of edge ``cell_m`` whose points lie on a plane: the eigenvalues ``l0 <= l1 <= l2`` of
    their covariance satisfy ``l0 / l1 < max_flatness`` (thin) and ``l1 / l2 > min_extent`` (a patch,
    not a line: one scan ring in a cell gives no normal).  Moments are taken about each cell's
    corner, so nothing cancels in floating point.

    Two passes (at most :data:`MAX_PLANE_POINTS` points, by a fixed stride: the cost).  A cube cuts a noisy plane wherever the plane runs close to one of its faces: the
    points on the far side of the face land in the next cell, and both cells' means move off the
    plane (measured: a room's front wall 2 cm inside a cell face gave 1.4-1.8 cm mean residuals
    at the true transform, a bias that longer accumulation does not average away; range noise lies
    along the beam, so its spread across the plane is not small).  So the first pass only finds
    each planar cell's plane; the second refits it from every point within ``band_m`` of that plane
    whose projection onto it falls inside the cell, whichever cube the point itself is in (the
    point's own cube or one of its six face neighbours: a plane 10 cm from a cube's edge and corner
    at once is rare, and the 27-neighbour version cost four times as much for no measured gain).
    ``min_coplanar_neighbours`` > 0 also drops cells with fewer planar neighbours of the same
    plane (edges of surfaces).
    """
    empty = PlaneCells(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64),
                       np.full(len(points), -1, dtype=np.int64))
    if len(points) < min_points:
        return empty
    keys = np.floor(points / cell_m).astype(np.int64)
    lo = keys.min(axis=0) - 1
    keys -= lo
    shape = keys.max(axis=0) + 2
    flat = (keys[:, 0] * shape[1] + keys[:, 1]) * shape[2] + keys[:, 2]
    uniq, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    local = points - (keys + lo) * cell_m
    cnt, s1, s2 = _moments(local, inverse, len(uniq))
    mu, lam, vec = _pca(cnt, s1, s2)
    planar = ((counts >= min_points) & (lam[:, 0] < max_flatness * lam[:, 1])
              & (lam[:, 1] > min_extent * lam[:, 2]))
    if not planar.any():
        return empty
    codes = uniq[planar]                      # sorted
    normal = vec[planar, :, 0]
    cell_keys = np.column_stack(np.unravel_index(codes, tuple(int(v) for v in shape)))
    offset = np.einsum("ij,ij->i", normal, mu[planar])  # plane: n . local = offset (cell-corner frame)
    m = len(codes)
    # Second pass: every point near a planar cell's plane whose projection is inside that cell.
    pts_idx, cell_idx, loc_list = [], [], []
    for dx, dy, dz in _SELF_AND_FACES:
        nb = flat + (dx * shape[1] + dy) * shape[2] + dz
        pos = np.clip(np.searchsorted(codes, nb), 0, m - 1)
        found = np.flatnonzero(codes[pos] == nb)
        if not len(found):
            continue
        j = pos[found]
        loc = local[found] - np.array([dx, dy, dz]) * cell_m    # in cell j's corner frame
        d = np.einsum("ij,ij->i", loc, normal[j]) - offset[j]
        proj = loc - d[:, None] * normal[j]
        ok = (np.abs(d) < band_m) & np.all((proj >= 0) & (proj < cell_m), axis=1)
        pts_idx.append(found[ok])
        cell_idx.append(j[ok])
        loc_list.append(loc[ok])
        del nb, pos
    pi = np.concatenate(pts_idx)
    ci = np.concatenate(cell_idx)
    cnt2, s1b, s2b = _moments(np.vstack(loc_list), ci, m)
    mu2, lam2, vec2 = _pca(cnt2, s1b, s2b)
    good = ((cnt2 >= min_points) & (lam2[:, 0] < max_flatness * lam2[:, 1])
            & (lam2[:, 1] > min_extent * lam2[:, 2]))
    if min_coplanar_neighbours > 0 and good.any():
        good[good] = _interior(cell_keys[good], (mu2 + cell_keys * cell_m)[good], vec2[good, :, 0],
                               min_coplanar_neighbours)
    new_index = np.full(m, -1, dtype=np.int64)
    new_index[good] = np.arange(int(good.sum()))
    label = np.full(len(points), -1, dtype=np.int64)
    # a point within the band of two cells' planes keeps the last one: either is its surface
    label[pi] = new_index[ci]
    corner = (cell_keys + lo) * cell_m
    return PlaneCells((mu2 + corner)[good], vec2[good, :, 0], cnt2[good].astype(np.int64), label)


def _interior(cell_keys: np.ndarray, mean_m: np.ndarray, normal: np.ndarray, need: int,
              max_angle_deg: float = 15.0, max_offset_m: float = 0.02) -> np.ndarray:
    """True for planar cells with at least ``need`` coplanar planar neighbours (of 26)."""
    shape = cell_keys.max(axis=0) + 3
    code = ((cell_keys[:, 0] + 1) * shape[1] + cell_keys[:, 1] + 1) * shape[2] + cell_keys[:, 2] + 1
    order = np.argsort(code)
    sorted_code = code[order]
    cos_max = np.cos(np.radians(max_angle_deg))
    count = np.zeros(len(code), dtype=np.int64)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if dx == dy == dz == 0:
                    continue
                nb = code + (dx * shape[1] + dy) * shape[2] + dz
                pos = np.clip(np.searchsorted(sorted_code, nb), 0, len(code) - 1)
                found = sorted_code[pos] == nb
                j = order[pos]
                same = (found & (np.abs(np.einsum("ij,ij->i", normal, normal[j])) > cos_max)
                        & (np.abs(np.einsum("ij,ij->i", normal, mean_m[j] - mean_m)) < max_offset_m))
                count += same
    return count >= need


@dataclass(frozen=True)
class Registration:
    T: np.ndarray               # 4 x 4: maps source (lidar frame at pose j) into target (pose i)
    rms_m: float                # point-to-plane rms of the last stage's inliers
    inliers: int
    information: np.ndarray     # 6 x 6 J^T J of the last stage (order: rotation, translation)
    iterations: int
    # (k, 3) unit directions (target frame) along which the scene does not fix the translation
    # (:func:`free_translation_directions`): ``T``'s translation along them is the seed's
    free_directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def weakest_direction(self) -> tuple[float, np.ndarray]:
        """Smallest eigenvalue of the translation block and its direction (how well the scene
        pins the translation: a 16-line lidar that sees only walls leaves z loose)."""
        lam, vec = np.linalg.eigh(self.information[3:, 3:])
        return float(lam[0]), vec[:, 0]


def free_translation_directions(H: np.ndarray) -> np.ndarray:
    """(k, 3) unit directions of the translation block of the 6 x 6 normal matrix ``H`` whose
    information is below :data:`FREE_TRANSLATION_SHARE` of the largest (k = 0 for a scene of planes
    facing every way)."""
    lam, vec = np.linalg.eigh(H[3:, 3:])
    if not lam[-1] > 0:
        return np.eye(3)
    return vec[:, lam < FREE_TRANSLATION_SHARE * lam[-1]].T.copy()


def _step(H: np.ndarray, g: np.ndarray) -> np.ndarray:
    """The Gauss-Newton step ``-H^-1 g``, none along a free translation direction: point-to-plane ICP
    otherwise walks along it, each step nudged by the few points that touch it."""
    free = free_translation_directions(H)
    if not len(free):
        return -np.linalg.lstsq(H, g, rcond=1e-12)[0]
    # basis of the steps that leave the free directions alone: rotation, and the translation's rest
    keep = np.linalg.svd(np.eye(3) - free.T @ free)[0][:, :3 - len(free)]
    Q = np.zeros((6, 6 - len(free)))
    Q[:3, :3] = np.eye(3)
    Q[3:, 3:] = keep
    return -Q @ np.linalg.lstsq(Q.T @ H @ Q, Q.T @ g, rcond=1e-12)[0]


def _icp_stage(src: np.ndarray, src_normal: np.ndarray, cells: PlaneCells, anchor_cell: np.ndarray, tree: cKDTree,
               T: np.ndarray, max_dist_m: float, iterations: int, tol: float = 1e-8):
    """Point-to-plane Gauss-Newton steps: each source point against the plane of the cell of its
    nearest target point (nearest point, not nearest cell mean: near an inside corner the nearest
    mean is often the other wall's), kept only if the source point's own plane has the same normal
    within :data:`MAX_NORMAL_ANGLE_DEG` (a ceiling point next to a wall is otherwise matched to the
    wall's plane: measured 1.5 cm mean residuals on such cells at the true transform, a bias that
    more points do not average away)."""
    H = np.zeros((6, 6))
    rms, used, it = np.inf, 0, 0
    for it in range(1, iterations + 1):
        p = transform_points(T, src)
        dist, j = tree.query(p, distance_upper_bound=max_dist_m)
        ok = np.isfinite(dist)
        if ok.sum() < 6:
            break
        c_idx = anchor_cell[j[ok]]
        p, q, nrm = p[ok], cells.mean_m[c_idx], cells.normal[c_idx]
        agree = np.abs(np.einsum("ij,ij->i", src_normal[ok] @ T[:3, :3].T, nrm)) > _COS_NORMAL
        if agree.sum() < 6:
            break
        p, q, nrm = p[agree], q[agree], nrm[agree]
        r = np.einsum("ij,ij->i", p - q, nrm)
        # Huber weights at 1/5 of the correspondence distance: points of other surfaces count less.
        c = max_dist_m / 5
        w = np.where(np.abs(r) <= c, 1.0, c / np.maximum(np.abs(r), 1e-30))
        J = np.hstack([np.cross(p, nrm), nrm])          # d r / d(omega, v), left perturbation
        Jw = J * w[:, None]
        H = Jw.T @ J
        g = Jw.T @ r
        delta = _step(H, g)
        step = np.eye(4)
        step[:3, :3] = so3_exp(delta[:3])
        step[:3, 3] = delta[3:]
        T = step @ T
        rms, used = float(np.sqrt(np.mean(r ** 2))), int(ok.sum())
        if np.linalg.norm(delta) < tol:
            break
    return T, rms, used, H, it


class CloudModel:
    """One pose's cloud with its planar cells per cell size, computed once and used both as the
    target of one pair and as the source of the next."""

    def __init__(self, points: np.ndarray):
        stride = max(1, -(-len(points) // MAX_PLANE_POINTS))
        self.points = np.ascontiguousarray(points[::stride])
        self._cells: dict = {}

    def cells(self, cell_m: float):
        if cell_m not in self._cells:
            cells = plane_cells(self.points, cell_m)
            on_plane = np.flatnonzero(cells.label >= 0)
            anchors = on_plane[::max(1, -(-len(on_plane) // MAX_ANCHOR_POINTS))]
            tree = cKDTree(self.points[anchors]) if len(anchors) else None
            sources = on_plane[::max(1, -(-len(on_plane) // MAX_SOURCE_POINTS))]
            self._cells[cell_m] = (cells, cells.label[anchors], tree, self.points[sources],
                                   cells.normal[cells.label[sources]])
        return self._cells[cell_m]


def register(source, target, T0: np.ndarray | None = None, stages=DEFAULT_STAGES) -> Registration:
    """Transform that maps ``source`` points (lidar frame at pose j) onto ``target`` (pose i).

    Parameters
    ----------
    source, target : (N, 3) [m] accumulated clouds, each in the lidar frame of its pose, or
        :class:`CloudModel` of them (to reuse a cloud's cells across pairs)
    T0 : 4 x 4 initial guess (default identity); ICP only converges from a guess within its
        basin (in a room, a few degrees and a few tenths of a metre).
    stages : ((cell_m, max_dist_m, iterations), ...) coarse to fine
    """
    src_model = source if isinstance(source, CloudModel) else CloudModel(source)
    tgt_model = target if isinstance(target, CloudModel) else CloudModel(target)
    T = np.eye(4) if T0 is None else T0.copy()
    total = 0
    rms, used, H = np.inf, 0, np.zeros((6, 6))
    for cell_m, max_dist_m, iters in stages:
        cells, anchor_cell, tree, _, _ = tgt_model.cells(cell_m)
        _, _, _, src_pts, src_nrm = src_model.cells(cell_m)
        if tree is None or len(cells) < 6 or len(src_pts) < 6:
            break
        T, rms, used, H, it = _icp_stage(src_pts, src_nrm, cells, anchor_cell, tree, T, max_dist_m, iters)
        total += it
    return Registration(T, rms, used, H, total, free_translation_directions(H) if used else np.zeros((0, 3)))
