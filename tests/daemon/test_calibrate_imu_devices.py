"""``foveatrack calibrate-imu --config``: the lidar-IMU calibration on live devices (paper Sec. IV.A).

End to end through the virtual devices as separate processes, as a bench would run it: ``gimbal
serve`` (a heavy-worm head on a pseudo-terminal, Pelco-D in), ``lidar serve`` (a Horizon with its
IMU in the room of ``scenes/imu-calibration-head.toml``, over Livox UDP on 127.0.0.1, following that
head's pose: points and IMU samples), and the command under test reading the daemon's config.
"""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from daemon_procs import ROOT, env, first_line, free_udp_port, start, terminate, wait_for
from foveatrack.cli import main
from foveatrack.imu_calib.se3 import so3_log
from sim.scene import load_scene
from sim.virtual_head import read_truth

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")

SCENE = ROOT / "scenes" / "imu-calibration-head.toml"
WATCHDOG_S = 5.0   # the virtual lidar can pause on a loaded 2-core machine; this is not a watchdog test


def _config(tmp_path, link, bport) -> str:
    p = tmp_path / "d.toml"
    p.write_text(f"""
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
cmd_port = 0
data_port = 0
broadcast_port = {bport}
point_rate_hz = 100000
[head]
port = "{link}"
pan0_deg = 31.0
tilt0_deg = -12.0
pan_speed_max_deg_s = 30.0
tilt_speed_max_deg_s = 15.0
pan_turbo_deg_s = 40.0
[daemon]
watchdog_s = {WATCHDOG_S}
""")
    return str(p)


def _clock_zero(path) -> str | None:
    try:
        m = re.search(r"time\.monotonic\(\) = ([0-9.]+)", path.read_text())
    except OSError:
        return None
    return m.group(1) if m else None


def _rig(tmp_path):
    link, truth = tmp_path / "head", tmp_path / "truth.jsonl"
    bport = free_udp_port()
    procs = [start(["gimbal", "serve", "--family", "heavy-worm", "--link", str(link), "--truth", str(truth),
                    "--pan0-deg", "31", "--tilt0-deg", "-12"], tmp_path / "head.out", tmp_path / "head.err")]
    wait_for(lambda: _clock_zero(tmp_path / "head.err"), 20, "the head's pty and clock zero", procs)
    procs.append(start(["lidar", "serve", str(SCENE), "--cmd-port", "0", "--broadcast-port", str(bport),
                        "--head-truth", str(truth), "--head-clock-zero", _clock_zero(tmp_path / "head.err")],
                       tmp_path / "l.out", tmp_path / "l.err"))
    wait_for(lambda: first_line(tmp_path / "l.out"), 120, "the virtual lidar", procs)
    return procs, _config(tmp_path, link, bport), truth


def _errors(extrinsic: dict, X_true: np.ndarray) -> tuple[float, float]:
    R = np.array(extrinsic["rotation_matrix"])
    t = np.array(extrinsic["translation_m"])
    return (float(np.degrees(np.linalg.norm(so3_log(R @ X_true[:3, :3].T)))),
            float(np.linalg.norm(t - X_true[:3, 3])))


@pytest.mark.slow
def test_the_head_steps_the_rig_and_the_extrinsic_is_recovered(tmp_path):
    X_true = load_scene(SCENE).imu.T_lidar_imu
    procs, cfg, truth = _rig(tmp_path)
    try:
        out = tmp_path / "x.json"
        p = subprocess.run([sys.executable, "-m", "foveatrack", "calibrate-imu", "--config", cfg, "--poses", "7",
                            "--dwell-s", "2", "--settle-s", "0.7", "--out", str(out), "--json", "--max-s", "240"],
                           cwd=ROOT, env=env(), capture_output=True, text=True, timeout=400)
        assert p.returncode == 0, p.stderr
        summary = json.loads(p.stdout)
        ext = json.loads(out.read_text())
        rot_err_deg, tr_err_m = _errors(ext, X_true)
        print(f"rotation error {rot_err_deg:.4f} deg, translation error {tr_err_m * 100:.3f} cm; "
              f"1-sigma {ext['sigma_rotation_deg']} deg, {ext['sigma_translation_m']} m; "
              f"singular values {ext['translation_singular_values']}; gravity {ext['gravity_m_s2']}")
        print(json.dumps({k: summary[k] for k in ("points_per_pose", "static_spread_deg_s", "registration_rms_m",
                                                  "consistency_eq8", "wall_s")}))
        assert rot_err_deg < 0.3 and tr_err_m < 0.02, (rot_err_deg, tr_err_m, ext)
        # back at the start pose (dead-reckoned), and stopped
        rest = read_truth(truth)[-1]
        assert rest["pan_speed_deg_s"] == 0.0 and rest["tilt_speed_deg_s"] == 0.0
    finally:
        for q in procs:
            terminate(q)
