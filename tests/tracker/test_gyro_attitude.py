"""The gyro attitude source (foveatrack.gyro_attitude): strapdown integration against known rotations,
the bias from rest, rest from the commands (and refuted by the gyro), the config key."""

import math

import numpy as np
import pytest

from foveatrack.control import STOP, HeadCommand
from foveatrack.errors import UserError
from foveatrack.gyro_attitude import GyroAttitude, euler_xyz_matrix, quat_from_matrix, quat_matrix
from foveatrack.reconstruction import Reconstructor, rotation_matrix
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import Tracker, TrackerConfig
from sim.head_imu import lidar_body_rate_rad_s

RATE_HZ = 200.0
DENSITY_DEG = 0.014   # BMI088 [deg/s/sqrt(Hz)]


def _source(pan0=0.0, tilt0=0.0, moving=True, **kw) -> GyroAttitude:
    rec = Reconstructor(SpeedTable.nominal(), pan0_deg=pan0, tilt0_deg=tilt0, tilt_limits_deg=(-90.0, 90.0),
                        accel_deg_s2=40.0)
    g = GyroAttitude(rec, **kw)
    if moving:   # the commands say the head moves from t = 0 (no rest: no bias update, no hold)
        g.on_command(0.0, HeadCommand(1, 20, 0, 0))
    return g


def _errors(g, t, pan, tilt):
    est = np.array([g.angles_at(x)[:2] for x in t])
    return (est[:, 0] - pan + 180.0) % 360.0 - 180.0, est[:, 1] - tilt


def test_body_rate_is_the_rotation_derivative():
    # omega_body = vee(R^T dR/dt) with R = R_z(pan) R_y(-tilt), by central differences
    h = 1e-6
    for pan, pr, tilt, tr in [(10.0, 30.0, 20.0, -7.0), (-170.0, -5.0, 75.0, 12.0), (0.0, 0.0, -30.0, 3.0)]:
        R = rotation_matrix(pan, tilt)
        dR = (rotation_matrix(pan + pr * h, tilt + tr * h) - rotation_matrix(pan - pr * h, tilt - tr * h)) / (2 * h)
        W = R.T @ dR
        assert np.allclose(W, -W.T, atol=1e-8)
        want = np.array([W[2, 1], W[0, 2], W[1, 0]])
        assert np.allclose(lidar_body_rate_rad_s(pr, tilt, tr), want, atol=1e-8)


def test_constant_rate_about_a_fixed_axis_is_exact():
    # pan at 25 deg/s at a fixed tilt: a constant body rate, 20 s, across the +-180 wrap
    t = np.arange(0, int(20 * RATE_HZ) + 1) / RATE_HZ
    pan, tilt = 150.0 + 25.0 * t, np.full_like(t, 20.0)
    g = _source(150.0, 20.0, history_s=60.0)
    g.on_imu(t, lidar_body_rate_rad_s(np.full_like(t, 25.0), tilt, np.zeros_like(t)))
    dp, dt = _errors(g, t, pan, tilt)
    assert np.abs(dp).max() < 1e-9 and np.abs(dt).max() < 1e-9


def _pan_tilt_run(rate_hz):
    t = np.arange(0, int(10 * rate_hz) + 1) / rate_hz
    pan, tilt = 30.0 * t, -40.0 + 10.0 * t
    g = _source(0.0, -40.0)
    g.on_imu(t, lidar_body_rate_rad_s(np.full_like(t, 30.0), tilt, np.full_like(t, 10.0)))
    dp, dt = _errors(g, t, pan, tilt)
    return max(np.abs(dp).max(), np.abs(dt).max())


def test_pan_and_tilt_together_within_the_truncation_bound():
    # the body rate turns with tilt (pan about the world vertical): third-order error per step,
    # second order over the run: halving the rate quadruples the error
    e200, e100 = _pan_tilt_run(200.0), _pan_tilt_run(100.0)
    assert e200 < 1e-4   # measured 1.9e-5 deg after 10 s (from -40 to +60 tilt, 300 deg of pan)
    assert 3.0 < e100 / e200 < 5.0


def test_imu_mount_rotation_is_undone():
    # the IMU turned in the lidar frame: its rates are R^T w; the source rotates them back
    rpy = (5.0, -20.0, 90.0)
    R_li = euler_xyz_matrix(rpy)
    from scipy.spatial.transform import Rotation   # the convention of sim/imu.py and calibrate-imu
    assert np.allclose(R_li, Rotation.from_euler("xyz", rpy, degrees=True).as_matrix(), atol=1e-15)
    assert np.allclose(R_li, quat_matrix(quat_from_matrix(R_li)), atol=1e-15)
    t = np.arange(0, 1001) / RATE_HZ
    tilt = 10.0 * t
    w_lidar = lidar_body_rate_rad_s(np.full_like(t, -20.0), tilt, np.full_like(t, 10.0))
    g = _source(0.0, 0.0, imu_rotation_deg=rpy)
    g.on_imu(t, w_lidar @ R_li)      # (R_li^T w)^T row-wise
    dp, dt = _errors(g, t, -20.0 * t, tilt)
    assert np.abs(dp).max() < 1e-4 and np.abs(dt).max() < 1e-4


