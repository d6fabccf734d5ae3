"""Three processes on one machine: the scene's virtual lidar (UDP loopback), the virtual head (pty)
and the daemon.  The daemon must track the scene's UAV, stop on SIGTERM with status 0, and leave a
recording that holds every processed frame and replays to the same detections and commands."""

import json
import os
import socket
import threading
import time

import numpy as np

from gimbal.pts303h import PTS303H
from sim.loop import truth_speed_table
import pytest

from daemon_procs import SCENE, event, first_line, free_udp_port, start, stop_all, terminate, wait_for, write_config
from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording
from sim.virtual_head import read_truth

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")


def _setup(tmp_path, cmd_port=0, data_port=0, loss_rate=0.0):
    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    bport = free_udp_port()
    # The head's own speed curve as the table (what a good calibration of unit 3 gives): these tests
    # are about the processes and the faults, not about an uncalibrated head's drifting world frame.
    table = tmp_path / "unit3.json"
    truth_speed_table(PTS303H(unit_seed=3)).save(table)
    # the head restarted below keeps its pose (a cut link, not a power loss): "keep" trusts the dead reckoning
    cfg = write_config(tmp_path / "d.toml", link, rec, bport, cmd_port, data_port, speed_table=str(table),
                       head_extra='on_reconnect = "keep"')
    procs = {}
    procs["head"] = start(["gimbal", "serve", "--link", str(link), "--truth", str(truth), "--unit-seed", "3"],
                          tmp_path / "head.out", tmp_path / "head.err")
    wait_for(lambda: first_line(tmp_path / "head.out"), 20, "the head's pty", [procs["head"]])
    procs["daemon"] = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out", tmp_path / "d.err")
    # The daemon listens first.  The served scene's clock now starts at the daemon's first sampling
    # anyway; when it started with the serve, a daemon that came late met the UAV seconds into its
    # flight (seen in CI: a first-run compile of the daemon's kernels took 3.6 s, the first frame 3.1 s in).
    wait_for(lambda: event(log, "start"), 30, "the daemon to start", [procs["daemon"]])
    procs["lidar"] = start(["lidar", "serve", str(SCENE), "--cmd-port", "0", "--broadcast-port", str(bport),
                            "--head-truth", str(truth), "--loss-rate", str(loss_rate), "--seed", "5"],
                           tmp_path / "l.out", tmp_path / "l.err")
    # (up to ~20 s of compiling on a fresh install with cold caches, on two busy cores)
    wait_for(lambda: event(log, "lidar_data"), 60, "lidar data at the daemon", list(procs.values()))
    return procs, link, truth, rec, log


def _detections(rec):
    return [r for r in RecordingReader(rec).records("detections")]


def test_three_processes_track_and_replay(tmp_path):
    started_utc_ns = time.time_ns()
    procs, link, truth, rec, log = _setup(tmp_path)
    try:
        time.sleep(6.0)
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
        time.sleep(0.6)     # the head decelerates after the shutdown STOP (dead time + ramp)
    finally:
        stop_all(procs)
    stats = event(log, "stop")["stats"]
    # tracking: the UAV starts 11 deg left of the axis; the head turns and keeps it near the axis
    dets = _detections(rec)
    detected = np.array([d["detected"] for d in dets])
    # Misses belong to acquisition (the first ~1.2 s: the UAV 11 deg off-axis, where a 100 ms rosette
    # frame lays few points on it; 4-7 of the first 15 frames across runs); once on axis, every frame.
    assert stats["frames"] >= 40 and stats["frames_detected"] >= 0.8 * stats["frames"]
    assert detected[15:].mean() >= 0.95, np.flatnonzero(~detected)
    pan_err = np.array([d["error_pan_deg"] for d in dets if d["detected"]])
    assert pan_err[0] > 8.0
    assert np.all(np.abs(pan_err[-10:]) < 4.5), pan_err[-10:]
    rows = read_truth(str(truth))
    assert max(r["pan_deg"] for r in rows) > 5.0          # the head really turned left (truth)
    # The dead reckoning (which places D in the world) agrees with where the head really is: the
    # replayed tracker's pose once the head has settled after the shutdown STOP, against the head's
    # final truth (a mis-timed start-up command once left the tilt 0.85 deg off).
    est_pan, est_tilt = replay_recording(rec).final_pose_deg
    assert abs(est_tilt - rows[-1]["tilt_deg"]) < 0.3 and abs(est_pan - rows[-1]["pan_deg"]) < 1.0
    # shutdown: head stopped, recording complete, every processed frame in it
    assert rows[-1]["pan_speed_deg_s"] == 0.0 and rows[-1]["tilt_speed_deg_s"] == 0.0
    r = RecordingReader(rec)
    ch = r.channels()
    assert r.complete and ch["points"] == stats["frames"] == ch["detections"] and stats["recording_dropped"] == 0
    assert stats["lidar_dropped_total"] == 0
    sources = [c.get("source") for c in r.records("commands")]
    assert sources[-1] == "shutdown" and sources.count("tracker") == stats["frames"]
    assert r.records("commands")[-1]["raw_hex"] == "ff010000000001"   # Pelco-D stop, address 1
    lat = [m["value"] for m in r.records("metrics") if m["name"] == "latency_ms"]
    assert len(lat) == stats["frames"] and np.median(lat) < 100.0
    # log times: the host's clock (UTC) while it ran; the messages keep the Livox clock (seconds
    # since the simulated sensor started), which is what replay reads
    from mcap.reader import make_reader

    with open(rec, "rb") as fh:
        logs = [(c.topic, m.log_time) for _s, c, m in make_reader(fh).iter_messages(topics=["/points", "/head"])]
    assert logs and all(started_utc_ns <= t <= time.time_ns() for _c, t in logs)
    assert r.info["log_time"] == "host_utc"
    frames = list(r.points())
    assert all(0 < f.t_ns < 3600 * 10**9 for f in frames)
    # replay: the same detections and commands, bit for bit
    res = replay_recording(rec)
    assert res.comparison["detections_equal"] and res.comparison["commands_equal"], res.comparison
    assert res.comparison["commands_compared"] == stats["frames"]


