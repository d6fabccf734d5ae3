"""The head's pose checked against the background, through the daemon (issue 26).

A head that loses power behind a live link (the virtual head's SIGUSR1: it comes back at its power-on
pose, 0/0, while its pty stays up) went unnoticed on 802524f: no event, the estimate stayed where
the head had been, the tracker locked onto the ground.  With ``[pose_check]`` on, the background the
lidar sees no longer matches the map the daemon built at start: pose unknown within 2 s, the head
re-homed, tracking resumed with the estimate where the head really is.

Waits are generous (the machine these run on may be loaded): what is asserted is what happened, and
the one bound that is timed -- pose unknown within 2 s of the power cut -- is the issue's.
"""

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from daemon_procs import (event, first_line, free_udp_port, log_events, start, stop_all, terminate, wait_for,
                          write_config)
from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording
from gimbal.pts303h import PTS303H
from sim.loop import truth_speed_table
from sim.virtual_head import read_truth

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")]

YARD = Path(__file__).resolve().parent / "scene_yard.toml"
POSE_CHECK = """
[pose_check]
enabled = true
"""


def _setup(tmp_path, unit_seed=3, table_unit=3, head_extra=""):
    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    bport = free_udp_port()
    table = tmp_path / f"unit{table_unit}.json"
    truth_speed_table(PTS303H(unit_seed=table_unit)).save(table)
    cfg = write_config(tmp_path / "d.toml", link, rec, bport, speed_table=str(table), head_extra=head_extra)
    # D ends short of the yard's trees (x > 20 m), as the scene's own [tracker.space]
    cfg.write_text(cfg.read_text().replace("max_xyz = [60.0, 60.0, 40.0]", "max_xyz = [19.0, 60.0, 40.0]") + POSE_CHECK)
    procs = {"head": start(["gimbal", "serve", "--link", str(link), "--truth", str(truth), "--unit-seed",
                            str(unit_seed)], tmp_path / "head.out", tmp_path / "head.err")}
    wait_for(lambda: first_line(tmp_path / "head.out"), 20, "the head's pty", list(procs.values()))
    procs["daemon"] = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out", tmp_path / "d.err")
    wait_for(lambda: event(log, "start"), 60, "the daemon to start", [procs["daemon"]])
    procs["lidar"] = start(["lidar", "serve", str(YARD), "--cmd-port", "0", "--broadcast-port", str(bport),
                            "--head-truth", str(truth)], tmp_path / "l.out", tmp_path / "l.err")
    wait_for(lambda: event(log, "pose_map"), 120, "the background map", list(procs.values()))
    return procs, truth, rec, log


def _frames(log):
    ev = [e for e in log_events(log) if e["event"] == "progress"]
    return ev[-1]["frames"] if ev else 0


