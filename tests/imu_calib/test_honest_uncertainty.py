"""The lidar-IMU extrinsic never comes with a 1-sigma smaller than its evidence allows (issue 27).

The three cases measured on 802524f: 3 poses (the bootstrap's 1-sigma exactly 0 while X was 0.28 deg /
0.85 cm off), rotation axes 12 deg apart (0.58 deg / 2.5 cm off, no warning), and one pose pair whose
registration slid 87 cm (a 90 deg yaw mount; X 38 cm off, no warning).  In each, what is written either
has a 1-sigma that covers the true error (within 3 sigma of the total) or has none, and a warning says
what is wrong.  Motions: the issue's ground truth (7 deg about a skew axis, 18 cm), 10 deg / 10 cm steps
with the per-pair noise of the simulated room (registration ~0.03 deg and 2 mm, the IMU half that).
"""

import json
import re

import numpy as np
import pytest

from foveatrack.cli import main
from foveatrack.imu_calib import procedure
from foveatrack.imu_calib.handeye import random_rotation, solve_handeye
from foveatrack.imu_calib.se3 import inv_T, make_T, rotation_angle_deg, se3_exp, so3_exp

ROOM = "scenes/imu-calibration-room.toml"


def _truth(yaw_deg: float = 0.0) -> np.ndarray:
    axis = np.array([1.0, 2.0, -1.5]) / np.linalg.norm([1.0, 2.0, -1.5])
    R = so3_exp([0, 0, np.radians(yaw_deg)]) @ so3_exp(axis * np.radians(7.0))
    return make_T(R, [0.12, -0.10, 0.08])


def _motions(rng, X, n, cone_deg=None, rot_noise_deg=0.03, tr_noise_m=0.002):
    """n pairs (A, B) with A X = X B up to noise; axes random, or within ``cone_deg`` of z."""
    A, B = [], []
    for _ in range(n):
        if cone_deg is None:
            R = random_rotation(rng, 10.0)
        else:
            phi = rng.uniform(0, 2 * np.pi)
            c = np.tan(np.radians(cone_deg))
            axis = np.array([c * np.cos(phi), c * np.sin(phi), 1.0])
            R = so3_exp(axis / np.linalg.norm(axis) * np.radians(10.0) * rng.choice([-1, 1]))
        d = rng.normal(size=3)
        a = make_T(R, d / np.linalg.norm(d) * 0.10)
        b = inv_T(X) @ a @ X
        noise_a = se3_exp(np.concatenate([rng.normal(0, tr_noise_m, 3), rng.normal(0, np.radians(rot_noise_deg), 3)]))
        noise_b = se3_exp(np.concatenate([rng.normal(0, tr_noise_m / 2, 3),
                                          rng.normal(0, np.radians(rot_noise_deg) / 2, 3)]))
        A.append(a @ noise_a)
        B.append(b @ noise_b)
    return A, B


def _errors(X_est, X):
    return rotation_angle_deg(X_est[:3, :3] @ X[:3, :3].T), float(np.linalg.norm(X_est[:3, 3] - X[:3, 3]))


def _covered(unc, err_deg, err_m, k=3.0) -> bool:
    return err_deg <= k * unc.rotation_rss_deg and err_m <= k * unc.translation_rss_m


@pytest.mark.parametrize("seed", range(6))
def test_two_pairs_get_no_sigma_and_a_warning(seed):
    X = _truth()
    A, B = _motions(np.random.default_rng(seed), X, 2)
    he, unc, removed, warnings = procedure.solve_pairs(A, B, bootstrap_samples=50)
    assert he.pairs_used == 2 and not removed
    assert not unc.given and np.all(np.isnan(unc.rotation_sigma_deg)) and np.all(np.isnan(unc.translation_sigma_m))
    assert any("only 2 pose pairs" in w and "no 1-sigma" in w for w in warnings), warnings
    assert any("cannot be checked against each other" in w for w in warnings), warnings


@pytest.mark.parametrize("seed", range(6))
def test_axes_12_deg_apart_warn_and_the_sigma_covers_the_error(seed):
    X = _truth()
    A, B = _motions(np.random.default_rng(100 + seed), X, 24, cone_deg=8.5)
    he, unc, removed, warnings = procedure.solve_pairs(A, B, bootstrap_samples=50)
    assert 10.0 < he.axis_spread_deg < 16.0, he.axis_spread_deg
    assert any("rotation axes spread only" in w for w in warnings), warnings
    err_deg, err_m = _errors(he.X, X)
    assert unc.given and _covered(unc, err_deg, err_m), (err_deg, err_m, unc)


