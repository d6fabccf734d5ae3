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


def _recorded_gyro_run(path, imu: bool = True, duration_s: float = 3.0):
    """fig12-predictive (its commands follow the world estimate, so the head's angles) with the head
    gyro and attitude = "gyro", the tracker's table nominal (command dead reckoning then runs degrees
    off the gyro's), recorded as simulate records it; ``imu=False``: as recordings were made before
    the IMU channel existed.  Returns the loop's per-frame log."""
    from foveatrack.recording import RecordingWriter
    from sim.recorder import SimRecorder, recording_meta

    class WithoutImu(SimRecorder):
        def __call__(self, frame, out, loop):
            fed, loop.imu_fed = loop.imu_fed, None
            try:
                super().__call__(frame, out, loop)
            finally:
                loop.imu_fed = fed

    sc = scene_variant(SCENES / "fig12-predictive.toml", "gyro", duration_s=duration_s)
    sc = replace(sc, gimbal=replace(sc.gimbal, speed_table="nominal"))
    loop = ClosedLoop(sc)
    with RecordingWriter(path, recording_meta(sc, loop), created_utc="fixed") as w:
        loop.frame_hook = (SimRecorder if imu else WithoutImu)(w)
        return loop.run()


@pytest.mark.slow
def test_a_recorded_gyro_run_replays_to_the_bit(tmp_path):
    # replay feeds the recorded gyro samples to the tracker before each frame, as the loop did: the
    # commands, detections and head estimates are the run's, frame by frame, to the bit
    from foveatrack.recording import RecordingReader
    from foveatrack.replay import replay_recording

    log = _recorded_gyro_run(tmp_path / "gyro.mcap")
    res = replay_recording(tmp_path / "gyro.mcap")
    c = res.comparison
    n = len(log["t_end_s"])
    assert c["gyro_samples_recorded"] is True
    assert c["detections_equal"] and c["commands_equal"] and c["commands_compared"] == n, c
    assert c["max_detection_xyz_diff_m"] == 0.0 and c["tracker_config_as_recorded"] is True
    assert np.array_equal(res.frames["command"], log["command"])
    assert np.array_equal(res.frames["detected"], log["detected"])
    assert np.array_equal(res.frames["head_pan_deg"], res.recorded["head_pan_deg"])
    assert np.array_equal(res.frames["head_tilt_deg"], res.recorded["head_tilt_deg"])
    assert sum(len(b) for b in RecordingReader(tmp_path / "gyro.mcap").imu()) == 1000 + 20 * n
    # the same run recorded without its samples (as before the channel): replay falls back to the
    # commands' dead reckoning and says so; with the nominal table its head estimate then leaves the
    # run's, and so do commands (measured: 26 of 30) and detections (6: the world-frame D), so the
    # equality above is the gyro's doing, not a coincidence of the two attitudes
    _recorded_gyro_run(tmp_path / "old.mcap", imu=False)
    old = replay_recording(tmp_path / "old.mcap")
    assert old.comparison["gyro_samples_recorded"] is False
    assert np.array_equal(old.recorded["head_pan_deg"], res.recorded["head_pan_deg"])
    off = np.hypot(old.frames["head_pan_deg"] - old.recorded["head_pan_deg"],
                   old.frames["head_tilt_deg"] - old.recorded["head_tilt_deg"])
    assert off.max() > 0.5
    assert old.comparison["frames_command_differs"] > n // 2


def test_replay_of_a_gyro_run_from_the_cli_is_the_run(tmp_path, capsys):
    from foveatrack.cli import main

    text = (SCENES / "fig12-tracking.toml").read_text().replace("[gimbal]\n", "[imu]\n\n[gimbal]\n", 1)
    text = text.replace("[tracker]\n", '[tracker]\nattitude = "gyro"\n', 1)
    scene = tmp_path / "gyro.toml"
    scene.write_text(text)
    assert load_scene(scene).tracker.attitude == "gyro" and load_scene(scene).imu is not None
    assert main(["simulate", str(scene), "--duration", "1", "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["replay", str(tmp_path / "out" / "run.mcap")]) == 0
    out = capsys.readouterr().out
    assert "same as recorded: all 10 detections and 10 commands identical" in out
    assert "no IMU samples" not in out


def test_replay_with_the_gyro_of_a_recording_without_imu_samples_says_so(tmp_path, capsys):
    # a recording made before the IMU channel (format 2, fig12, no [imu]) replayed with attitude = "gyro"
    from foveatrack.cli import main

    cfg = tmp_path / "gyro.toml"
    # a tracker config replaces the recorded one whole, so it names its space of interest (fig12's box)
    cfg.write_text('[tracker]\nattitude = "gyro"\n[tracker.space]\nkind = "box"\nframe = "world"\n'
                   'min_xyz = [1.0, -60.0, -0.7]\nmax_xyz = [60.0, 60.0, 40.0]\n')
    fixture = Path(__file__).resolve().parents[1] / "recording" / "fixtures" / "fig12-v2.mcap"
    assert main(["replay", str(fixture), "--tracker-config", str(cfg)]) == 0
    assert "the recording holds no IMU samples" in capsys.readouterr().out


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