def test_a_head_that_lost_power_behind_a_live_link_is_pose_unknown_within_2_s_and_rehomed(tmp_path):
    procs, truth, rec, log = _setup(
        tmp_path, head_extra='on_reconnect = "home"\nhome_pan_deg = 0.0\nhome_tilt_deg = 0.0\nhome_wait_s = 3.0')
    try:
        # the head turns onto the UAV (11 deg left at start, drifting right): cut its power once it is
        # well beyond the check's bound from its power-on pose
        wait_for(lambda: (rows := read_truth(str(truth))) and abs(rows[-1]["pan_deg"]) > 7.0, 120,
                 "the head to turn 7 deg", list(procs.values()))
        before = read_truth(str(truth))[-1]
        unknown_before = [e for e in log_events(log) if e["event"] == "head_pose_unknown"]
        t_cut = time.monotonic()
        procs["head"].send_signal(signal.SIGUSR1)
        wait_for(lambda: "power cycled" in (tmp_path / "head.err").read_text(), 10, "the power cut", [procs["head"]])
        got = wait_for(lambda: next((e for e in log_events(log) if e["event"] == "head_pose_unknown"), None),
                       60, "pose unknown", [procs["daemon"]])
        wait_for(lambda: event(log, "head_homed"), 60, "the head homed", [procs["daemon"]])
        f0 = _frames(log)
        wait_for(lambda: _frames(log) >= f0 + 60, 120, "60 frames after homing", [procs["daemon"], procs["lidar"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
        time.sleep(0.6)
    finally:
        stop_all(procs)
    assert not unknown_before and abs(before["pan_deg"]) > 7.0
    # the head's own table: the background never called it another unit's
    assert not [e for e in log_events(log) if e["event"] == "warning" and "speed table" in e["message"]]
    # no mismatch before the cut: the check said nothing wrong of a head that was where it was told
    events = log_events(log)
    assert got["why"] == "pose_check", got
    mismatch = next(e for e in events if e["event"] == "pose_mismatch")
    assert abs(mismatch["dpan_deg"]) > 3.0 or mismatch["match"] < 0.6, mismatch
    # the bound: pose unknown within 2 s of the power cut
    assert got["t_mono_s"] - t_cut <= 2.0, got["t_mono_s"] - t_cut
    stats = event(log, "stop")["stats"]
    assert stats["head_pose_unknown"] == 1 and stats["head_homed"] == 1, stats
    assert stats["pose_checks_ok"] >= 3 and stats["frames_mapping"] >= 10, stats
    # after the homing the estimate agrees with where the head really is: compared at rest, the dead
    # reckoning carried through the shutdown STOP by replay (equal to the run to the bit, below); the
    # last frame's estimate is not where the head stopped (it may still be turning then)
    rows = read_truth(str(truth))
    r = RecordingReader(rec)
    res = replay_recording(rec)
    est_pan, est_tilt = res.final_pose_deg
    err_pan, err_tilt = est_pan - rows[-1]["pan_deg"], est_tilt - rows[-1]["tilt_deg"]
    print(f"true error after recovery: pan {err_pan:+.2f} deg, tilt {err_tilt:+.2f} deg; pose unknown "
          f"{got['t_mono_s'] - t_cut:.2f} s after the cut; head at {before['pan_deg']:.1f} deg before it")
    assert abs(err_pan) < 1.0 and abs(err_tilt) < 0.5, ((est_pan, est_tilt), rows[-1])
    # and tracking resumed on the UAV (inside D, ~12 m away), not the ground or a tree
    homed = [e for e in r.records("daemon") if e.get("event") == "tracker_rebased" and e["reason"] == "head_homed"]
    dets = [d for d in r.records("detections") if d["detected"]]
    after = [d for d in dets if d["t_ns"] * 1e-9 > homed[-1]["t0_s"]]
    assert len(after) >= 10 and all(np.linalg.norm(d["xyz_m"]) < 16.0 for d in dets)
    # replay repeats the corrections and the homing: the same detections and commands
    c = res.comparison
    assert not c["partial"] and c["detections_equal"] and c["commands_equal"], c


def test_a_speed_table_of_another_unit_is_a_warning_within_a_minute(tmp_path):
    # issue 26: a unit-3 table on a unit-7 head ran 30 s with pan 8.6 deg off and no warning
    procs, truth, rec, log = _setup(tmp_path, unit_seed=7, table_unit=3)
    try:
        t_map = event(log, "pose_map")["t_mono_s"]
        warn = wait_for(lambda: next((e for e in log_events(log) if e["event"] == "warning"
                                      and "speed table" in e["message"]), None), 120, "the speed-table warning",
                        list(procs.values()))
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    print(f"warned {warn['t_mono_s'] - t_map:.1f} s after the map: {warn['message']}")
    assert warn["t_mono_s"] - t_map <= 60.0, warn
    # unit 7 turns faster than unit 3 at the low bytes a tracker uses: the table's speeds are too low
    assert warn["table_error_rel"] < -0.1, warn
    assert event(log, "stop")["stats"].get("pose_checks_mismatch", 0) == 0


def test_a_link_recreated_to_another_head_is_refused_once_the_background_says_so(tmp_path):
    # issue 26: the link re-created to a different head (unit 7) was connected within a second and driven
    # (97 commands, 14.5 deg).  Our lidar sits on our head: the other head's homing moves nothing it sees.
    procs, truth, rec, log = _setup(
        tmp_path, head_extra='on_reconnect = "home"\nhome_pan_deg = 0.0\nhome_tilt_deg = 0.0\nhome_wait_s = 3.0')
    try:
        wait_for(lambda: (rows := read_truth(str(truth))) and abs(rows[-1]["pan_deg"]) > 7.0, 120,
                 "the head to turn 7 deg", list(procs.values()))
        procs["head"].kill()              # our head's link goes (its pose stays where it was: the lidar sees it)
        procs["head"].wait(5)
        time.sleep(1.0)
        procs["other"] = start(["gimbal", "serve", "--link", str(tmp_path / "head"), "--truth",
                                str(tmp_path / "other.jsonl"), "--unit-seed", "7"], tmp_path / "o.out", tmp_path / "o.err")
        refused = wait_for(lambda: event(log, "head_identity_refused"), 90, "the refusal", [procs["daemon"]])
        n = len([e for e in log_events(log) if e["event"] == "progress"])
        wait_for(lambda: len([e for e in log_events(log) if e["event"] == "progress"]) >= n + 3, 60,
                 "3 s more of the daemon", [procs["daemon"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    events = log_events(log)
    names = [e["event"] for e in events]
    # the link came back (the re-created link names "the head" to the device check), was homed, and the
    # first check after the homing found the lidar where the other head's move could not have put it
    assert names.index("head_connected") < names.index("head_homed") < names.index("head_identity_refused")
    assert "not the one the lidar sits on" in refused["why"] and str(tmp_path / "head") in refused["why"]
    assert abs(refused["dpan_deg"]) > 3.0 or refused["match"] < 0.6, refused
    assert not [e for e in events if e["event"] == "head_identity" and e.get("verified")]
    assert "not the one the lidar sits on" in (tmp_path / "d.err").read_text()
    # nothing written to the other head after the refusal: no tracking, no STOP, not at shutdown either
    stats = event(log, "stop")["stats"]
    assert stats["head_frames_sent"] == refused["frames_sent"], (stats["head_frames_sent"], refused["frames_sent"])
    assert stats["head_identity_refused"] == 1
    # what it did get: the homing's STOP and two absolute sets, and no tracker command
    other = read_truth(str(tmp_path / "other.jsonl"))
    assert max(abs(r["pan_deg"]) for r in other) < 0.5, "the other head was not turned by tracking"


def test_the_same_head_back_on_its_link_is_verified_by_the_background_and_tracked_again(tmp_path):
    # the counterpart of the refusal: our own head restarted (at its power-on pose) behind the link; the
    # homing moves the lidar, and the background agrees
    procs, truth, rec, log = _setup(
        tmp_path, head_extra='on_reconnect = "home"\nhome_pan_deg = 0.0\nhome_tilt_deg = 0.0\nhome_wait_s = 3.0')
    try:
        wait_for(lambda: (rows := read_truth(str(truth))) and abs(rows[-1]["pan_deg"]) > 7.0, 120,
                 "the head to turn 7 deg", list(procs.values()))
        procs["head"].kill()
        procs["head"].wait(5)
        time.sleep(1.0)
        procs["head"] = start(["gimbal", "serve", "--link", str(tmp_path / "head"), "--truth", str(truth),
                               "--unit-seed", "3"], tmp_path / "head2.out", tmp_path / "head2.err")
        ok = wait_for(lambda: next((e for e in log_events(log) if e["event"] == "head_identity"), None), 90,
                      "the head's identity", [procs["daemon"]])
        f0 = _frames(log)
        wait_for(lambda: _frames(log) >= f0 + 30, 120, "30 frames after it", [procs["daemon"], procs["lidar"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    assert ok["verified"] and ok["by"] == "pose_check", ok
    names = [e["event"] for e in log_events(log)]
    assert "head_identity_refused" not in names and names.index("head_homed") < names.index("head_identity")
    stats = event(log, "stop")["stats"]
    assert stats["frames"] > 0 and stats.get("pose_checks_mismatch", 0) == 0
    assert stats["commands_written"] > 0


def test_after_a_power_cut_the_head_is_homed_to_the_targets_bearing_and_tracks_again_within_seconds(tmp_path):
    """Issue 26: after a head restart the daemon waited the worst case blind (58 s in the shipped
    example) at home, and the UAV had left the home view.  Now the head goes to where the tracker last
    saw the UAV while its pose was trusted, and the pose check ends the wait once the background shows
    the head there at rest.  Counted: frames detected in the 100 frames after the pose became unknown
    (on 621f5c0, with the same default wait: 0)."""
    procs, truth, rec, log = _setup(tmp_path, head_extra='on_reconnect = "home"\nhome_pan_deg = 0.0\nhome_tilt_deg = 0.0')
    try:
        wait_for(lambda: (rows := read_truth(str(truth))) and abs(rows[-1]["pan_deg"]) > 7.0, 120,
                 "the head to turn 7 deg", list(procs.values()))
        procs["head"].send_signal(signal.SIGUSR1)
        wait_for(lambda: "power cycled" in (tmp_path / "head.err").read_text(), 10, "the power cut", [procs["head"]])
        wait_for(lambda: event(log, "head_pose_unknown"), 60, "pose unknown", [procs["daemon"]])
        # 100 frames and more (sensor time) after the pose became unknown
        t_unknown = event(log, "head_pose_unknown")["t_mono_s"]
        t_u = max(e["sensor_t_s"] or 0.0 for e in log_events(log) if e["event"] == "progress" and e["t_mono_s"] <= t_unknown)

        def sensor_t():
            ev = [e for e in log_events(log) if e["event"] == "progress"]
            return ev[-1]["sensor_t_s"] or 0.0
        wait_for(lambda: sensor_t() >= t_u + 11.0, 240, "11 s of frames after", [procs["daemon"], procs["lidar"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    r = RecordingReader(rec)
    unknown = next(e for e in r.records("daemon") if e.get("event") == "head_pose_unknown")
    t0_ns = unknown["t_ns"]
    # the 10 s (100 frame periods) of sensor time after it; frames not tracked are not recorded
    window = [d for d in r.records("detections") if t0_ns < d["t_ns"] <= t0_ns + 10_000_000_000]
    pts = [p.t_ns for p in r.points() if p.t_ns > t0_ns + 10_000_000_000]
    detected = sum(d["detected"] for d in window)
    stats = event(log, "stop")["stats"]
    events = log_events(log)
    plan = next((e for e in events if e["event"] == "head_homing_plan"), None)
    homed = next((e for e in events if e["event"] == "head_homed"), None)
    blind_s = None if homed is None else homed["t_mono_s"] - event(log, "head_pose_unknown")["t_mono_s"]
    print(f"power cut: {detected} of the 100 frame periods after pose unknown detected; plan {plan}; "
          f"blind {blind_s} s; head_homed {stats.get('head_homed', 0)}; frames_pose_unknown "
          f"{stats.get('frames_pose_unknown')}")
    assert pts, "the run ended within 10 s of the power cut"
    assert plan is not None and plan["goal"] == "last_bearing", plan
    assert abs(plan["pan_deg"]) > 5.0, plan                      # not home: where the UAV was
    assert event(log, "head_homing_confirmed") is not None
    # blind for the move and three checks at rest (seen: 24 frames), not the worst case (41 s to there)
    assert stats["frames_pose_unknown"] <= 80, stats["frames_pose_unknown"]
    # and tracking again once the pose is confirmed: most of the frames after the blind ones have a
    # detection.  (A bar of 40 of the 100 held only while the blind part stayed under ~55 frames,
    # tighter than the bound above: beside two busy loops a check at rest is now and then repeated,
    # blind 6.4-7.6 s in 4 of 17 runs, one of them on 5595742's code; after it 22 of 24, 24 of 26,
    # 25 of 32 and 27 of 35 frames were detected.)
    after = 100 - stats["frames_pose_unknown"]
    assert detected >= 0.7 * after, (detected, after)
    # the estimate agrees with the head after all that (at rest, as above), and replay repeats the run
    rows = read_truth(str(truth))
    res = replay_recording(rec)
    est_pan, est_tilt = res.final_pose_deg
    assert abs(est_pan - rows[-1]["pan_deg"]) < 1.0 and abs(est_tilt - rows[-1]["tilt_deg"]) < 0.5, (
        (est_pan, est_tilt), rows[-1])
    c = res.comparison
    assert not c["partial"] and c["detections_equal"] and c["commands_equal"], c