def _noisy_run(seed, rest_s=5.0, move_s=10.0, bias_deg_s=(0.3, -0.5, 0.8)):
    rng = np.random.default_rng(seed)
    n_rest, n_move = int(rest_s * RATE_HZ), int(move_s * RATE_HZ) + 1
    t_rest = (np.arange(n_rest) - n_rest) / RATE_HZ
    t_move = np.arange(n_move) / RATE_HZ
    pan, tilt = 12.0 * t_move, 5.0 + 3.0 * t_move
    w = np.vstack([np.zeros((n_rest, 3)),
                   lidar_body_rate_rad_s(np.full(n_move, 12.0), tilt, np.full(n_move, 3.0))])
    sigma_sample = math.radians(DENSITY_DEG) * math.sqrt(RATE_HZ)
    meas = w + np.radians(bias_deg_s) + rng.normal(0, sigma_sample, w.shape)
    rec = Reconstructor(SpeedTable.nominal(), tilt0_deg=5.0, accel_deg_s2=40.0)
    g = GyroAttitude(rec, noise_density_deg_s_rthz=DENSITY_DEG, bias_walk_deg_s_rts=0.0)
    g.on_imu(t_rest, meas[:n_rest])              # at rest before the first command
    g.on_command(0.0, HeadCommand(1, 20, 1, 20))
    g.on_imu(t_move, meas[n_rest:])
    dp, dt = _errors(g, t_move[-1:], pan[-1:], tilt[-1:])
    return float(dp[0]), float(dt[0]), g.angles_at(t_move[-1])[2], g


@pytest.mark.slow
def test_with_noise_and_bias_within_the_stated_sigma():
    # 5 s at rest (bias estimate sigma 0.014/sqrt(5) = 0.0063 deg/s per axis), then 10 s moving:
    # the final error is the bias error x 10 s (0.063 deg) plus the angle random walk
    # 0.014 sqrt(10) = 0.044 deg: 1 sigma ~ 0.077 deg per axis.  Over 40 runs the stated sigma must
    # match the scatter (rms of error / sigma within [0.6, 1.5]) and no run exceed 4 sigma.
    theory = math.hypot(DENSITY_DEG / math.sqrt(5.0) * 10.0, DENSITY_DEG * math.sqrt(10.0))
    z = []
    for seed in range(40):
        dp, dt, sigma, _ = _noisy_run(seed)
        assert sigma == pytest.approx(theory, rel=0.1)
        assert abs(dp) < 4 * sigma and abs(dt) < 4 * sigma
        z += [dp / sigma, dt / sigma]
    assert 0.6 < math.sqrt(np.mean(np.square(z))) < 1.5


def test_bias_from_rest_and_held_attitude():
    bias = (0.3, -0.5, 0.8)
    _, _, _, g = _noisy_run(7, bias_deg_s=bias)
    est = np.degrees(g.bias.b)
    sd = DENSITY_DEG / math.sqrt(5.0)     # mean of 5 s of white noise
    assert np.all(np.abs(est - bias) < 4 * sd), est
    assert math.degrees(g.bias.sigma_rad_s) == pytest.approx(sd, rel=0.05)
    assert g.rest_samples == 1000 and g.bias.updates >= 1
    # during the rest the attitude was held: the start pose exactly
    assert g.angles_at(-2.0)[:2] == pytest.approx((0.0, 5.0), abs=1e-12)


def test_rest_from_the_commands():
    rec = Reconstructor(SpeedTable.nominal(), latency_s=0.01, dead_time_s=0.04, accel_deg_s2=40.0)
    g = GyroAttitude(rec, rest_margin_s=0.2)
    assert g.at_rest(-5.0) and g.at_rest(0.999)
    g.on_command(1.0, HeadCommand(1, 63, 0, 0))      # moves from the moment it leaves
    assert not g.at_rest(1.0) and not g.at_rest(3.0)
    g.on_command(3.0, STOP)
    v = SpeedTable.nominal().pan.speed_deg_s(63)
    t_rest = 3.0 + 0.05 + v / 40.0 + 0.2        # effect + deceleration + margin
    assert not g.at_rest(t_rest - 1e-6) and g.at_rest(t_rest) and g.at_rest(t_rest + 10)
    g.on_command(t_rest - 0.1, HeadCommand(0, 0, -1, 10))   # moves again before that rest began
    assert not g.at_rest(t_rest + 1.0)
    assert g.at_rest(2.0) is False and g.at_rest(0.5)


