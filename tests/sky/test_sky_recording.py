"""Every track where a track goes (issue 28): the recording's /tracks channel, the configuration that
replay rebuilds the multi-object tracker from, and replay's tracks equal to the run's to the bit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from foveatrack.recording import RecordingReader
from foveatrack.recording.records import RecordError, TracksRecord
from foveatrack.replay.driver import replay_recording
from foveatrack.sky.controller import sky_configs_from_mapping

SCENES = Path(__file__).resolve().parents[2] / "scenes"


@pytest.fixture(scope="module")
def crossing_run(tmp_path_factory):
    from foveatrack.cli import main

    out = tmp_path_factory.mktemp("crossing") / "run"
    # 6 s: both drones confirmed (the 1 s warm-up, then the rim's sparse hits), the fovea turned between them
    assert main(["simulate", str(SCENES / "two-drones-crossing.toml"), "--duration", "6", "--out", str(out),
                 "--no-progress", "--one-thread", "--plot"]) == 0
    return out / "run.mcap"


def test_every_frame_records_its_tracks_and_the_table_that_ran(crossing_run):
    r = RecordingReader(crossing_run)
    recs = [TracksRecord.from_json(x) for x in r.records("tracks")]
    assert len(recs) == 60 and [x.frame_id for x in recs] == list(range(60))
    confirmed = {t.id for x in recs for t in x.tracks if t.confirmed}
    assert len(confirmed) >= 2, "both drones have confirmed tracks within 6 s"
    assert any(x.fixated is not None for x in recs)
    # the recorded table reads back to the configurations that ran (the scene's defaults, the lidar's field)
    cfg, att = sky_configs_from_mapping(r.meta["sky"], "recorded")
    assert cfg.field_half_angle_deg is not None and att.revisit_s == 3.0


def test_replay_rebuilds_the_multi_object_tracker_and_its_tracks_are_the_runs_to_the_bit(crossing_run):
    res = replay_recording(crossing_run)
    c = res.comparison
    assert c["detections_equal"] and c["commands_equal"]
    assert c["tracks"]["identical_all"], c["tracks"]
    assert c["tracks"]["recorded"] == 60
    rec = [x for x in RecordingReader(crossing_run).records("tracks")]
    assert [t.to_json() for t in res.tracks] == [TracksRecord.from_json(x).to_json() for x in rec]


def test_replay_with_another_sky_table_says_where_the_tracks_first_differ(crossing_run):
    table = {"sky": {"warmup_s": 0.5}}       # the scene's [tracker] otherwise (the recorded one)
    meta = RecordingReader(crossing_run).meta
    table.update({k: v for k, v in meta["tracker"].items() if k != "sky"})
    res = replay_recording(crossing_run, tracker_table=table, config_name="shorter warm-up")
    tr = res.comparison["tracks"]
    assert not tr["identical_all"] and tr["first_difference"] is not None
    assert tr["first_difference"] >= 4, "the first 0.5 s are the warm-up in both"


def test_replay_with_a_paper_tracker_table_runs_the_paper_tracker(crossing_run):
    meta = RecordingReader(crossing_run).meta
    table = {k: v for k, v in meta["tracker"].items()}
    res = replay_recording(crossing_run, tracker_table=table, config_name="paper")
    assert res.tracks == [] and res.comparison["tracks"]["compared"] == 0
    # and the report says so, where it printed "0 of 60 recorded frames' tracks identical"
    from foveatrack.replay.report import format_report

    text = format_report(res)
    assert "ran the paper's single-target tracker" in text and "none to compare" in text, text
    assert "recorded frames' tracks identical" not in text


def test_a_damaged_tracks_record_names_its_field():
    good = {"t_ns": 1, "frame_id": 0, "tracks": [{"id": 3, "confirmed": True, "label": "drone", "looks_like": "drone",
                                                   "xyz_m": [1.0, 2.0, 3.0], "velocity_m_s": [0.0, 0.0, 0.0],
                                                   "hit": True, "in_view": True, "score": 0.5}]}
    assert TracksRecord.from_json(json.loads(json.dumps(good))).tracks[0].id == 3
    bad = json.loads(json.dumps(good))
    bad["tracks"][0]["xyz_m"] = [1.0, "x", 3.0]
    with pytest.raises(RecordError, match=r"tracks\[0\].*xyz_m"):
        TracksRecord.from_json(bad)
    bad = json.loads(json.dumps(good))
    bad["in_fovea"] = [1.5]
    with pytest.raises(RecordError, match="in_fovea"):
        TracksRecord.from_json(bad)


def test_simulate_reports_the_multi_object_figures_and_plots_the_tracks(crossing_run):
    summary = json.loads((crossing_run.parent / "summary.json").read_text())
    sky = summary["sky"]
    assert sorted(sky["drones"]) == ["drone-a", "drone-b"]
    for r in sky["drones"].values():
        assert r["time_to_confirm_s"] is not None and r["id_switches"] == 0
    assert sky["confirmed_tracks"] >= 2 and sky["gospa_mean_m"] > 0
    assert (crossing_run.parent / "tracks.png").stat().st_size > 10_000
    assert not (crossing_run.parent / "error.png").exists(), "Fig. 14's plots are of one target"


def test_a_rebased_controller_starts_afresh_but_never_reuses_an_id():
    from foveatrack.sky.controller import SkyController
    from foveatrack.speed_table import SpeedTable
    from foveatrack.tracker import Tracker
    from sim.scene import load_scene

    scene = load_scene(SCENES / "two-drones-crossing.toml")
    cfg, att = sky_configs_from_mapping(scene.tracker_table["sky"], "scene", 19.2)
    c = SkyController(Tracker(scene.tracker, SpeedTable.nominal()), cfg, att)
    c.sky._next_id = 7                        # seven tracks were made before the rebase
    c.pin(3)
    new = c.rebased(12.5, 10.0, 2.0)
    assert new.sky.tracks == [] and new.sky.background.frame_no == 0 and new.attention.pinned is None
    assert new.sky._next_id == 7 and new.tracker.recon.angles_at(12.5)[:2] == (10.0, 2.0)
    assert new.sky_table() == c.sky_table()


def test_a_run_with_the_saccade_gain_records_it_and_replays_to_the_bit(tmp_path):
    # the option travels in the recorded table (the default is written as null and reads back as it);
    # replay rebuilds the controller with it: the same commands and tracks
    from foveatrack.cli import main

    scene = tmp_path / "crossing-fast-saccades.toml"
    scene.write_text((SCENES / "two-drones-crossing.toml").read_text()
                     + "\n[tracker.sky.attention]\nsaccade_gain_1_s = 4.0\nsaccade_latency_s = 0.6\n")
    out = tmp_path / "run"
    assert main(["simulate", str(scene), "--duration", "6", "--out", str(out), "--no-progress", "--one-thread"]) == 0
    meta = RecordingReader(out / "run.mcap").meta
    assert meta["sky"]["attention"]["saccade_gain_1_s"] == 4.0
    _, att = sky_configs_from_mapping(meta["sky"], "recorded")
    assert att.saccade_gain_1_s == 4.0
    res = replay_recording(out / "run.mcap")
    c = res.comparison
    assert c["detections_equal"] and c["commands_equal"] and c["tracks"]["identical_all"], c


def test_replay_plots_the_tracks_as_simulate_does(crossing_run, tmp_path):
    # replay --plot of a multi-object run draws tracks.png too (it drew the single-target figures
    # only): the replayed tracks, the recorded truth of every object and each drone's time in the
    # fovea -- the masks simulate drew from its own run; a daemon's recording (no truth): tracks alone
    from types import SimpleNamespace

    import numpy as np

    from foveatrack.cli.replay_plots import plot_all, sky_plot_data
    from foveatrack.cli.sim_plots import plot_sky_tracks

    res = replay_recording(crossing_run)
    files = plot_all(res, tmp_path)
    assert (tmp_path / "tracks.png") in files and (tmp_path / "tracks.png").stat().st_size > 10_000
    # as simulate draws a multi-object run: the one-target figures mixed the fixated tracks' detections
    assert sorted(p.name for p in files) == ["head.png", "tracks.png"]
    t = np.asarray(res.frames["t_end_s"], float)
    data = sky_plot_data(res, t)
    assert sorted(i for i, (c, _) in data["truth"].items() if c == "drone") == ["drone-a", "drone-b"]
    assert len(data["tracks"]) >= 2 and all(m.any() for m in data["in_fovea"].values())
    # measured frames are confirmed frames, and some frames coasted (drawn apart: a user took a track's
    # coasted straight line for measured positions)
    assert all(np.isfinite(x[h, 0]).all() for _, x, h in data["tracks"].values())
    assert any((np.isfinite(x[:, 0]) & ~h).any() for _, x, h in data["tracks"].values())
    # each frame's label, as recorded (a track drawn in its last label hid the frames it was a drone)
    assert all(((labels != "") == np.isfinite(x[:, 0])).all() for labels, x, _ in data["tracks"].values())
    for k, rec in enumerate(res.tracks):
        for v in rec.tracks:
            if v.confirmed:
                assert data["tracks"][v.id][0][k] == v.label
    # the fovea masks are the ones the run's own figures count (sim.sky_summary.drone_truth)
    from sim.loop import ClosedLoop
    from sim.scene import load_scene
    from sim.sky_summary import drone_truth, truth_frames
    import dataclasses

    loop = ClosedLoop(dataclasses.replace(load_scene(SCENES / "two-drones-crossing.toml"), duration_s=6.0))
    log = loop.run()
    want = drone_truth(loop, log, truth_frames(loop, log))
    for d, m in data["in_fovea"].items():
        assert np.array_equal(m, want[d]["in_fovea"]), d
    daemon = SimpleNamespace(source="daemon", path=str(crossing_run), truth=None, tracks=res.tracks)
    bare = sky_plot_data(daemon, t)
    assert bare["truth"] == {} and bare["in_fovea"] == {} and len(bare["tracks"]) == len(data["tracks"])
    assert plot_sky_tracks(bare, "daemon", tmp_path / "bare.png").stat().st_size > 5_000


def test_export_writes_every_track_and_every_objects_truth_as_the_recording_holds_them(crossing_run, tmp_path):
    """``export --tracks`` / ``--truth-objects``: a row per track (object) and frame, what a
    multi-object evaluation takes; the CSV and the NPZ hold the recorded values (the NPZ to the bit)."""
    import csv

    import numpy as np

    from foveatrack.cli import main
    from foveatrack.recording.records import ObjectTruthRecord

    out = {k: tmp_path / f"{k}.{ext}" for k, ext in (("tc", "csv"), ("tn", "npz"), ("oc", "csv"), ("on", "npz"))}
    assert main(["export", str(crossing_run), "--tracks", str(out["tc"]), "--truth-objects", str(out["oc"])]) == 0
    assert main(["export", str(crossing_run), "--tracks", str(out["tn"]), "--truth-objects", str(out["on"])]) == 0
    r = RecordingReader(crossing_run)
    want = [(f, e) for f in map(TracksRecord.from_json, r.records("tracks")) for e in f.tracks]
    z = np.load(out["tn"])
    assert len(z["id"]) == len(want) > 0
    assert z["frame_id"].tolist() == [f.frame_id for f, _ in want]
    assert z["id"].tolist() == [e.id for _, e in want]
    assert z["label"].tolist() == [e.label for _, e in want]
    assert np.array_equal(np.column_stack([z["x_m"], z["y_m"], z["z_m"]]), np.array([e.xyz_m for _, e in want]))
    assert z["fixated"].tolist() == [e.id == f.fixated for f, e in want]
    assert int(z["fixated"].sum()) > 0 and int(z["confirmed"].sum()) > 0
    rows = list(csv.DictReader(out["tc"].open()))
    assert [int(x["id"]) for x in rows] == z["id"].tolist()
    assert [float(x["y_m"]) for x in rows] == z["y_m"].tolist()       # repr round-trips the float
    truth = [ObjectTruthRecord.from_json(x) for x in r.records("truth_objects")]
    o = np.load(out["on"])
    assert sorted(set(o["id"].tolist())) == ["drone-a", "drone-b"] and len(o["id"]) == len(truth)
    assert np.array_equal(np.column_stack([o["x_m"], o["y_m"], o["z_m"]]), np.array([t.true_world_m for t in truth]))
    assert [x["class"] for x in csv.DictReader(out["oc"].open())] == o["class"].tolist()


def test_export_of_tracks_from_a_single_target_run_says_it_has_none(tmp_path, capsys):
    from foveatrack.cli import main

    run = tmp_path / "run"
    assert main(["simulate", str(SCENES / "fig12-tracking.toml"), "--duration", "0.5", "--out", str(run),
                 "--no-progress", "--one-thread"]) == 0
    capsys.readouterr()
    assert main(["export", str(run / "run.mcap"), "--tracks", str(tmp_path / "t.csv")]) == 2
    assert "holds no tracks: a run of the single-target tracker" in capsys.readouterr().err
    assert main(["export", str(run / "run.mcap"), "--truth-objects", str(tmp_path / "o.csv")]) == 2
    assert "holds no object truth" in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists() and not (tmp_path / "o.csv").exists()


def test_a_replay_under_another_table_places_the_points_from_the_head_as_it_moved(crossing_run):
    """Open loop: the points were seen while the head ran the recorded commands, so the replayed
    tracker's dead reckoning follows those, whatever it would have sent itself.  Before, it followed
    its own commands: under another schedule the head estimate drifted from the recorded one and the
    recorded points were put in the world at the wrong pose."""
    meta = RecordingReader(crossing_run).meta
    table = {k: v for k, v in meta["tracker"].items() if k != "sky"}
    table["sky"] = {"attention": {"saccade_gain_1_s": 4.0, "revisit_s": 1.0}}
    res = replay_recording(crossing_run, tracker_table=table, config_name="faster saccades")
    assert not res.comparison["commands_equal"], "another schedule: other commands"
    # where its dead reckoning has the head in the end: where the recorded commands took it, as the
    # replay under the recorded table has it (before: 12.6 deg of pan apart)
    assert res.final_pose_deg == replay_recording(crossing_run).final_pose_deg


# Each key a sky table gained after recordings began to keep it, at the value it ran with before, and
# the run in which today's default acts differently (so the test can tell):
# * classifier.drone_after_hits, tree line seed 258: a crown's part is labelled drone 3.2 s in after
#   five hits and five frames of coasting (the count of hits keeps that label back; so does
#   drone_label_on_hit, which a recording that lacks the first lacks too);
# * attention.saccade_counts_motion and keep_verdict, the crossing (its own seed): out of the fovea a
#   drone's track looks unknown, and keeps its label for the schedule (the first key's default is
#   what ran before it; a table without it must still replay so);
# * attention.idle_search, tree line seed 220: the drone's first track is lost at the sparse rim,
#   nothing is left to serve, and the paper tracker's search swept the head away (today the head
#   holds);
# * attention.drop_unseen_priority_s, the flock seed 2: the head chased coasting tracks of birds
#   20-40 m from any object for seconds (today they are set aside after 1.5 s unseen);
# * classifier.bird_speed_after_hits, the flock seed 230: bird tracks confirmed on lone returns
#   stayed unknown and took the fovea from the drone;
# * attention.unseen_over_fixations, the flock seed 2 (the first seed tried from 0 on which the
#   head's path differs, by 3.6 deg: a priority's unseen time counted over its fixations);
# * the tracker's own lone_returns (sub-table None), the same run: objects only, the drone was
#   confirmed later;
# * classifier.drone_label_on_hit, tree line seed 39: a crown part's track was labelled drone 0.4 s
#   after its last hit (today the label waits for a hit, which never came).
ADDED_KEYS = [("drone-and-flock", 230, None, {"lone_returns": False}),
              ("drone-and-flock", 230, "classifier", {"bird_speed_after_hits": 0}),
              ("drone-and-flock", 2, "attention", {"unseen_over_fixations": False}),
              ("drone-tree-line", 258, "classifier", {"drone_after_hits": 0, "drone_label_on_hit": False}),
              ("drone-tree-line", 39, "classifier", {"drone_label_on_hit": False}),
              ("two-drones-crossing", 28, "attention", {"saccade_counts_motion": False, "keep_verdict": False}),
              ("drone-tree-line", 220, "attention", {"idle_search": True}),
              ("drone-and-flock", 2, "attention", {"drop_unseen_priority_s": 0.0})]


@pytest.mark.parametrize("name,seed,sub,before", ADDED_KEYS, ids=[f"{k[2] or 'sky'}-{'-'.join(k[3])}" for k in ADDED_KEYS])
def test_a_recording_made_before_a_sky_key_existed_replays_as_it_ran(tmp_path, monkeypatch, name, seed, sub, before):
    # a recording made before the keys ran without them, and a table without them must replay so,
    # not with today's defaults
    from foveatrack.cli import main
    from foveatrack.recording import run_meta
    from foveatrack.sky.controller import recorded_sky_table

    def part(table):            # the sub-table the keys are in (None: the sky table itself)
        return table if sub is None else table[sub]

    scene = tmp_path / f"{name}-before.toml"
    text = (SCENES / f"{name}.toml").read_text()
    assert text.rstrip().endswith("[tracker.sky]")          # the scenes end with it: keys can follow
    scene.write_text(text + ("\n" if sub is None else f"\n[tracker.sky.{sub}]\n")
                     + "".join(f"{k} = {json.dumps(v)}\n" for k, v in before.items()))
    out = tmp_path / "run"
    assert main(["simulate", str(scene), "--seed", str(seed), "--out", str(out),
                 "--no-progress", "--one-thread"]) == 0
    from_dict = run_meta.RecordingMeta.from_dict

    def as_made_before(meta, where="recording"):
        meta = json.loads(json.dumps(meta))
        for k in before:
            del part(meta["sky"])[k]
        return from_dict(meta, where)

    monkeypatch.setattr(run_meta.RecordingMeta, "from_dict", staticmethod(as_made_before))
    res = replay_recording(out / "run.mcap")
    c = res.comparison
    recorded = run_meta.RecordingMeta.from_dict(RecordingReader(out / "run.mcap").meta).sky
    assert not set(before) & set(part(recorded))
    assert {k: part(recorded_sky_table(recorded))[k] for k in before} == before
    # a table that has the keys keeps its own
    own = {k: (not v if isinstance(v, bool) else v + 7) for k, v in before.items()}
    assert {k: part(recorded_sky_table(own if sub is None else {sub: own}))[k] for k in before} == own
    assert c["commands_equal"] and c["tracks"]["identical_all"], c["tracks"]
    # today's defaults on the same frames act differently: the test above can tell
    table = {k: v for k, v in RecordingReader(out / "run.mcap").meta["tracker"].items() if k != "sky"}
    sky = dict(RecordingReader(out / "run.mcap").meta["sky"])
    if sub is None:
        sky = {k: v for k, v in sky.items() if k not in before}
    else:
        sky[sub] = {k: v for k, v in sky[sub].items() if k not in before}
    res_now = replay_recording(out / "run.mcap", tracker_table={**table, "sky": sky}, config_name="today's default")
    assert not (res_now.comparison["commands_equal"] and res_now.comparison["tracks"]["identical_all"])


def test_a_recorded_sky_table_without_the_trackers_own_later_keys_gets_them_as_they_ran():
    # lone_returns (default on since 2026-12-07) came after recordings kept the sky table: a table
    # without it ran without lone returns, and one that has it keeps its own
    from foveatrack.sky.controller import recorded_sky_table
    from foveatrack.sky.tracks import ADDED_SINCE_RECORDED

    assert ADDED_SINCE_RECORDED == {"lone_returns": False}
    assert recorded_sky_table({"gate_max_m": 2.5})["lone_returns"] is False
    assert recorded_sky_table({"lone_returns": True})["lone_returns"] is True
    assert recorded_sky_table({})["classifier"] == {"drone_after_hits": 0, "bird_speed_after_hits": 0,
                                                    "drone_label_on_hit": False, "drone_stays_when_still": False,
                                                    "drone_through_unknown_s": 0.0}
    # and the attention's: a pin held the fovea only since pin_holds_fovea
    assert recorded_sky_table({})["attention"]["pin_holds_fovea"] is False
