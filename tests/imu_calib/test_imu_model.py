"""The simulated IMU's noise statistics (sim/imu.py) and the integration of its samples."""

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.imu_calib.imu_integration import GRAVITY_M_S2, relative_motions
from foveatrack.imu_calib.se3 import inv_T, make_T, rotation_angle_deg, so3_exp
from sim.imu import ImuNoise, PoseSchedule, RigTrajectory, simulate_imu
from sim.scene import scene_from_mapping

BMI088 = ImuNoise()


def _static(duration_s=200.0):
    return RigTrajectory([make_T(so3_exp([0.1, -0.2, 0.3]), [0, 0, 0])], duration_s, 1.0)


def test_white_noise_matches_the_datasheet_density():
    noise = ImuNoise(gyro_bias_walk_deg_s_rts=0.0, accel_bias_walk_ug_rts=0.0)
    s = simulate_imu(_static(), noise, 200.0, np.random.default_rng(1))
    g_std = (s.gyro_rad_s - s.gyro_rad_s.mean(axis=0)).std(axis=0)
    a_std = (s.accel_m_s2 - s.accel_m_s2.mean(axis=0)).std(axis=0)
    # 0.014 deg/s/sqrt(Hz) at 200 Hz: 0.198 deg/s per sample; 175 ug/sqrt(Hz): 24.3 mm/s^2
    assert noise.gyro_sigma_rad_s == pytest.approx(np.radians(0.014) * np.sqrt(200))
    assert np.allclose(g_std, noise.gyro_sigma_rad_s, rtol=0.03)
    assert np.allclose(a_std, noise.accel_sigma_m_s2, rtol=0.03)


def test_bias_random_walk_grows_as_sqrt_time():
    noise = ImuNoise(gyro_bias_walk_deg_s_rts=0.01, accel_bias_walk_ug_rts=500.0)
    tau_s = 5.0
    d_g, d_a = [], []
    for seed in range(40):
        s = simulate_imu(_static(100.0), noise, 100.0, np.random.default_rng(seed), white=False)
        k = int(tau_s * noise.rate_hz)
        d_g.append(s.gyro_rad_s[k::k] - s.gyro_rad_s[:-k:k][: len(s.gyro_rad_s[k::k])])
        d_a.append(s.accel_m_s2[k::k] - s.accel_m_s2[:-k:k][: len(s.accel_m_s2[k::k])])
    var_g = np.var(np.vstack(d_g))
    var_a = np.var(np.vstack(d_a))
    assert var_g == pytest.approx(np.radians(0.01) ** 2 * tau_s, rel=0.1)
    assert var_a == pytest.approx((500e-6 * GRAVITY_M_S2) ** 2 * tau_s, rel=0.1)


def test_at_rest_the_accelerometer_reads_gravity_up_in_its_own_frame():
    noise = ImuNoise(gyro_bias_sigma_deg_s=0, accel_bias_sigma_mg=0, gyro_bias_walk_deg_s_rts=0,
                     accel_bias_walk_ug_rts=0)
    traj = _static(10.0)
    s = simulate_imu(traj, noise, 10.0, np.random.default_rng(2))
    R = traj.poses[0][:3, :3]
    assert np.allclose(s.accel_m_s2.mean(axis=0), R.T @ [0, 0, GRAVITY_M_S2], atol=0.005)
    assert np.allclose(s.gyro_rad_s.mean(axis=0), 0, atol=0.002)


def test_a_seed_gives_the_same_samples_and_another_seed_others():
    a = simulate_imu(_static(5.0), BMI088, 5.0, np.random.default_rng(3))
    b = simulate_imu(_static(5.0), BMI088, 5.0, np.random.default_rng(3))
    c = simulate_imu(_static(5.0), BMI088, 5.0, np.random.default_rng(4))
    assert np.array_equal(a.gyro_rad_s, b.gyro_rad_s) and np.array_equal(a.accel_m_s2, b.accel_m_s2)
    assert not np.array_equal(a.gyro_rad_s, c.gyro_rad_s)


def _poses(rng, n):
    from foveatrack.imu_calib.handeye import random_rotation

    poses = [np.eye(4)]
    for _ in range(n - 1):
        poses.append(poses[-1] @ make_T(random_rotation(rng, 10.0), rng.normal(0, 0.06, 3)))
    return poses


def test_integration_recovers_the_moves_with_biases_estimated_at_rest():
    rng = np.random.default_rng(5)
    poses = _poses(rng, 8)
    sched = PoseSchedule(count=8, dwell_s=5.0, move_s=1.0)
    traj = RigTrajectory(poses, sched.dwell_s, sched.move_s)
    # large constant biases, no white noise: what the static windows must remove
    noise = ImuNoise(gyro_noise_density_deg_s_rthz=0, accel_noise_density_ug_rthz=0, gyro_bias_walk_deg_s_rts=0,
                     accel_bias_walk_ug_rts=0, gyro_bias_sigma_deg_s=1.0, accel_bias_sigma_mg=20.0)
    s = simulate_imu(traj, noise, sched.duration_s, rng)
    m = relative_motions(s, sched.windows())
    assert m.gravity_m_s2 == pytest.approx(GRAVITY_M_S2, abs=1e-3)
    for a, b, B in zip(poses, poses[1:], m.B):
        truth = inv_T(a) @ b
        assert rotation_angle_deg(B[:3, :3].T @ truth[:3, :3]) < 2e-3
        assert np.linalg.norm(B[:3, 3] - truth[:3, 3]) < 5e-4
    # with the biases left in (no static estimate) the moves would be far off: the test can fail
    from foveatrack.imu_calib.imu_integration import integrate_rotation

    sl = (s.t_s >= 5.0) & (s.t_s <= 6.0)
    R_raw = integrate_rotation(s.t_s[sl], s.gyro_rad_s[sl])[-1]
    assert rotation_angle_deg(R_raw.T @ (inv_T(poses[0]) @ poses[1])[:3, :3]) > 0.3


def test_scene_imu_tables_are_validated():
    base = {"background": [{"type": "ground", "height_m": 1.0}]}
    with pytest.raises(UserError, match=r"\[imu\].*unknown key|\[imu\].*gyro_noise"):
        scene_from_mapping({**base, "imu": {"gyro_noise": 1.0}}, "s.toml")
    with pytest.raises(UserError, match=r"\[imu_poses\] needs an \[imu\]"):
        scene_from_mapping({**base, "imu_poses": {"count": 5}}, "s.toml")
    with pytest.raises(UserError, match="count must be an integer in"):
        scene_from_mapping({**base, "imu": {}, "imu_poses": {"count": 2}}, "s.toml")
    with pytest.raises(UserError, match="translation_m"):
        scene_from_mapping({**base, "imu": {"translation_m": [5, 0, 0]}}, "s.toml")
    sc = scene_from_mapping({**base, "imu": {"rotation_deg": [0, 0, 90]}}, "s.toml")
    assert np.allclose(sc.imu.T_lidar_imu[:3, :3] @ [1, 0, 0], [0, 1, 0])
    assert scene_from_mapping(base, "s.toml").imu is None     # no [imu]: nothing simulated
