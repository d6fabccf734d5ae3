"""Recordings made by earlier writers still read and replay to the bit.

fixtures/fig12-v1.mcap (format 1: JSON + base64 points, before the Foxglove SDK writer): the first 0.8 s
(8 frames, 36 051 points) of scenes/fig12-tracking.toml, written by main at d76062b with
``RecordingWriter(..., compression="zstd")`` (zstd to keep the committed file near 1 MB).

fixtures/fig12-v2.mcap (format 2: the SDK, float64 points, before the simulator's points were put on
the Livox mm grid): ``foveatrack simulate scenes/fig12-tracking.toml --duration 0.4 --out DIR`` at
f1d9283 (4 frames, 18 219 points, lz4 as it wrote by default).

fixtures/fig12-v3.mcap (format 3: points on the Livox mm grid as float32, point times in the unit of
protobuf field 16 and the frame index in field 15, both outside Foxglove's PointCloud schema):
``foveatrack simulate scenes/fig12-tracking.toml --duration 0.4 --out DIR`` at 621f5c0 (4 frames,
18 264 points, zstd 1)."""

from pathlib import Path

import numpy as np
import pytest

from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording

HERE = Path(__file__).parent / "fixtures"
FIXTURES = {"1": (HERE / "fig12-v1.mcap", 8, 36051), "2": (HERE / "fig12-v2.mcap", 4, 18219),
            "3": (HERE / "fig12-v3.mcap", 4, 18264)}


@pytest.mark.parametrize("version", sorted(FIXTURES))
def test_old_fixture_reads_whole(version):
    path, n_frames, n_points = FIXTURES[version]
    r = RecordingReader(path)
    assert r.info["format_version"] == version
    frames = list(r.points())
    assert [f.frame_index for f in frames] == list(range(n_frames))
    assert sum(len(f) for f in frames) == n_points
    assert r.complete and r.problem is None
    assert r.meta["scene_name"] == "fig12-tracking"
    # versions 1 and 2: float64 points as the simulator made them then (off the mm grid), read as they
    # were written; version 3: on the mm grid, read back as the client's k * 1e-3
    xyz = np.concatenate([f.xyz for f in frames])
    assert np.any(np.rint(xyz * 1000) * 1e-3 != xyz) == (version != "3")
    # the point times lie in the frame [t_ns - 100 ms, t_ns] (the simulator's frame interval)
    assert all(np.all(f.t_ns_points <= f.t_ns) and np.all(f.t_ns_points >= f.t_ns - 100_000_000) for f in frames)


@pytest.mark.parametrize("version", sorted(FIXTURES))
def test_old_fixture_replays_to_the_bit(version):
    path, n_frames, _ = FIXTURES[version]
    res = replay_recording(path)
    c = res.comparison
    assert c["detections_equal"] and c["commands_equal"], c
    assert c["commands_compared"] == n_frames and c["max_detection_xyz_diff_m"] == 0.0
    assert res.recorded is not None
    assert np.array_equal(res.frames["head_pan_deg"], res.recorded["head_pan_deg"])
    assert np.array_equal(res.frames["head_tilt_deg"], res.recorded["head_tilt_deg"])
