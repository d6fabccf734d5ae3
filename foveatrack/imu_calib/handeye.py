"""The extrinsic from the hand-eye problem ``A_i X = X B_i`` (paper Section IV.A, refs. [35], [36]).

``A_i``: the lidar's relative transform between two static poses (lidar frame of the first pose);
``B_i``: the IMU's (IMU frame of the first pose); ``X = T_lidar_imu``: the IMU's pose in the lidar
frame (maps IMU coordinates into lidar coordinates), so that ``T_world_imu = T_world_lidar X``.

Solver: Park & Martin, "Robot sensor calibration: solving AX = XB on the Euclidean group",
IEEE Trans. Robotics and Automation 10(5), 1994.  Rotation: with ``alpha_i = Log(R_Ai)`` and
``beta_i = Log(R_Bi)``, ``alpha_i = R_X beta_i``; Park-Martin's least-squares solution is
``R_X = (M^T M)^{-1/2} M^T`` with ``M = sum beta_i alpha_i^T``.  We compute the same least-squares
rotation by SVD (orthogonal Procrustes: Arun, Huang & Blostein 1987), which equals Park-Martin's
where ``M^T M`` is invertible and still works when the axes span only a plane (two distinct axes
determine ``R_X``).  Translation: the stacked linear least squares
``(R_Ai - I) t_X = R_X t_Bi - t_Ai`` (Park-Martin eq. 22).

Degenerate motions are refused with :class:`DegenerateMotion` (a :class:`UserError`), not solved:

* a pair whose rotation is below ``min_rotation_deg`` carries no rotation information and makes
  ``R_Ai - I`` near zero; such pairs are dropped, and fewer than two left is an error;
* all rotation axes (nearly) parallel: the rotation about the axes' common direction is fixed but
  the translation along it is not (Tsai & Lenz 1989, Park & Martin 1994 Sec. III: at least two
  pairs with non-parallel axes are needed).  The spread of the axes is the angle
  ``2 atan(sqrt(l2 / l1))`` from the eigenvalues ``l1 >= l2`` of ``sum u_i u_i^T`` (exactly the
  angle between the axes when there are two); below ``min_axis_spread_deg`` is an error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foveatrack.errors import UserError
from foveatrack.imu_calib.se3 import make_T, so3_exp, so3_log


class DegenerateMotion(UserError):
    """The poses' relative motions cannot determine the extrinsic (the message says why)."""


@dataclass(frozen=True)
class HandEyeResult:
    X: np.ndarray                    # 4 x 4, T_lidar_imu
    pairs_used: int
    axis_spread_deg: float
    rotation_residual_deg: np.ndarray    # per pair: |alpha_i - R_X beta_i| [deg]
    translation_residual_m: np.ndarray   # per pair: |(R_A - I) t_X - R_X t_B + t_A| [m]


def axis_spread_deg(axes: np.ndarray, weights: np.ndarray | None = None) -> float:
    """Spread of rotation axes (any sign) [deg]: 0 when all are parallel, 90 for two orthogonal."""
    u = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    w = np.ones(len(u)) if weights is None else weights
    S = (u * w[:, None]).T @ u
    lam = np.sort(np.linalg.eigvalsh(S))[::-1]
    if lam[0] <= 0:
        return 0.0
    return float(np.degrees(2 * np.arctan(np.sqrt(max(lam[1], 0.0) / lam[0]))))