def test_rest_refuted_by_the_gyro_follows_the_head():
    # the commands say STOP at 1 s, but the head keeps panning (the STOP was lost on the link)
    t = np.arange(0, int(4 * RATE_HZ) + 1) / RATE_HZ
    g = _source(0.0, 0.0, rest_margin_s=0.1)
    g.on_command(1.0, STOP)
    w = lidar_body_rate_rad_s(np.full_like(t, 8.0), np.zeros_like(t), np.zeros_like(t))
    g.on_imu(t, w)
    dp, _ = _errors(g, t, 8.0 * t, 0 * t)
    assert g.rests_refuted >= 1
    assert np.abs(dp).max() < 1e-6
    assert not g.at_rest(3.0)


def test_beyond_the_last_sample_the_commands_carry_on():
    g = _source(0.0, 0.0)
    t = np.arange(0, 201) / RATE_HZ
    g.on_imu(t, lidar_body_rate_rad_s(np.full_like(t, 5.0), np.zeros_like(t), np.zeros_like(t)))
    p1, _, s1, _ = g.angles_at(1.0)
    p2, _, s2, _ = g.angles_at(1.5)
    c1, c2 = g.commands.angles_at(1.0)[0], g.commands.angles_at(1.5)[0]
    assert p1 == pytest.approx(5.0, abs=1e-9)
    assert p2 - p1 == pytest.approx(c2 - c1, abs=1e-12)
    assert s2 >= s1


def test_without_samples_the_gyro_source_is_the_commands():
    g = _source(30.0, 10.0)
    for t in (0.0, 0.3, 1.7):
        assert g.angles_at(t)[:2] == pytest.approx(g.commands.angles_at(t)[:2], abs=1e-12)


def test_config_key_and_its_errors():
    assert TrackerConfig().attitude == "commands"
    cfg = TrackerConfig.from_mapping({"attitude": "gyro", "imu_rotation_deg": [0, 0, 90]})
    assert cfg.attitude == "gyro" and cfg.imu_rotation_deg == (0.0, 0.0, 90.0)
    assert isinstance(Tracker(cfg, SpeedTable.nominal()).recon, GyroAttitude)
    assert isinstance(Tracker(TrackerConfig(), SpeedTable.nominal()).recon, Reconstructor)
    # the gyro's keys are in a recording's effective configuration only when it runs
    assert "attitude" not in TrackerConfig().effective() and cfg.effective()["attitude"] == "gyro"
    bad = [({"attitude": "imu"}, "attitude"), ({"attitude": 1}, "attitude"),
           ({"imu_rotation_deg": [0, 0]}, "imu_rotation_deg"), ({"imu_rotation_deg": [0, 0, 200]}, "imu_rotation_deg"),
           ({"gyro_noise_deg_s_rthz": 0}, "gyro_noise_deg_s_rthz"),
           ({"gyro_bias_walk_deg_s_rts": -1}, "gyro_bias_walk_deg_s_rts"),
           ({"gyro_rest_margin_s": -0.1}, "gyro_rest_margin_s")]
    for table, key in bad:
        with pytest.raises(UserError) as e:
            TrackerConfig.from_mapping(table, where="x.toml [tracker]")
        assert key in str(e.value) and "x.toml [tracker]" in str(e.value)
    with pytest.raises(UserError, match="commands, gyro|'commands', 'gyro'|commands.*gyro"):
        TrackerConfig.from_mapping({"attitude": "imu"})


def test_a_command_replaced_at_the_same_instant_leaves_the_rest_alone():
    # a frozen head: the tracker registers its command, the driver then says STOP went instead
    g = _source(0.0, 0.0, moving=False)
    for k in range(5):
        g.on_command(0.1 * k, HeadCommand(1, 30, 1, 30))
        g.on_command(0.1 * k, STOP)
    assert g.at_rest(0.25) and g.at_rest(10.0)
    # the same with a real motion first: the replacement STOP's rest starts after the deceleration
    g.on_command(1.0, HeadCommand(1, 30, 0, 0))
    g.on_command(1.1, HeadCommand(1, 40, 0, 0))
    g.on_command(1.1, STOP)
    assert not g.at_rest(1.1) and g.at_rest(3.0)


def test_a_nan_sample_is_dropped_and_counted_not_integrated():
    # issue 32: one NaN sample made the head estimate NaN for good; it is now dropped and counted, and
    # the estimate is the one without it (within the one missing step's share)
    t = np.arange(0, int(5 * RATE_HZ) + 1) / RATE_HZ
    pan, tilt = 25.0 * t, np.full_like(t, 20.0)
    w = lidar_body_rate_rad_s(np.full_like(t, 25.0), tilt, np.zeros_like(t))
    bad = w.copy()
    bad[300, 1] = np.nan
    t_bad = t.copy()
    t_bad[500] = np.inf
    g = _source(0.0, 20.0, history_s=60.0)
    g.on_imu(t_bad, bad)
    assert g.nonfinite_samples == 2
    dp, dt = _errors(g, t[::50], pan[::50], tilt[::50])
    assert np.isfinite(dp).all() and np.isfinite(dt).all()
    assert np.abs(dp).max() < 1e-6 and np.abs(dt).max() < 1e-6
