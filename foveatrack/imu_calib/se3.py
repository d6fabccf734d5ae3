"""Rigid transforms as 4 x 4 homogeneous matrices; Exp and Log on SO(3) and SE(3).

Conventions: ``T_a_b`` maps points of frame b into frame a (``p_a = R p_b + t``).  The SE(3) Log
is the 6-vector ``(rho [m], omega [rad])`` with ``omega`` the rotation vector and
``t = V(omega) rho`` (Murray, Li & Sastry 1994, *A Mathematical Introduction to Robotic
Manipulation*, Sec. 2.3; Barfoot 2017, *State Estimation for Robotics*, eq. 7.83-7.95) — the Log
the paper's eq. (8) refers to (its ref. [37]).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def make_T(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=float)
    return T


def inv_T(T: np.ndarray) -> np.ndarray:
    R = T[:3, :3]
    return make_T(R.T, -R.T @ T[:3, 3])


def so3_exp(omega) -> np.ndarray:
    return Rotation.from_rotvec(np.asarray(omega, dtype=float)).as_matrix()


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] of ``R`` (angle in [0, pi])."""
    return Rotation.from_matrix(R).as_rotvec()


def skew(v) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _V(omega: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3): ``t = V rho`` (Barfoot eq. 7.87)."""
    theta = float(np.linalg.norm(omega))
    W = skew(omega)
    if theta < 1e-8:
        return np.eye(3) + 0.5 * W + W @ W / 6.0
    return (np.eye(3) + (1 - np.cos(theta)) / theta**2 * W
            + (theta - np.sin(theta)) / theta**3 * W @ W)


def se3_exp(xi) -> np.ndarray:
    """``xi = (rho [m], omega [rad])`` to a 4 x 4 transform."""
    xi = np.asarray(xi, dtype=float)
    return make_T(so3_exp(xi[3:]), _V(xi[3:]) @ xi[:3])


def se3_log(T: np.ndarray) -> np.ndarray:
    """The 6-vector ``(rho [m], omega [rad])`` with ``se3_exp(se3_log(T)) == T``."""
    omega = so3_log(T[:3, :3])
    rho = np.linalg.solve(_V(omega), T[:3, 3])
    return np.concatenate([rho, omega])


def eq8_error(A: np.ndarray, B: np.ndarray, X: np.ndarray) -> float:
    """The paper's calibration error, eq. (8): ``|| Log(A) - Log(X B X^-1) ||``.

    ``A``: the lidar's true relative transform between two poses; ``B``: the IMU's (integrated);
    ``X``: the calibrated extrinsic ``T_lidar_imu`` (``A X = X B``).  The norm mixes metres and
    radians as the paper's does; :func:`eq8_parts` splits it.
    """
    return float(np.linalg.norm(se3_log(A) - se3_log(X @ B @ inv_T(X))))


def eq8_parts(A: np.ndarray, B: np.ndarray, X: np.ndarray) -> tuple[float, float]:
    """Translation [m] and rotation [rad] parts of the eq. (8) difference."""
    d = se3_log(A) - se3_log(X @ B @ inv_T(X))
    return float(np.linalg.norm(d[:3])), float(np.linalg.norm(d[3:]))


def rotation_angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(so3_log(R))))


def transform_points(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]
