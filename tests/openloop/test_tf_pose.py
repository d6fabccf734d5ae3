"""A bag whose sensor moved: ``--fixed-frame`` turns each cloud into the fixed frame with the bag's
``/tf`` and ``/tf_static``, and the track comes out where the drone was in that frame."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import bag_writers as bw
from foveatrack.cli import main
from foveatrack.openloop import track_source
from foveatrack.sources import open_source

FIXTURE = Path(__file__).parent / "mmaud_seq1" / "livox_avia"
TOPIC = "/livox/lidar"


def _poses(n):
    # the mount pans 3 deg and tilts 1 deg per frame and drifts 5 cm: far from the identity
    return [(Rotation.from_euler("zy", [3.0 * k, -1.0 * k], degrees=True).as_matrix(),
             np.array([0.05 * k, -0.02 * k, 1.0])) for k in range(n)]


@pytest.mark.parametrize("ros1", [False, True], ids=["ros2-mcap", "ros1-bag"])
def test_clouds_turned_into_the_fixed_frame_give_the_fixture_track(tmp_path, ros1):
    frames = bw.npy_frames(FIXTURE)
    path = bw.write_bag_with_tf(tmp_path / ("m.bag" if ros1 else "m"), frames, _poses(len(frames)), ros1=ros1)
    got = [fr for _, fr in open_source(path, TOPIC, fixed_frame="world")]
    want = [fr for _, fr in open_source(FIXTURE)]
    for a, b in zip(got, want):
        np.testing.assert_allclose(a.xyz, b.xyz, rtol=0, atol=1e-9)
    res, ref = track_source(open_source(path, TOPIC, fixed_frame="world")), track_source(open_source(FIXTURE))
    assert res.frames["detected"].tolist() == ref.frames["detected"].tolist()
    d = ref.frames["detected"]
    np.testing.assert_allclose(res.frames["xyz_m"][d], ref.frames["xyz_m"][d], rtol=0, atol=1e-9)
    # without the pose the cloud turns with the mount and the track is elsewhere
    raw = track_source(open_source(path, TOPIC))
    assert not np.allclose(raw.frames["xyz_m"][raw.frames["detected"]][-1], ref.frames["xyz_m"][d][-1], atol=0.1)


def test_unknown_fixed_frame_and_a_bag_without_tf(tmp_path, capsys):
    frames = bw.npy_frames(FIXTURE)[:3]
    path = bw.write_bag_with_tf(tmp_path / "m", frames, _poses(3), ros1=False)
    assert main(["track", str(path), "--topic", TOPIC, "--fixed-frame", "map"]) == 2
    err = capsys.readouterr().err
    assert "no transform from 'livox' to 'map'" in err and "base" in err and "Traceback" not in err
    plain = bw.write_bag(tmp_path / "p", frames, "pointcloud2", ros1=False)
    assert main(["track", str(plain), "--topic", TOPIC, "--fixed-frame", "world"]) == 2
    err = capsys.readouterr().err
    assert "--fixed-frame world needs a /tf topic" in err and "Traceback" not in err
    assert main(["track", str(FIXTURE), "--fixed-frame", "world"]) == 2
    assert "only a bag has /tf" in capsys.readouterr().err
