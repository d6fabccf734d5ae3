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

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from foveatrack.errors import UserError
from foveatrack.imu_calib.se3 import make_T, skew, so3_exp, so3_log


#: Below this spread of the rotation axes (but above the refusal threshold) the result carries a
#: warning: on 802524f, 24 pairs 12 deg apart gave X 0.58 deg / 2.5 cm off with no word (issue 27).
WEAK_AXIS_SPREAD_DEG = 30.0


class DegenerateMotion(UserError):
    """The poses' relative motions cannot determine the extrinsic (the message says why)."""


@dataclass(frozen=True)
class HandEyeResult:
    X: np.ndarray                    # 4 x 4, T_lidar_imu
    pairs_used: int
    axis_spread_deg: float
    rotation_residual_deg: np.ndarray    # per pair used: |alpha_i - R_X beta_i| [deg]
    translation_residual_m: np.ndarray   # per pair used: |(R_A - I) t_X - R_X t_B + t_A| [m]
    used: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # indices of the pairs used
    # The joint fit's noise per pair (estimated from its residuals) and its 6 x 6 covariance of
    # (rotation error vector [rad], lidar frame; translation [m]); None for the closed form alone.
    pair_sigma_rad: float = float("nan")
    pair_sigma_m: float = float("nan")
    covariance: np.ndarray | None = None
    dof: int = 0                     # residuals minus parameters of the joint fit


def axis_spread_deg(axes: np.ndarray, weights: np.ndarray | None = None) -> float:
    """Spread of rotation axes (any sign) [deg]: 0 when all are parallel, 90 for two orthogonal."""
    u = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    w = np.ones(len(u)) if weights is None else weights
    S = (u * w[:, None]).T @ u
    lam = np.sort(np.linalg.eigvalsh(S))[::-1]
    if lam[0] <= 0:
        return 0.0
    return float(np.degrees(2 * np.arctan(np.sqrt(max(lam[1], 0.0) / lam[0]))))


def measured_part(free: np.ndarray | None) -> np.ndarray:
    """3 x 3 projector onto the translation directions a pair's lidar motion measured: ``I`` less
    its ``free`` directions ((k, 3) unit rows, :attr:`...registration.Registration.free_directions`:
    the registration kept the seed's translation along them, so they carry no evidence)."""
    if free is None or not len(free):
        return np.eye(3)
    free = np.asarray(free, float).reshape(-1, 3)
    return np.eye(3) - free.T @ free


def _projectors(free, n: int) -> np.ndarray:
    return np.array([measured_part(None if free is None else free[i]) for i in range(n)]).reshape(n, 3, 3)