def test_faults_head_killed_and_restarted_lossy_lidar_garbage(tmp_path):
    cmd_port, data_port = free_udp_port(), free_udp_port()
    procs, link, truth, rec, log = _setup(tmp_path, cmd_port, data_port, loss_rate=0.1)
    stop = threading.Event()
    sent = {"n": 0}

    def garbage():
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.2", 0))            # a second address on the loopback network
        rng = np.random.default_rng(1)
        while not stop.is_set():
            for port in (data_port, cmd_port):
                s.sendto(rng.integers(0, 256, int(rng.integers(1, 1400)), dtype=np.uint8).tobytes(),
                         ("127.0.0.1", port))
                sent["n"] += 1
            time.sleep(0.01)
        s.close()

    g = threading.Thread(target=garbage, daemon=True)
    g.start()
    try:
        time.sleep(2.5)
        last = read_truth(str(truth))[-1]
        procs["head"].kill()                 # the head's link vanishes (like an unplugged adapter)
        procs["head"].wait(5)
        time.sleep(1.0)
        # the same head comes back on the same link path, where it was (a head keeps its pose)
        procs["head"] = start(["gimbal", "serve", "--link", str(link), "--truth", str(truth), "--unit-seed", "3",
                               "--pan0-deg", f"{last['pan_deg']:.4f}", "--tilt0-deg", f"{last['tilt_deg']:.4f}"],
                              tmp_path / "head2.out", tmp_path / "head2.err")
        wait_for(lambda: first_line(tmp_path / "head2.out"), 20, "the restarted head", [procs["daemon"]])
        wait_for(lambda: event(log, "head_connected"), 5,
                 "the daemon to reopen the head's link", [procs["daemon"]])
        time.sleep(6.0)   # re-acquiring a UAV that drifted ~10 deg off while the head was gone takes 3-4 s under load
        # then the lidar stops: the watchdog must stop the head
        terminate(procs["lidar"])
        wait_for(lambda: event(log, "watchdog_stop"), 5, "the watchdog", [procs["daemon"]])
        time.sleep(0.3)
        assert procs["daemon"].poll() is None
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop.set()
        stop_all(procs)
    stats = event(log, "stop")["stats"]
    assert stats["lidar_foreign_source"] > 0.5 * sent["n"] - 50
    assert 5.0 < stats["lidar_points_missing_pct"] < 15.0, stats["lidar_points_missing_pct"]
    assert stats["head_disconnects"] >= 1 and stats["head_opens"] >= 2
    assert stats["watchdog_trips"] == 1
    lidar_counters = json.loads((tmp_path / "l.out").read_text().splitlines()[-1])
    assert lidar_counters["head_restarts"] >= 1 and lidar_counters["packets_lost"] > 0
    # counters that add up: every slot on the wire is a return or a no-return, and the points lost
    # (missing time slots, the daemon's count) are the packets the lidar dropped (its count) x 100
    assert stats["lidar_wire_points"] == stats["lidar_returns"] + stats["lidar_no_return_points"]
    assert stats["lidar_no_return_points"] > 0
    assert abs(stats["lidar_lost_slots"] - 100 * lidar_counters["packets_lost"]) <= 0.03 * stats["lidar_lost_slots"], \
        (stats["lidar_lost_slots"], lidar_counters["packets_lost"])
    assert 5.0 < stats["lidar_lost_pct"] < 15.0, stats["lidar_lost_pct"]
    # and the end of the run says so on stderr, not in the log's counters alone
    assert "of the lidar's points were lost on the way" in (tmp_path / "d.err").read_text()
    # Recovered: after the restart the daemon's commands reach the head again and it turns right,
    # after the UAV (which drifted ~10 deg right of the axis while the head was gone), and the UAV is
    # detected again.  How fast the error closes is the tracker's business (the paper's controller
    # stops on every empty frame, and 10 deg off-axis with 10 % packet loss about half the frames are
    # empty): under heavy load it took from 2 s to longer than this test runs, so no bound on it here.
    rows2 = read_truth(str(truth))          # the restarted head's own file (it truncates it)
    assert rows2[0]["pan_deg"] == pytest.approx(last["pan_deg"], abs=1e-3)
    assert min(r["pan_deg"] for r in rows2) < last["pan_deg"] - 2.0, (last["pan_deg"], rows2[-1])
    tracker_cmds = [c for c in RecordingReader(rec).records("commands") if c["source"] == "tracker"]
    back = max(c["frame_id"] for c in tracker_cmds if not c["written"]) + 1
    assert sum(d["detected"] for d in _detections(rec)[back:]) >= 5
    cmds = RecordingReader(rec).records("commands")
    assert any(c["source"] == "watchdog" for c in cmds)
    assert any(not c["written"] for c in cmds if c["source"] == "tracker")   # writes failed while it was gone
    res = replay_recording(rec)
    assert res.comparison["detections_equal"] and res.comparison["commands_equal"], res.comparison
