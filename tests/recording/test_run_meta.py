"""One body of configuration (issue 25): a recording keeps the typed configuration that ran
(:class:`foveatrack.recording.run_meta.RecordingMeta`), built from the objects that run, and replay
rebuilds its tracker from that.  A run whose tracker was changed in code (a Monte-Carlo gain, a
study's frame window) used to record its scene's raw ``[tracker]`` table beside it, and replay
rebuilt the scene's tracker, not the one that ran."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from foveatrack.recording import RecordingReader
from foveatrack.recording.run_meta import RecordingMeta, recorded_tracker
from foveatrack.replay import replay_recording
from foveatrack.space_of_interest import BackgroundMap, Box, Cylinder, Sector
from foveatrack.tracker import TrackerConfig

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "fig12-tracking.toml"
OLD_RECORDINGS = [ROOT / "tests" / "recording" / "fixtures" / "fig12-v1.mcap",
                  ROOT / "tests" / "recording" / "fixtures" / "fig12-v2.mcap",
                  ROOT / "tests" / "corpus" / "intact.mcap"]


@pytest.mark.parametrize("space", [None, Box((0, -5, -1), (50, 5, 10), "world"), Cylinder((1, 2), 3.0, -1.0, 5.0),
                                   Sector(r_min_m=1.0), Sector(-10, 10, 0, 80, 1, 300, "world"),
                                   BackgroundMap(0.2, 2, Box((0, 0, 0), (1, 1, 1)))])
@pytest.mark.parametrize("settings", [{}, {"attitude": "gyro", "imu_rotation_deg": (1.0, -2.0, 3.0)},
                                      {"gain_pan_1_s": 0.7, "pan_limits_deg": (-10.0, 10.0), "max_pan_speed_deg_s": 3.3,
                                       "controller": "predictive", "search_timeout_s": None, "min_points": 4}])
def test_the_recorded_tracker_table_rebuilds_the_same_configuration(space, settings):
    cfg = TrackerConfig(space=space, **settings)
    table = json.loads(json.dumps(cfg.to_mapping()))     # as the recording's JSON keeps it
    assert set(table) == {f for f in TrackerConfig.__dataclass_fields__}    # every setting
    assert TrackerConfig.from_mapping(table) == cfg


def _study_run(path, **tracker):
    """A study's run (sim.study.common.run_loop, recorded as ``study ... --record`` does) of 2 s of
    fig12-tracking with the scene's tracker changed in code, as Monte-Carlo and the studies do."""
    from sim.scene import load_scene, with_run_overrides
    from sim.study.common import run_loop

    scene = with_run_overrides(load_scene(SCENE), 2.0, 3)
    scene = replace(scene, tracker=replace(scene.tracker, **tracker))
    return run_loop(scene, record_to=path)


@pytest.mark.determinism
@pytest.mark.parametrize("tracker", [{"gain_pan_1_s": 0.6, "gain_tilt_1_s": 0.6},   # a Monte-Carlo gain
                                     {"rate_hz": 1000.0 / 50.0}],                     # a study's 50 ms window
                         ids=["gain", "window"])
def test_a_run_changed_in_code_records_and_replays_what_ran(tmp_path, tracker):
    path = tmp_path / "run.mcap"
    m = _study_run(path, **tracker)
    log, ran = m["_log"], m["_loop"].tracker.config
    meta = RecordingMeta.from_dict(RecordingReader(path).meta)
    assert meta.tracker == ran and all(getattr(meta.tracker, k) == v for k, v in tracker.items())
    res = replay_recording(path)
    c = res.comparison
    n = len(log["t_end_s"])
    assert res.tracker_cfg == ran and c["tracker_config_as_recorded"] is True
    assert c["detections_equal"] and c["commands_equal"] and c["commands_compared"] == n, c
    assert c["max_detection_xyz_diff_m"] == 0.0
    assert np.array_equal(res.frames["command"], log["command"])
    assert np.array_equal(res.frames["detected"], log["detected"])
    assert np.array_equal(res.frames["head_pan_deg"], res.recorded["head_pan_deg"])
    assert np.array_equal(res.frames["head_tilt_deg"], res.recorded["head_tilt_deg"])


def test_no_recording_written_now_carries_a_raw_tracker_table(tmp_path):
    # the simulator's recording, and the daemon's metadata as its recording thread writes it
    from foveatrack.daemon import Daemon, load_config

    _study_run(tmp_path / "sim.mcap")
    sim_meta = RecordingReader(tmp_path / "sim.mcap").meta
    d = Daemon(load_config(ROOT / "examples" / "daemon-virtual.toml"), log_path=str(tmp_path / "log.jsonl"),
               status=False, install_signals=False)
    d.log.close()
    for meta in (sim_meta, json.loads(json.dumps(d._meta()))):
        assert not {"tracker_table", "tracker_overrides", "tracker_effective"} & set(meta), sorted(meta)
        rm = RecordingMeta.from_dict(meta)
        assert not rm.legacy and json.loads(json.dumps(rm.to_dict())) == meta   # read back as written
    assert RecordingMeta.from_dict(json.loads(json.dumps(d._meta()))).tracker == d.tracker.config


@pytest.mark.parametrize("path", OLD_RECORDINGS, ids=lambda p: p.name)
def test_recordings_of_the_earlier_form_are_read_by_the_legacy_path(path):
    # the raw table and the head's values beside it, rebuilt as replay always rebuilt them
    raw = RecordingReader(path).meta
    assert "tracker_table" in raw
    meta = RecordingMeta.from_dict(raw)
    assert meta.legacy and meta.source == raw["source"] and meta.speed_table.to_dict() == raw["speed_table"]
    if "tracker_overrides" in raw:
        assert meta.tracker.tilt_limits_deg == tuple(raw["tracker_overrides"]["tilt_limits_deg"])
    assert recorded_tracker(raw) == meta.tracker


def test_the_foxglove_view_takes_d_and_the_lidar_offset_from_the_configuration_that_ran():
    from foveatrack.recording.foxglove_view import FoxgloveChannels
    from foveatrack.recording.run_meta import SimulatorOrigin
    from foveatrack.speed_table import SpeedTable

    cfg = TrackerConfig(space=Box((1.0, -5.0, -1.0), (50.0, 5.0, 10.0), "world"), lidar_offset_m=(0.1, 0.0, 0.2))
    meta = RecordingMeta(cfg, {}, SpeedTable.nominal(), None, SimulatorOrigin("s", None, None, 1, (), {})).to_dict()
    view = FoxgloveChannels(meta)
    assert view.lidar_offset_m == (0.1, 0.0, 0.2)
    assert len(view._space_entities(0)) == 1
    sector = replace(cfg, space=Sector(r_min_m=1.0))       # not drawn
    assert FoxgloveChannels(RecordingMeta.from_dict({**meta, "tracker": sector.to_mapping()}).to_dict())._space_entities(0) == []
    # a meta of a caller's own names no tracker: nothing drawn, nothing fails
    assert FoxgloveChannels({"seed": 1})._space_entities(0) == []


@pytest.mark.parametrize("meta", [{"source": "daemon", "tracker": 3, "head_values": {}},
                                  {"source": "daemon", "tracker": {}, "head_values": {}},
                                  {"source": "elsewhere", "tracker": {}, "head_values": {}},
                                  {"source": "simulator", "tracker_table": {}}])
def test_metadata_no_run_wrote_is_a_one_line_error_naming_the_recording(meta):
    from foveatrack.errors import UserError

    with pytest.raises(UserError, match=r"^x\.mcap: "):
        RecordingMeta.from_dict(meta, "x.mcap")
