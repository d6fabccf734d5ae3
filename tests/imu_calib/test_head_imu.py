"""The IMU on the served head (sim/head_imu.py) against the head's own motion, and the live plan's
checks (foveatrack/imu_calib/live.py) that need no devices."""

import numpy as np
import pytest

from foveatrack.imu_calib.handeye import DegenerateMotion, solve_handeye
from foveatrack.imu_calib.imu_integration import ImuSamples, relative_motions
from foveatrack.imu_calib.live import RigPlan, static_spread_deg_s, translation_observability
from foveatrack.imu_calib.se3 import inv_T, make_T, rotation_angle_deg, so3_log
from sim.head_imu import HeadImu, head_rotations
from sim.imu import ImuNoise, ImuSpec

QUIET = ImuNoise(gyro_noise_density_deg_s_rthz=0.0, gyro_bias_sigma_deg_s=0.0, gyro_bias_walk_deg_s_rts=0.0,
                 accel_noise_density_ug_rthz=0.0, accel_bias_sigma_mg=0.0, accel_bias_walk_ug_rts=0.0)
X_TRUE = ImuSpec(rotation_deg=(1.5, -2.0, 3.0), translation_m=(-0.05, 0.03, -0.04)).T_lidar_imu


def _trapezoid(delta_deg, v_deg_s, a_deg_s2, t):
    """Angle covered at times ``t`` (from 0) by a rest-to-rest move of ``delta_deg`` (exact)."""
    d = abs(delta_deg)
    if d == 0:
        return np.zeros_like(t)
    t_acc = min(v_deg_s / a_deg_s2, np.sqrt(d / a_deg_s2))
    v = a_deg_s2 * t_acc
    t_flat = (d - a_deg_s2 * t_acc**2) / v
    T = 2 * t_acc + t_flat
    tc = np.clip(t, 0, T)
    up = 0.5 * a_deg_s2 * np.minimum(tc, t_acc) ** 2
    flat = v * np.clip(tc - t_acc, 0, t_flat)
    td = np.clip(tc - t_acc - t_flat, 0, t_acc)
    down = v * td - 0.5 * a_deg_s2 * td**2
    return np.sign(delta_deg) * (up + flat + down)


class HeadPath:
    """A head stepped through a plan: dwell, move (pan and tilt together, trapezoids), dwell, ..."""

    def __init__(self, plan: RigPlan, pan0=31.0, tilt0=-12.0, dwell_s=2.0, move_s=2.0):
        self.off = np.array(plan.offsets_deg()) + [pan0, tilt0]
        self.dwell_s, self.move_s = dwell_s, move_s

    def windows(self):
        per = self.dwell_s + self.move_s
        return [(i * per, i * per + self.dwell_s) for i in range(len(self.off))]

    def __call__(self, t_s):
        t = np.asarray(t_s, float)
        per = self.dwell_s + self.move_s
        i = np.clip(np.floor(t / per).astype(int), 0, len(self.off) - 1)
        tau = t - i * per - self.dwell_s
        pan, tilt = self.off[i, 0].copy(), self.off[i, 1].copy()
        for k in np.unique(i):
            m = (i == k) & (tau > 0)
            d = self.off[min(k + 1, len(self.off) - 1)] - self.off[k]
            pan[m] += _trapezoid(d[0], 30.0, 60.0, tau[m])
            tilt[m] += _trapezoid(d[1], 15.0, 40.0, tau[m])
        return pan, tilt

    def A_true(self):
        Rw = head_rotations(self.off[:, 0], self.off[:, 1])
        return [make_T(a.T @ b, np.zeros(3)) for a, b in zip(Rw, Rw[1:])]


def _imu(path, noise, seed=0):
    t_end = path.windows()[-1][1]
    t = np.arange(0, t_end + 1e-9, 1 / 200.0)
    gyro, acc_g = HeadImu(path, X_TRUE, noise, np.random.default_rng(seed))(np.round(t * 1e9).astype(np.int64))
    return ImuSamples(t, gyro, acc_g * 9.80665)


def test_head_rotation_is_the_ray_casters():
    from sim.world.kernels import rotate_pan_tilt_kernel

    rng = np.random.default_rng(0)
    d = rng.normal(size=(20, 3))
    pan, tilt = rng.uniform(-180, 180, 20), rng.uniform(-30, 60, 20)
    out = np.empty_like(d)
    rotate_pan_tilt_kernel(d, np.radians(pan), np.radians(tilt), out)
    assert np.allclose(np.einsum("nij,nj->ni", head_rotations(pan, tilt), d), out, atol=1e-12)


def test_noise_free_head_imu_integrates_to_the_heads_motion():
    # The served IMU's gyro and accelerometer, integrated by the calibration's own code, give the
    # motion the head made (rotation and the IMU's arc about the head's centre): B = X^-1 A X.
    path = HeadPath(RigPlan(poses=7))
    motion = relative_motions(_imu(path, QUIET), path.windows())
    assert motion.gravity_m_s2 == pytest.approx(9.80665, abs=1e-4)
    for a, b in zip(path.A_true(), motion.B):
        b_true = inv_T(X_TRUE) @ a @ X_TRUE
        assert rotation_angle_deg(b[:3, :3].T @ b_true[:3, :3]) < 5e-4   # the midpoint rule over ramps
        assert np.linalg.norm(b[:3, 3] - b_true[:3, 3]) < 5e-5       # 0.05 mm of a 1-2 cm arc
    # and the hand-eye solve of the true A with these B is the mount: every component observable
    res = solve_handeye(path.A_true(), motion.B)
    assert rotation_angle_deg(res.X[:3, :3].T @ X_TRUE[:3, :3]) < 1e-3
    assert np.linalg.norm(res.X[:3, 3] - X_TRUE[:3, 3]) < 2e-4


