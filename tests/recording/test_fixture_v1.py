"""A recording made by the format-1 writer (JSON + base64 points, before the Foxglove SDK writer)
still reads and replays to the bit.

fixtures/fig12-v1.mcap: the first 0.8 s (8 frames, 36 051 points) of scenes/fig12-tracking.toml,
written by main at d76062b with ``RecordingWriter(..., compression="zstd")`` (zstd to keep the
committed file near 1 MB; the format is version 1 as ``simulate --out`` wrote it)."""

from pathlib import Path

import numpy as np

from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording

FIXTURE = Path(__file__).parent / "fixtures" / "fig12-v1.mcap"


def test_format_1_fixture_reads_whole():
    r = RecordingReader(FIXTURE)
    assert r.info["format_version"] == "1"
    frames = list(r.points())
    assert [f.frame_index for f in frames] == list(range(8))
    assert sum(len(f) for f in frames) == 36051
    assert r.complete and r.problem is None
    assert r.meta["scene_name"] == "fig12-tracking"


def test_format_1_fixture_replays_to_the_bit():
    res = replay_recording(FIXTURE)
    c = res.comparison
    assert c["detections_equal"] and c["commands_equal"], c
    assert c["commands_compared"] == 8 and c["max_detection_xyz_diff_m"] == 0.0
    assert res.recorded is not None
    assert np.array_equal(res.frames["head_pan_deg"], res.recorded["head_pan_deg"])
    assert np.array_equal(res.frames["head_tilt_deg"], res.recorded["head_tilt_deg"])