def solve_handeye(A: list[np.ndarray], B: list[np.ndarray], min_rotation_deg: float = 2.0,
                  min_axis_spread_deg: float = 10.0) -> HandEyeResult:
    """Least-squares ``X`` of ``A_i X = X B_i`` (Park & Martin 1994).

    Parameters
    ----------
    A, B : sequences of 4 x 4 transforms, the same length (pairs of poses)
    min_rotation_deg : float > 0 [deg]
        Pairs whose IMU rotation is smaller are dropped (see the module docstring).
    min_axis_spread_deg : float > 0 [deg]
        Below this spread of the rotation axes the motion is degenerate: error.
    """
    if len(A) != len(B):
        raise ValueError(f"{len(A)} lidar motions but {len(B)} IMU motions")
    alpha = np.array([so3_log(a[:3, :3]) for a in A]).reshape(-1, 3)
    beta = np.array([so3_log(b[:3, :3]) for b in B]).reshape(-1, 3)
    ang_deg = np.degrees(np.linalg.norm(beta, axis=1))
    keep = ang_deg >= min_rotation_deg
    if keep.sum() < 2:
        raise DegenerateMotion(
            f"only {int(keep.sum())} of {len(A)} pose pairs rotate by at least {min_rotation_deg:g} deg "
            f"(rotations {', '.join(f'{a:.2f}' for a in ang_deg)} deg): the rotation between the "
            "sensors cannot be found; turn the rig by about 10 deg between poses, about different axes")
    alpha, beta = alpha[keep], beta[keep]
    A = [a for a, k in zip(A, keep) if k]
    B = [b for b, k in zip(B, keep) if k]
    spread = axis_spread_deg(beta)
    if spread < min_axis_spread_deg:
        raise DegenerateMotion(
            f"all {len(A)} pose pairs rotate about (nearly) one axis (axes spread {spread:.2f} deg < "
            f"{min_axis_spread_deg:g} deg): the translation along that axis is unobservable; "
            "turn the rig about at least two different axes")
    # Rotation: min sum |alpha_i - R beta_i|^2 (Park-Martin's least squares, solved by SVD).
    H = beta.T @ alpha
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R_X = Vt.T @ D @ U.T
    # Translation: (R_A - I) t_X = R_X t_B - t_A, stacked.
    C = np.vstack([a[:3, :3] - np.eye(3) for a in A])
    d = np.concatenate([R_X @ b[:3, 3] - a[:3, 3] for a, b in zip(A, B)])
    t_X, *_ = np.linalg.lstsq(C, d, rcond=None)
    rot_res = np.degrees(np.linalg.norm(alpha - beta @ R_X.T, axis=1))
    tr_res = np.linalg.norm((C @ t_X - d).reshape(-1, 3), axis=1)
    return HandEyeResult(make_T(R_X, t_X), len(A), spread, rot_res, tr_res)


@dataclass(frozen=True)
class Uncertainty:
    rotation_sigma_deg: np.ndarray    # (3,) 1-sigma of the rotation error vector, lidar frame
    translation_sigma_m: np.ndarray   # (3,)
    samples: int


def bootstrap_uncertainty(A, B, X: np.ndarray, samples: int = 200, seed: int = 0, **solve_kw) -> Uncertainty:
    """1-sigma of ``X`` by resampling the pose pairs with replacement (Efron's bootstrap).

    Resamples whose motion is degenerate are skipped.  With few pairs (< 6) the bootstrap
    understates the spread; the figure is what the data supports, not a guarantee.
    """
    rng = np.random.default_rng(seed)
    n = len(A)
    rot, tr = [], []
    for _ in range(samples):
        idx = rng.integers(0, n, n)
        try:
            r = solve_handeye([A[i] for i in idx], [B[i] for i in idx], **solve_kw)
        except DegenerateMotion:
            continue
        rot.append(np.degrees(so3_log(r.X[:3, :3] @ X[:3, :3].T)))
        tr.append(r.X[:3, 3] - X[:3, 3])
    if len(rot) < 2:
        nan = np.full(3, np.nan)
        return Uncertainty(nan, nan, len(rot))
    return Uncertainty(np.std(rot, axis=0, ddof=1), np.std(tr, axis=0, ddof=1), len(rot))


def random_rotation(rng: np.random.Generator, angle_deg: float) -> np.ndarray:
    """A rotation of ``angle_deg`` about a uniformly random axis (test and simulation helper)."""
    axis = rng.normal(size=3)
    return so3_exp(axis / np.linalg.norm(axis) * np.radians(angle_deg))