def pair_residuals(A: np.ndarray, B: np.ndarray, X: np.ndarray, free: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """One pair's residuals of ``A X = X B``: rotation ``alpha - R_X beta`` [rad] and translation
    ``(R_A - I) t_X - R_X t_B + t_A`` [m] (3-vectors, lidar frame), the translation's only along the
    directions the lidar measured (``free``: those it did not, see :func:`measured_part`)."""
    R, t = X[:3, :3], X[:3, 3]
    r_rot = so3_log(A[:3, :3]) - R @ so3_log(B[:3, :3])
    r_tr = (A[:3, :3] - np.eye(3)) @ t - R @ B[:3, 3] + A[:3, 3]
    return r_rot, measured_part(free) @ r_tr


def _logs(T) -> np.ndarray:
    """Rotation vectors of the rotation parts of a sequence of 4 x 4 transforms, (n, 3) [rad]."""
    if not len(T):
        return np.zeros((0, 3))
    return Rotation.from_matrix(np.array([t[:3, :3] for t in T])).as_rotvec().reshape(-1, 3)


def _rotation_pairs(A, B, min_rotation_deg: float, min_axis_spread_deg: float):
    """Log maps of the pairs that rotate enough, their indices and the axes' spread (or refuse)."""
    if len(A) != len(B):
        raise ValueError(f"{len(A)} lidar motions but {len(B)} IMU motions")
    alpha = _logs(A)
    beta = _logs(B)
    ang_deg = np.degrees(np.linalg.norm(beta, axis=1))
    keep = ang_deg >= min_rotation_deg
    if keep.sum() < 2:
        raise DegenerateMotion(
            f"only {int(keep.sum())} of {len(A)} pose pairs rotate by at least {min_rotation_deg:g} deg "
            f"(rotations {', '.join(f'{a:.2f}' for a in ang_deg)} deg): the rotation between the "
            "sensors cannot be found; turn the rig by about 10 deg between poses, about different axes")
    used = np.flatnonzero(keep)
    spread = axis_spread_deg(beta[keep])
    if spread < min_axis_spread_deg:
        raise DegenerateMotion(
            f"all {len(used)} pose pairs rotate about (nearly) one axis (axes spread {spread:.2f} deg < "
            f"{min_axis_spread_deg:g} deg): the translation along that axis is unobservable; "
            "turn the rig about at least two different axes")
    return alpha[keep], beta[keep], used, spread


def park_martin(A, B, min_rotation_deg: float = 2.0, min_axis_spread_deg: float = 10.0, free=None) -> HandEyeResult:
    """Closed-form least-squares ``X`` of ``A_i X = X B_i`` (Park & Martin 1994): the rotation from
    the rotation vectors alone, then the translation with the rotation held."""
    alpha, beta, used, spread = _rotation_pairs(A, B, min_rotation_deg, min_axis_spread_deg)
    return _park_martin(A, B, alpha, beta, used, spread, _projectors(free, len(A))[used])


def _park_martin(A, B, alpha, beta, used, spread, P) -> HandEyeResult:
    A = [A[i] for i in used]
    B = [B[i] for i in used]
    # Rotation: min sum |alpha_i - R beta_i|^2 (Park-Martin's least squares, solved by SVD).
    H = beta.T @ alpha
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R_X = Vt.T @ D @ U.T
    # Translation: (R_A - I) t_X = R_X t_B - t_A, stacked.
    # (each pair's rows only along the directions its lidar motion measured: P, measured_part)
    C = np.vstack([p @ (a[:3, :3] - np.eye(3)) for a, p in zip(A, P)])
    d = np.concatenate([p @ (R_X @ b[:3, 3] - a[:3, 3]) for a, b, p in zip(A, B, P)])
    t_X, *_ = np.linalg.lstsq(C, d, rcond=None)
    rot_res = np.degrees(np.linalg.norm(alpha - beta @ R_X.T, axis=1))
    tr_res = np.linalg.norm((C @ t_X - d).reshape(-1, 3), axis=1)
    return HandEyeResult(make_T(R_X, t_X), len(A), spread, rot_res, tr_res, used)


#: Noise floors of the joint fit's weights (only their ratio matters; these keep exact data finite).
_SIGMA_FLOOR_RAD = 1e-9
_SIGMA_FLOOR_M = 1e-10


def _joint_system(alpha, beta, RA, tA, tB, X, P):
    """Stacked residuals (rotation block, translation block) and their Jacobians with respect to
    ``(delta, dt)``, ``R_X <- Exp(delta) R_X``, ``t_X <- t_X + dt`` (per pair: ``alpha, beta`` the
    rotation vectors, ``RA`` the lidar's rotation, ``tA, tB`` the translations, ``P`` the projector
    onto the translation it measured; arrays over pairs)."""
    n = len(alpha)
    R, t = X[:3, :3], X[:3, 3]
    Rb = beta @ R.T
    Rtb = tB @ R.T
    I = np.eye(3)
    r_rot = alpha - Rb
    r_tr = np.einsum("nij,j->ni", RA - I, t) - Rtb + tA
    J_rot = np.zeros((n, 3, 6))
    J_tr = np.empty((n, 3, 6))
    J_rot[:, :, :3] = _skews(Rb)            # d(-Exp(delta) R beta)/d delta = [R beta]_x
    J_tr[:, :, :3] = _skews(Rtb)
    J_tr[:, :, 3:] = RA - I
    r_tr = np.einsum("nij,nj->ni", P, r_tr)
    J_tr = np.einsum("nij,njk->nik", P, J_tr)
    return r_rot, r_tr, J_rot.reshape(-1, 6), J_tr.reshape(-1, 6)


def _skews(v: np.ndarray) -> np.ndarray:
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def solve_handeye(A: list[np.ndarray], B: list[np.ndarray], min_rotation_deg: float = 2.0,
                  min_axis_spread_deg: float = 10.0, joint: bool = True, iterations: int = 4,
                  free=None) -> HandEyeResult:
    """Least-squares ``X`` of ``A_i X = X B_i``.

    The closed form of Park & Martin (1994) finds the rotation from the pairs' rotation vectors
    alone, then the translation with that rotation held.  But the translation equations
    ``R_X t_Bi = t_Ai - (R_Ai - I) t_X`` also carry the rotation (the IMU's displacements turned
    into the lidar's), and they pin it best exactly where the rotation vectors pin it worst: when
    the rotation axes are nearly parallel, the rotation about their common direction.  With
    ``joint`` (default) the closed form seeds a Gauss-Newton fit of rotation and translation
    together to both sets of residuals, each weighted by its own noise variance, which the fit
    estimates from its residuals (re-estimated ``iterations`` times: a variance-component fit,
    Helmert's; rotation residuals in rad against translation residuals in m need their own scales).
    Measured on the same motions (``tests/imu_calib/test_honest_uncertainty.py``, 24 pairs with axes
    ~12 deg apart, 12 seeds): 0.24 deg closed form against 0.10 deg joint with 0.5 mm translation
    noise per pair, 0.21 against 0.18 deg with 2 mm; the same (0.08 deg) with axes spread widely.

    Parameters
    ----------
    A, B : sequences of 4 x 4 transforms, the same length (pairs of poses)
    min_rotation_deg : float > 0 [deg]
        Pairs whose IMU rotation is smaller are dropped (see the module docstring).
    min_axis_spread_deg : float > 0 [deg]
        Below this spread of the rotation axes the motion is degenerate: error.
    free : optional, per pair the (k, 3) translation directions its lidar motion did not measure
        (:attr:`...registration.Registration.free_directions`): its translation equations are used
        only across them (a scene of walls alone leaves the vertical free, and ICP's value along it
        is the seed's, not evidence).
    """
    alpha, beta, used, spread = _rotation_pairs(A, B, min_rotation_deg, min_axis_spread_deg)
    P = _projectors(free, len(A))[used]
    pm = _park_martin(A, B, alpha, beta, used, spread, P)
    if not joint:
        return pm
    n = pm.pairs_used
    RA = np.array([A[i][:3, :3] for i in pm.used])
    tA = np.array([A[i][:3, 3] for i in pm.used])
    tB = np.array([B[i][:3, 3] for i in pm.used])
    X = pm.X.copy()
    n_tr = int(round(np.trace(P, axis1=1, axis2=2).sum()))   # translation rows that carry evidence
    dof_k = max(3 * n - 3, 1)      # per block: its residuals less about 3 parameters
    dof_t = max(n_tr - 3, 1)
    s_rot = max(np.sqrt(np.sum(np.radians(pm.rotation_residual_deg) ** 2) / dof_k), _SIGMA_FLOOR_RAD)
    s_tr = max(np.sqrt(np.sum(pm.translation_residual_m ** 2) / dof_t), _SIGMA_FLOOR_M)
    for _outer in range(iterations):
        for _gn in range(10):
            r_rot, r_tr, J_rot, J_tr = _joint_system(alpha, beta, RA, tA, tB, X, P)
            J = np.vstack([J_rot / s_rot, J_tr / s_tr])
            r = np.concatenate([r_rot.ravel() / s_rot, r_tr.ravel() / s_tr])
            step = -np.linalg.lstsq(J, r, rcond=None)[0]
            X = make_T(so3_exp(step[:3]) @ X[:3, :3], X[:3, 3] + step[3:])
            if np.linalg.norm(step[:3]) < 1e-10 and np.linalg.norm(step[3:]) < 1e-10:
                break
        r_rot, r_tr, J_rot, J_tr = _joint_system(alpha, beta, RA, tA, tB, X, P)
        s_rot = max(np.sqrt(np.sum(r_rot ** 2) / dof_k), _SIGMA_FLOOR_RAD)
        s_tr = max(np.sqrt(np.sum(r_tr ** 2) / dof_t), _SIGMA_FLOOR_M)
    J = np.vstack([J_rot / s_rot, J_tr / s_tr])
    cov = np.linalg.pinv(J.T @ J)
    return HandEyeResult(X, n, pm.axis_spread_deg, np.degrees(np.linalg.norm(r_rot, axis=1)),
                         np.linalg.norm(r_tr, axis=1), pm.used, float(s_rot), float(s_tr), cov, 3 * n + n_tr - 6)


def random_rotation(rng: np.random.Generator, angle_deg: float) -> np.ndarray:
    """A rotation of ``angle_deg`` about a uniformly random axis (test and simulation helper)."""
    axis = rng.normal(size=3)
    return so3_exp(axis / np.linalg.norm(axis) * np.radians(angle_deg))
