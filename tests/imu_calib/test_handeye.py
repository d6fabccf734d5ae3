"""Hand-eye solver (Park & Martin 1994) and the SE(3) maps, on synthetic motions with known answers."""

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.imu_calib.handeye import DegenerateMotion, random_rotation, solve_handeye
from foveatrack.imu_calib.uncertainty import bootstrap_sigma
from foveatrack.imu_calib.se3 import eq8_error, inv_T, make_T, rotation_angle_deg, se3_exp, se3_log, so3_exp


def _X(rng):
    return make_T(random_rotation(rng, 25.0), rng.normal(0, 0.1, 3))


def _motions(rng, X, n=10, angle_deg=10.0, axis=None):
    A, B = [], []
    for _ in range(n):
        R = random_rotation(rng, angle_deg) if axis is None else so3_exp(np.asarray(axis) * np.radians(angle_deg) * rng.choice([-1, 1]))
        a = make_T(R, rng.normal(0, 0.1, 3))
        A.append(a)
        B.append(inv_T(X) @ a @ X)        # A X = X B
    return A, B


def test_se3_exp_log_are_inverse():
    rng = np.random.default_rng(1)
    for _ in range(50):
        xi = np.concatenate([rng.normal(0, 1, 3), rng.normal(0, 1, 3) * rng.uniform(0, 1)])
        assert np.allclose(se3_log(se3_exp(xi)), xi, atol=1e-9)
    T = make_T(random_rotation(rng, 40), [1, 2, 3])
    assert np.allclose(se3_exp(se3_log(T)), T, atol=1e-12)
    assert np.allclose(se3_log(np.eye(4)), 0)


def test_exact_motions_give_x_exactly_and_eq8_zero():
    rng = np.random.default_rng(2)
    X = _X(rng)
    A, B = _motions(rng, X)
    res = solve_handeye(A, B)
    assert np.allclose(res.X, X, atol=1e-9)
    assert max(eq8_error(a, b, res.X) for a, b in zip(A, B)) < 1e-9
    # eq. (8) sees a wrong extrinsic
    Xw = X @ make_T(so3_exp([0, 0, np.radians(1.0)]), [0.01, 0, 0])
    assert np.mean([eq8_error(a, b, Xw) for a, b in zip(A, B)]) > 1e-3


def test_two_distinct_axes_suffice():
    rng = np.random.default_rng(3)
    X = _X(rng)
    A1, B1 = _motions(rng, X, 3, axis=[1, 0, 0])
    A2, B2 = _motions(rng, X, 3, axis=[0, 1, 0])
    res = solve_handeye(A1 + A2, B1 + B2)
    assert np.allclose(res.X, X, atol=1e-8)
    assert res.axis_spread_deg == pytest.approx(90.0, abs=1e-6)


def test_noise_is_averaged_and_bootstrap_sigma_covers_the_error():
    rng = np.random.default_rng(4)
    X = _X(rng)
    A, B = _motions(rng, X, 30)
    Bn = [b @ se3_exp(np.concatenate([rng.normal(0, 0.002, 3), rng.normal(0, np.radians(0.05), 3)])) for b in B]
    res = solve_handeye(A, Bn)
    err_deg = rotation_angle_deg(res.X[:3, :3] @ X[:3, :3].T)
    err_m = np.linalg.norm(res.X[:3, 3] - X[:3, 3])
    # Rotation: each pair's axis is off by ~(0.087 deg / 10 deg) rad = 0.5 deg; 30 pairs -> ~0.1 deg.
    assert err_deg < 0.25 and err_m < 0.02
    rot_sigma, tr_sigma, samples = bootstrap_sigma(A, Bn, res.X, samples=200, seed=0)
    assert samples >= 190
    # the bootstrap 1-sigma describes the actual error: within 3 sigma, and not 10x too wide
    s_rot, s_tr = np.linalg.norm(rot_sigma), np.linalg.norm(tr_sigma)
    assert err_deg < 3 * s_rot and err_m < 3 * s_tr
    assert s_rot < 10 * max(err_deg, 0.02) and s_tr < 10 * max(err_m, 0.002)


def test_rotations_about_one_axis_are_refused():
    rng = np.random.default_rng(5)
    X = _X(rng)
    A, B = _motions(rng, X, 8, axis=[0, 0, 1])   # every motion about one axis (turns of a pan head)
    with pytest.raises(DegenerateMotion, match="one axis"):
        solve_handeye(A, B)
    assert issubclass(DegenerateMotion, UserError)


def test_too_small_rotations_are_refused():
    rng = np.random.default_rng(6)
    X = _X(rng)
    A, B = _motions(rng, X, 8, angle_deg=0.5)
    with pytest.raises(DegenerateMotion, match="rotate by at least"):
        solve_handeye(A, B)
    # but small ones among good ones are only dropped
    A2, B2 = _motions(rng, X, 6)
    res = solve_handeye(A + A2, B + B2)
    assert res.pairs_used == 6
    assert np.allclose(res.X, X, atol=1e-8)
