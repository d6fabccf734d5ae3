"""The lidar's gyro on the head in the closed loop (sim/head_imu.py) and the tracker's gyro attitude
against command dead reckoning (sim/attitude_study.py)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.gyro_attitude import GyroAttitude
from sim.attitude_study import head_angle_error_deg, run_variant, scene_variant
from sim.loop import ClosedLoop
from sim.scene import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"
NOISE_FREE = {"gyro_noise_density_deg_s_rthz": 0.0, "gyro_bias_sigma_deg_s": 0.0, "gyro_bias_walk_deg_s_rts": 0.0}


def _bits(log):
    return {k: np.ascontiguousarray(v).tobytes() for k, v in log.items()}


def test_a_scene_without_imu_is_unchanged_to_the_bit():
    # Without [imu] nothing is simulated; with [imu] and the commands' attitude the gyro draws from its
    # own stream and the tracker ignores it: the run is the same, bit for bit (noisy-link: every
    # random stream of the loop is in use, the UART's included).
    plain = replace(load_scene(SCENES / "noisy-link.toml"), duration_s=3.0)
    loop = ClosedLoop(plain)
    assert loop.gyro is None
    a = loop.run()
    b_loop = ClosedLoop(scene_variant(SCENES / "noisy-link.toml", "commands", duration_s=3.0))
    assert b_loop.gyro is not None
    b = b_loop.run()
    assert b_loop.gyro._k_next > 0          # the gyro did run
    assert _bits(a) == _bits(b)


def test_the_simulated_gyro_follows_the_head():
    # noise-free gyro: the integrated attitude is the truth up to the trapezoid's error at the head's
    # acceleration kinks (dt^2 |delta a| / 8 per kink: 1.25e-4 deg at 40 deg/s^2, 200 Hz), even with
    # an uncalibrated table that sends command dead reckoning tens of degrees off
    sc = scene_variant(SCENES / "fig12-tracking.toml", "gyro", duration_s=10.0, imu=NOISE_FREE)
    sc = replace(sc, gimbal=replace(sc.gimbal, speed_table="nominal"))
    loop = ClosedLoop(sc)
    log = loop.run()
    assert isinstance(loop.tracker.recon, GyroAttitude)
    err = head_angle_error_deg(log)
    assert np.nanmax(err) < 2e-3
    assert np.isfinite(err).all()


def test_gyro_attitude_needs_an_imu():
    sc = load_scene(SCENES / "fig12-tracking.toml")
    with pytest.raises(UserError, match=r"attitude = \"gyro\" needs an \[imu\]"):
        ClosedLoop(replace(sc, tracker=replace(sc.tracker, attitude="gyro")))


@pytest.mark.slow
def test_gyro_beats_command_dead_reckoning_with_a_miscalibrated_table():
    # fig12, 30 s, the tracker's table 3 % fast (every speed of the unit's truth x 1.03): the commands'
    # dead reckoning drifts with every turn; the gyro (BMI088 noise and bias, estimated at rest) does not
    runs = {a: run_variant(scene_variant(SCENES / "fig12-tracking.toml", a, table_scale=1.03))
            for a in ("commands", "gyro")}
    cmd, gyro = runs["commands"], runs["gyro"]
    assert gyro["head_angle_error_deg"]["rms"] < 0.5 * cmd["head_angle_error_deg"]["rms"]
    assert gyro["head_angle_error_deg"]["max"] < cmd["head_angle_error_deg"]["max"]
    assert gyro["reconstruction_error_m"]["rms"] < cmd["reconstruction_error_m"]["rms"]
    # measured: commands 0.86 deg rms, gyro 0.13 deg rms; the gyro's own bound on this run
    assert gyro["head_angle_error_deg"]["max"] < 0.5


def test_replay_of_a_gyro_run_says_the_imu_was_not_recorded(tmp_path, capsys):
    from foveatrack.cli import main

    text = (SCENES / "fig12-tracking.toml").read_text().replace("[gimbal]\n", "[imu]\n\n[gimbal]\n", 1)
    text = text.replace("[tracker]\n", '[tracker]\nattitude = "gyro"\n', 1)
    scene = tmp_path / "gyro.toml"
    scene.write_text(text)
    assert load_scene(scene).tracker.attitude == "gyro" and load_scene(scene).imu is not None
    assert main(["simulate", str(scene), "--duration", "1", "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["replay", str(tmp_path / "out" / "run.mcap")]) == 0
    assert "recordings hold no IMU samples" in capsys.readouterr().out


def test_head_angle_error_is_the_rotation_between_the_attitudes():
    # two routes: the vectorised metric against the angle of R_true^T R_est from its trace
    from foveatrack.metrics import head_angle_error_deg as metric
    from foveatrack.reconstruction import rotation_matrix

    rng = np.random.default_rng(4)
    p, t = rng.uniform(-180, 180, 200), rng.uniform(-80, 80, 200)
    ep, et = p + rng.normal(0, 2, 200), t + rng.normal(0, 2, 200)
    ep[:3], et[:3] = p[:3], t[:3]
    got = metric(p, t, ep, et)
    want = [np.degrees(np.arccos(np.clip((np.trace(rotation_matrix(a, b).T @ rotation_matrix(c, d)) - 1) / 2, -1, 1)))
            for a, b, c, d in zip(p, t, ep, et)]
    assert np.allclose(got, want, atol=1e-6)
    assert np.all(got[:3] == 0.0)
    # pure tilt error: the angle is the tilt difference; NaN estimates stay NaN
    assert metric([10.0], [20.0], [10.0], [20.5])[0] == pytest.approx(0.5, abs=1e-9)
    assert np.isnan(metric([0.0], [0.0], [np.nan], [0.0])[0])
