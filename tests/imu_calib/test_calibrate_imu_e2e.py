"""The whole lidar-IMU calibration on the simulated rig (paper Section IV.A, Fig. 11b).

The bar of issue 19: the extrinsic within 0.1 deg and 1 cm after 10 s per pose on the Mid-40 rig
(scenes/imu-calibration-room.toml: 25 poses, 2 cm range noise, 1 % motor speed noise, a BMI088;
with 13 poses it measured 0.17 deg, not met).  The error must
fall with accumulation and the 16-line lidar must do worse at equal time.
"""

import json

import numpy as np
import pytest

from foveatrack.cli import main
from sim import imu_rig
from sim.scene import load_scene

ROOM = "scenes/imu-calibration-room.toml"


@pytest.fixture(scope="module")
def room_25_poses():
    """The shipped room (25 poses), Mid-40, 10 s per pose."""
    return imu_rig.run(load_scene(ROOM), ["mid40"], (10.0,), bootstrap_samples=100)


@pytest.fixture(scope="module")
def room_7_poses(tmp_path_factory):
    """The room with 7 poses (6 pairs): enough to compare registration errors."""
    path = tmp_path_factory.mktemp("imu") / "room7.toml"
    path.write_text(open(ROOM).read().replace("count = 25", "count = 7"))
    return imu_rig.run(load_scene(path), ["mid40", "vlp16"], (0.2, 1.0, 10.0), bootstrap_samples=0)


@pytest.mark.slow
def test_mid40_10s_meets_the_bar(room_25_poses):
    _, out = room_25_poses
    _, s = out["mid40"][-1]
    assert s.accumulate_s == 10.0
    assert s.rotation_error_deg < 0.1, s
    assert s.translation_error_m < 0.01, s
    # the bootstrap 1-sigma is the size of the error actually made (within 4 sigma)
    assert s.rotation_error_deg < 4 * np.linalg.norm(s.rotation_sigma_deg)
    assert s.translation_error_m < 4 * np.linalg.norm(s.translation_sigma_m)


@pytest.mark.slow
def test_error_falls_with_accumulation_and_16_lines_do_worse(room_7_poses):
    _, out = room_7_poses
    mid = {s.accumulate_s: s for _, s in out["mid40"]}
    vlp = {s.accumulate_s: s for _, s in out["vlp16"]}
    assert mid[10.0].registration_rotation_deg < mid[0.2].registration_rotation_deg
    assert mid[10.0].registration_translation_m < mid[0.2].registration_translation_m
    for t in (1.0, 10.0):
        assert vlp[t].registration_translation_m > 2 * mid[t].registration_translation_m, (t, vlp[t], mid[t])


def test_cli_user_errors(tmp_path, capsys):
    assert main(["calibrate-imu", ROOM, "--lidar", "velodyne64"]) == 2
    assert "lidar 'velodyne64' unknown" in capsys.readouterr().err
    assert main(["calibrate-imu", ROOM, "--accumulate", "1,x"]) == 2
    assert "--accumulate" in capsys.readouterr().err
    assert main(["calibrate-imu", ROOM, "--accumulate", "20"]) == 2
    assert "longer than the dwell" in capsys.readouterr().err
    assert main(["calibrate-imu", "scenes/calibration-room.toml"]) == 2
    assert "no [imu] table" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_writes_the_extrinsic(tmp_path, capsys):
    scene = tmp_path / "short.toml"
    text = open(ROOM).read().replace("count = 25", "count = 5").replace("dwell_s = 10.0", "dwell_s = 1.0")
    scene.write_text(text)
    out = tmp_path / "x.json"
    assert main(["calibrate-imu", str(scene), "--accumulate", "1", "--out", str(out), "--json",
                 "--no-progress", "--bootstrap", "20"]) == 0
    summary = json.loads(capsys.readouterr().out)
    x = json.loads(out.read_text())
    assert len(x["translation_m"]) == 3 and len(x["sigma_rotation_deg"]) == 3
    assert x["pairs"] == 4
    assert summary["extrinsic"]["translation_m"] == x["translation_m"]
    assert abs(x["error_translation_m"]) < 0.1        # 4 pairs, 1 s: rough, but not lost


def test_a_lidars_clouds_do_not_depend_on_its_place_in_the_list(tmp_path):
    # Issue 27: the clouds were seeded with the lidar's index, so the Mid-40 at 0.1 s gave 0.367 deg
    # alone and 0.127 deg as the second lidar.
    path = tmp_path / "room3.toml"
    path.write_text(open(ROOM).read().replace("count = 25", "count = 3"))
    scene = load_scene(path)
    alone = imu_rig.simulate_rig(scene, ["mid40"], 0.05)
    second = imu_rig.simulate_rig(scene, ["horizon", "mid40"], 0.05)
    for a, b in zip(alone.clouds["mid40"], second.clouds["mid40"]):
        assert np.array_equal(a.xyz_m, b.xyz_m) and np.array_equal(a.t_s, b.t_s)