def test_pan_only_motion_is_refused_not_solved():
    # A head panning only turns the rig about one axis: the translation along it is unobservable.
    with pytest.raises(DegenerateMotion, match="pan axis only"):
        RigPlan(poses=7, tilt_step_deg=0.0).check_axes()
    path = HeadPath(RigPlan(poses=7, tilt_step_deg=0.0))
    motion = relative_motions(_imu(path, QUIET), path.windows())
    A = path.A_true()
    with pytest.raises(DegenerateMotion, match="one axis"):
        solve_handeye(A, motion.B)
    s, weak = translation_observability(A)
    pan_axis_in_lidar = head_rotations([31.0], [-12.0])[0].T @ [0.0, 0.0, 1.0]   # world z, seen from the lidar
    assert s[-1] < 1e-9 and abs(weak @ pan_axis_in_lidar) > 0.999   # along the pan axis nothing is pinned
    s2, _ = translation_observability(HeadPath(RigPlan(poses=7)).A_true())
    assert s2[-1] > 0.05                              # with tilt steps every direction is pinned


def test_static_spread_sees_a_rig_that_moves():
    rng = np.random.default_rng(3)
    t = np.arange(0, 2, 1 / 200)
    still = rng.normal(0, np.radians(0.2), (len(t), 3))
    assert static_spread_deg_s(t, still, 0, 2) < 0.1
    drifting = still.copy()
    drifting[t > 1.5, 2] += np.radians(1.0)          # turning at 1 deg/s for the last half second
    assert static_spread_deg_s(t, drifting, 0, 2) > 0.3


def test_what_the_imu_allows_on_the_head_plan():
    # The IMU's share of the error on the e2e test's plan (9 poses, 2 s dwell, 10 deg steps, 1.5 s
    # from one window to the next): the true lidar motions with the noisy IMU's, BMI088 noise
    # (sim.imu defaults), 10 seeds.  Measured (20 seeds): rotation 0.068 deg mean (95th percentile
    # 0.101), translation 0.40 cm (0.65 cm).  The rotation is the gyro's white noise over the moves
    # (without any bias it is the same); the translation grows with the time between windows (2.3 s:
    # 3.7 mm per pair against 1.7 mm at 1.5 s), which is why the live path starts each move as soon
    # as the window's points are in.
    path = HeadPath(RigPlan(poses=9), move_s=1.5)
    rot, tr = [], []
    for seed in range(10):
        motion = relative_motions(_imu(path, ImuNoise(), seed), path.windows())
        X = solve_handeye(path.A_true(), motion.B).X
        rot.append(np.degrees(np.linalg.norm(so3_log(X[:3, :3] @ X_TRUE[:3, :3].T))))
        tr.append(np.linalg.norm(X[:3, 3] - X_TRUE[:3, 3]))
    print(f"IMU-only floor over 10 seeds: rotation {np.mean(rot):.4f} deg (max {max(rot):.4f}), "
          f"translation {np.mean(tr) * 100:.3f} cm (max {max(tr) * 100:.3f})")
    assert np.mean(rot) < 0.09 and np.mean(tr) < 0.0055
    assert min(rot) > 0.005 and min(tr) > 5e-4    # the noise is there: not a noise-free route by mistake


def test_the_closed_loops_gyro_and_the_served_imus_agree_on_one_head_motion():
    # sim/head_imu.py has two routes to the same kinematics: HeadGyro (the closed loop) from the head
    # model's exact rates, HeadImu (lidar serve) by differences of the pose.  On one motion of the head
    # model, noise off, they must give the same gyro: to the finite difference's error where the
    # acceleration switches (its rate over [t - h/2, t + h/2] against the rate at t), exactly elsewhere.
    from gimbal.pelco import encode_pan_tilt
    from gimbal.pts303h import PTS303H
    from sim.head_imu import HeadGyro, head_imu_truth

    spec = ImuSpec(rotation_deg=(1.5, -2.0, 3.0), noise=QUIET, rest_before_s=0.0)
    head = PTS303H(unit_seed=3, pan0_deg=20.0, tilt0_deg=5.0)
    head.receive(encode_pan_tilt(1, +1, 0x28, +1, 0x3F), [0.2] * 7)           # pan left, tilt up
    head.receive(encode_pan_tilt(1, -1, 0x10, -1, 0x20), [1.5] * 7)           # reverse both
    gyro = HeadGyro(spec, seed=0, tilt0_deg=5.0, white=False, bias=False)
    h = 1.0 / spec.noise.rate_hz

    def pose(ts):
        return head.angles_at(ts, wrap_pan=False)

    loop, served = [], []
    for k in range(30):           # frame by frame, as the loop asks (the head keeps a few seconds of history)
        t, w = gyro.samples_until(head, 0.1 * (k + 1))
        keep = t >= h             # the difference looks h back; the model's history starts at 0
        loop.append(w[keep])
        served.append(head_imu_truth(pose, spec.T_lidar_imu, t[keep], h)[0])
    w_loop, w_served = np.concatenate(loop), np.concatenate(served)
    diff = np.linalg.norm(w_served - w_loop, axis=1)
    accel_rad_s2 = np.radians(max(head.params.pan_accel_deg_s2, head.params.tilt_accel_deg_s2))
    assert np.abs(w_loop).max() > np.radians(5.0)                                # the head did move
    assert diff.max() <= 0.5 * accel_rad_s2 * h + 1e-9, np.degrees(diff.max())
    assert np.median(diff) < 1e-6     # and in between to the difference's O(h^2) (measured 5e-8 rad/s)