def test_the_joint_fit_beats_the_closed_form_where_the_axes_are_close():
    # Mean over seeds, the same motions for both: the translations carry the rotation about the
    # axes' common direction, which the rotation vectors alone barely fix.
    X = _truth()
    pm, joint = [], []
    for seed in range(12):
        A, B = _motions(np.random.default_rng(200 + seed), X, 24, cone_deg=8.5, tr_noise_m=0.0005)
        pm.append(_errors(solve_handeye(A, B, joint=False).X, X)[0])
        joint.append(_errors(solve_handeye(A, B).X, X)[0])
    print(f"axes ~12 deg apart, 24 pairs: closed form {np.mean(pm):.3f} deg, joint {np.mean(joint):.3f} deg")
    assert np.mean(joint) < 0.7 * np.mean(pm)


@pytest.mark.parametrize("seed", range(4))
def test_a_slipped_pair_is_removed_and_named(seed):
    # A 90 deg yaw mount; pair 8's registration slid 87 cm along a wall (x), and turned 0.1 deg.
    X = _truth(yaw_deg=90.0)
    A, B = _motions(np.random.default_rng(300 + seed), X, 24)
    A[7] = make_T(A[7][:3, :3] @ so3_exp([0, 0, np.radians(0.1)]), A[7][:3, 3] + [0.87, 0.0, 0.0])
    he, unc, removed, warnings = procedure.solve_pairs(A, B, bootstrap_samples=50)
    assert [r.index for r in removed] == [7]
    assert 7 not in he.used and he.pairs_used == 23
    assert any("pose pair 8 (poses 8-9) removed" in w and re.search(r"\b8[67]\.\d cm", w) for w in warnings), warnings
    err_deg, err_m = _errors(he.X, X)
    assert err_deg < 0.2 and err_m < 0.01, (err_deg, err_m)
    assert unc.given and _covered(unc, err_deg, err_m), (err_deg, err_m, unc)


@pytest.mark.parametrize("seed", range(4))
def test_a_translation_the_lidar_did_not_measure_is_not_used_and_not_blamed(seed):
    # Pair 8's registration saw walls only: the vertical was free and its translation there is the
    # seed's, here 50 cm off (the registration names the direction, Registration.free_directions).
    # The pair's rotation and its horizontal translation still count; its vertical does not, so it
    # is neither removed as slid nor pulls X.
    X = _truth()
    A, B = _motions(np.random.default_rng(500 + seed), X, 24)
    A[7] = make_T(A[7][:3, :3], A[7][:3, 3] + [0.0, 0.0, 0.50])
    free = [np.zeros((0, 3))] * 24
    free[7] = np.array([[0.0, 0.0, 1.0]])
    he, unc, removed, warnings = procedure.solve_pairs(A, B, bootstrap_samples=50, free=free)
    assert not removed and not warnings and he.pairs_used == 24
    assert he.dof == 6 * 24 - 1 - 6
    err_deg, err_m = _errors(he.X, X)
    assert err_deg < 0.2 and err_m < 0.01, (err_deg, err_m)
    assert unc.given and _covered(unc, err_deg, err_m), (err_deg, err_m, unc)
    # the same pairs with the vertical taken as measured: the pair is blamed and removed
    assert [r.index for r in procedure.solve_pairs(A, B, bootstrap_samples=0)[2]] == [7]


@pytest.mark.parametrize("seed", range(4))
def test_good_pairs_are_all_kept_and_the_sigma_covers_the_error(seed):
    X = _truth()
    A, B = _motions(np.random.default_rng(400 + seed), X, 24)
    he, unc, removed, warnings = procedure.solve_pairs(A, B, bootstrap_samples=50)
    assert not removed and not warnings and he.pairs_used == 24
    err_deg, err_m = _errors(he.X, X)
    assert _covered(unc, err_deg, err_m), (err_deg, err_m, unc)
    # and not uselessly wide: the error is not far below a tenth of it
    assert unc.rotation_rss_deg < 10 * max(err_deg, 0.01) and unc.translation_rss_m < 10 * max(err_m, 0.001)


@pytest.mark.slow
def test_cli_with_3_poses_writes_no_sigma_and_warns(tmp_path, capsys):
    scene = tmp_path / "three.toml"
    scene.write_text(open(ROOM).read().replace("count = 25", "count = 3").replace("dwell_s = 10.0", "dwell_s = 1.0"))
    out = tmp_path / "x.json"
    assert main(["calibrate-imu", str(scene), "--accumulate", "1", "--out", str(out), "--no-progress",
                 "--bootstrap", "50"]) == 0
    captured = capsys.readouterr()
    x = json.loads(out.read_text())
    assert x["pairs"] == 2
    # none given (on 802524f: 0.0 per axis, with the answer 0.28 deg / 0.85 cm off)
    assert all(s is None for s in x["sigma_rotation_deg"] + x["sigma_translation_m"]), x
    assert x["sigma_rotation_total_deg"] is None and x["sigma_translation_total_m"] is None
    assert any("only 2 pose pairs" in w for w in x["warnings"])
    assert "warning: mid40, 1 s: only 2 pose pairs" in captured.err, captured.err
    assert "none" in captured.out     # the table's 1-sigma column says so
