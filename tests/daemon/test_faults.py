"""The daemon against what real devices do (issue 16), through the real processes: the virtual head
(``gimbal serve``), the virtual lidar (``lidar serve``) and the daemon, all on loopback.

Recovery is judged in sensor time and by counts (frames, detections), never by wall-clock luck: the
machine these run on is shared and busy."""

import math
import os
import socket
import threading
import time

import numpy as np
import pytest

from daemon_procs import (SCENE, event, first_line, free_udp_port, head_clock_zero, log_events, start, stop_all,
                          terminate, wait_for, write_config)
from foveatrack.livox.protocol import encode_data_packets
from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording
from gimbal.pts303h import PTS303H
from sim.loop import truth_speed_table
from sim.virtual_head import read_truth

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")]


def _head(tmp_path, link, truth, name="head", extra=()):
    p = start(["gimbal", "serve", "--link", str(link), "--truth", str(truth), "--unit-seed", "3", *extra],
              tmp_path / f"{name}.out", tmp_path / f"{name}.err")
    wait_for(lambda: first_line(tmp_path / f"{name}.out"), 20, f"the {name}'s pty", [p])
    return p


def _lidar(tmp_path, bport, truth, name="l"):
    return start(["lidar", "serve", str(SCENE), "--cmd-port", "0", "--broadcast-port", str(bport),
                  "--head-truth", str(truth)], tmp_path / f"{name}.out", tmp_path / f"{name}.err")


def _setup(tmp_path, data_port=0, speed_table=None, head_extra=(), config_extra="", recording_extra=""):
    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    bport = free_udp_port()
    if speed_table is None:
        speed_table = tmp_path / "unit3.json"
        truth_speed_table(PTS303H(unit_seed=3)).save(speed_table)
    cfg = write_config(tmp_path / "d.toml", link, rec, bport, 0, data_port, speed_table=str(speed_table),
                       recording_extra=recording_extra)
    if config_extra:
        txt = cfg.read_text()
        cfg.write_text(txt.replace("[tracker]\n", config_extra + "\n[tracker]\n", 1))
    procs = {"head": _head(tmp_path, link, truth, extra=head_extra)}
    procs["daemon"] = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out", tmp_path / "d.err")
    wait_for(lambda: event(log, "start"), 60, "the daemon to start", [procs["daemon"]])
    procs["lidar"] = _lidar(tmp_path, bport, truth)
    wait_for(lambda: event(log, "lidar_data"), 60, "lidar data at the daemon", list(procs.values()))
    return procs, link, truth, rec, log, bport


def _wait_frames(log_path, rec_path, n, procs, timeout_s=90):
    """Wait until the daemon's log says it processed ``n`` more frames (progress events)."""
    def frames():
        ev = [e for e in log_events(log_path) if e["event"] == "progress"]
        return ev[-1]["frames"] if ev else 0
    f0 = frames()
    wait_for(lambda: frames() >= f0 + n, timeout_s, f"{n} more frames", procs)


def _detections(rec):
    return RecordingReader(rec).records("detections")


def _replays_to_the_bit(rec):
    """Replay re-enacts the daemon's rebases (``tracker_rebased``): without them the replayed dead
    reckoning runs on across a new clock or a homing, and detections and commands part from the run."""
    res = replay_recording(rec)
    c = res.comparison
    assert not c["partial"], c
    assert c["detections_equal"] and c["commands_equal"], {k: c[k] for k in (
        "frames_detection_differs", "frames_command_differs") if k in c}
    return res


#: fig12's acquisition in this scene, from its own start (the head at the scene's pan0/tilt0, the UAV
#: 11.3 deg left and 4.2 deg up, crossing right at 2.3 deg/s): the closed-loop simulator (sim.loop.ClosedLoop
#: on SCENE, seeds 12-43) detects it in every frame from 1.7 s on at the latest (from 0.2-1.0 s in most
#: seeds; the paper scene's acquisition is 1.4 s, docs/tracker.md), and in >= 93 % of the 30 frames after
#: the bound below from any start pan -9..7 deg (16 seeds each).
FIG12_HELD_S = 1.7


def _held_bound(pan_deg: float) -> tuple[float, float, float]:
    """When the restarted scene's UAV is held at the latest, for a head at pan ``pan_deg`` at the
    new clock's start: ``(held_s, off_deg, rate_deg_s)``.

    The paper's controller moves the head only on a frame with a detection and stops it on every empty
    one (``HOLDING``), so at the rim of the Mid-40's rosette, where a 0.35 m UAV at 12 m is in 27-50 %
    of the frames (within 4 deg of the axis: 99 %; the simulator, the head held still), the head's
    speed is not what limits the acquisition: the detections are (from 16-19 deg off the simulator
    holds it from 0.7-4.1 s, from fig12's start by 1.7 s).  What is sure is the UAV's own crossing: it
    flies toward a stopped head's axis at ``rate_deg_s`` (at least), and the head only ever turns
    toward it, so it is no farther off than fig12's start (``off_fig12``) after
    ``(off - off_fig12) / rate``, and still closing: from there fig12's acquisition (``FIG12_HELD_S``)
    bounds the rest."""
    from sim.scene import load_scene

    scene = load_scene(SCENE)
    traj = scene.targets[0].trajectory
    t = np.arange(0.0, 10.05, 0.05)                      # the bound (<= 6 s) and 3 s after it
    xyz = traj.position(t)
    az = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))      # pan of the UAV's bearing (left +)
    rate = np.diff(az) / np.diff(t)
    off, off_fig12 = az[0] - pan_deg, az[0] - scene.gimbal.pan0_deg
    slowest = float(np.min(np.abs(rate)))
    if abs(off) <= abs(off_fig12):
        return FIG12_HELD_S, float(off), slowest
    # farther off than fig12's start: the extra time counts on the UAV flying toward the head's axis.
    # It does: the old run's last commands turned the head right, after the UAV, and the restarted
    # UAV, back at 11.3 deg left, is left of it and flies right
    assert np.all(np.sign(rate) == -np.sign(off)), (pan_deg, off)
    return FIG12_HELD_S + float(abs(off) - abs(off_fig12)) / slowest, float(off), slowest


def test_fault1_a_restarted_lidar_is_tracked_again(tmp_path):
    procs, link, truth, rec, log, bport = _setup(tmp_path)
    try:
        _wait_frames(log, rec, 30, list(procs.values()))
        procs["lidar"].kill()              # power cut: the lidar's clock will start again from 0
        procs["lidar"].wait(5)
        time.sleep(1.0)
        procs["lidar"] = _lidar(tmp_path, bport, truth, "l2")
        rebased = wait_for(lambda: event(log, "tracker_rebased"), 60, "the daemon to re-anchor the new clock",
                           [procs["daemon"], procs["lidar"]])
        held_s, off, rate = _held_bound(rebased["pan_deg"])
        # 3 s of frames from the bound on to judge the hold by
        _wait_frames(log, rec, max(60, math.ceil(held_s * 10) + 31), [procs["daemon"], procs["lidar"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    stats = event(log, "stop")["stats"]
    # said on stderr as it happened (no status line here: stderr is a file)
    err = (tmp_path / "d.err").read_text()
    assert "WARNING: no lidar packet for" in err and "the head is stopped until the lidar comes back" in err, err
    assert "the lidar is back after" in err, err
    jump = event(log, "lidar_clock_jump")
    assert jump is not None and jump["new_t_s"] < jump["last_t_s"], jump      # the clock went back
    assert stats["lidar_clock_jumps"] == 1 and stats["clock_epochs"] == 1
    # The head runs its last command until the watchdog stops it (2 s here): a pan command's 5-6 deg/s
    # carries it 11-13 deg on while the lidar is silent (seen: from 4-6 deg to -4.8 .. -8.6 deg).
    # The new tracker starts where the head really is, that run-on included (seen: within 0.12 deg):
    # the head is at rest when the daemon re-anchors (stopped by the watchdog >= 0.4 s before).
    zero = float(head_clock_zero(tmp_path / "head.err"))
    at_rest = [r for r in read_truth(str(truth)) if r["t_s"] + zero <= rebased["t_mono_s"]][-1]
    assert at_rest["pan_speed_deg_s"] == 0.0 and at_rest["tilt_speed_deg_s"] == 0.0, at_rest
    assert abs(rebased["pan_deg"] - at_rest["pan_deg"]) < 0.5, (rebased, at_rest)
    assert abs(rebased["tilt_deg"] - at_rest["tilt_deg"]) < 0.5, (rebased, at_rest)
    dets = _detections(rec)
    t = np.array([d["t_ns"] for d in dets]) * 1e-9
    back = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1          # the first frame of the new clock
    after = dets[back:]
    detected = np.array([d["detected"] for d in after])
    t_new = t[back:]                                           # sensor time = the restarted scene's time
    # tracked again within 2 s of its return (sensor time, i.e. frames of the new clock; seen: by its
    # 9th frame, also from the rim)
    first = int(np.argmax(detected))
    assert detected[first] and t_new[first] - t_new[0] <= 2.0, first
    # and held from the bound on (_held_bound: where the restarted UAV is off the head, how fast it
    # crosses, fig12's own acquisition).  Between the first detection and the bound the UAV may be
    # lost for seconds at the rim (seen: 2.4 s, from 16 deg off): that is the paper's controller there.
    window = detected[t_new >= held_s + 0.1 - 1e-6][:30]       # frames that start at or after held_s
    assert len(window) == 30 and window.mean() >= 0.9, (
        f"UAV {off:.1f} deg off the head at the restart, closing at {rate:.2f} deg/s: held from "
        f"{held_s:.2f} s", "".join(str(int(d)) for d in detected))
    # and nothing of the new clock was thrown away as late
    assert stats["slicer_late_points"] < 1000, stats["slicer_late_points"]
    _replays_to_the_bit(rec)


def test_fault2_packets_with_wrong_times_are_dropped_and_tracking_holds(tmp_path):
    data_port = free_udp_port()
    procs, link, truth, rec, log, bport = _setup(tmp_path, data_port=data_port)
    stop = threading.Event()
    sent = {"n": 0}

    def bad_packets():
        # well-formed Mid-40 packets from the lidar's own address with random times, ~2 % of its
        # 1000 packets/s, and one stamped 20 s ahead of the stream
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        rng = np.random.default_rng(7)
        xyz = np.tile([[5.0, 0.0, -1.5]], (100, 1))
        while not stop.is_set():
            t0 = int(rng.integers(0, 2**62))
            if sent["n"] == 50:
                ev = event(log, "progress") or {}
                t0 = int((ev.get("sensor_t_s") or 0.0) * 1e9 + 20e9)
            (pkt,) = encode_data_packets(xyz, np.full(100, 20, np.uint8), t0, 100_000.0, data_type=0)
            s.sendto(pkt, ("127.0.0.1", data_port))
            sent["n"] += 1
            time.sleep(0.05)
        s.close()

    g = threading.Thread(target=bad_packets, daemon=True)
    try:
        _wait_frames(log, rec, 20, list(procs.values()))
        g.start()
        _wait_frames(log, rec, 60, list(procs.values()))
        stop.set()
        g.join(5)
        assert procs["daemon"].poll() is None, (tmp_path / "d.err").read_text()
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop.set()
        stop_all(procs)
    stats = event(log, "stop")["stats"]
    assert sent["n"] >= 50
    # counted (a bad packet landing beside another is one segment with it: at least nearly all)
    assert 0.9 * sent["n"] <= stats["lidar_bad_time_segments"] <= sent["n"], (stats["lidar_bad_time_segments"], sent)
    assert stats.get("lidar_clock_jumps", 0) == 0 and stats.get("clock_epochs", 0) == 0
    assert stats.get("frames_skipped", 0) <= 3
    dets = _detections(rec)
    detected = np.array([d["detected"] for d in dets])
    assert detected[20:].mean() >= 0.9, np.flatnonzero(~detected)
    t = np.array([d["t_ns"] for d in dets])
    assert np.all(np.diff(t) == 100_000_000)      # every frame, in order, none lost to a wild time


def test_fault3_a_pty_that_took_the_heads_old_number_gets_no_byte(tmp_path):
    procs, link, truth, rec, log, bport = _setup(tmp_path, config_extra='on_reconnect = "keep"')
    held = []
    try:
        _wait_frames(log, rec, 20, list(procs.values()))
        old = os.readlink(link)
        procs["head"].kill()               # the head dies; its link is left behind, naming its pty
        procs["head"].wait(5)
        wait_for(lambda: event(log, "head_disconnected"), 30, "the daemon to lose the head", [procs["daemon"]])
        time.sleep(0.05)
        other = None
        for _ in range(64):                # another program takes a pty: the lowest free number
            m, s = os.openpty()
            held.append((m, s))
            if os.ttyname(s) == old:
                other = m
                break
        if other is None:
            pytest.skip(f"{old} was not handed out again (other programs hold ptys)")
        os.set_blocking(other, False)
        wait_for(lambda: event(log, "head_refused"), 30, "the daemon to refuse the other pty", [procs["daemon"]])
        _wait_frames(log, rec, 20, [procs["daemon"]])   # 2 s of frames, each wanting to write a command
        got = b""
        try:
            got = os.read(other, 4096)
        except BlockingIOError:
            pass
        assert got == b"", f"{len(got)} bytes written to another program's pty"
        refused = event(log, "head_refused")
        assert old in refused["reason"] and "not re-created" in refused["reason"], refused
        # the head comes back (its server re-creates the link): the daemon drives it again
        procs["head"] = _head(tmp_path, link, truth, "head2")
        wait_for(lambda: event(log, "head_connected"), 30, "the daemon to reopen the head", [procs["daemon"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        for m, s in held:
            os.close(m), os.close(s)
        stop_all(procs)
    stats = event(log, "stop")["stats"]
    assert stats["head_open_refusals"] >= 1


def test_fault4_a_head_back_at_its_power_on_pose_is_homed_before_tracking_resumes(tmp_path):
    # the restarted head comes back at 0/0 (its power-on pose); home is pan -6 deg (right, where the
    # UAV goes): the absolute move must really happen for the dead reckoning to agree with the head
    procs, link, truth, rec, log, bport = _setup(
        tmp_path, config_extra='on_reconnect = "home"\nhome_pan_deg = -6.0\nhome_tilt_deg = 0.0\nhome_wait_s = 3.0')
    try:
        _wait_frames(log, rec, 30, list(procs.values()))
        before = read_truth(str(truth))[-1]
        procs["head"].kill()
        procs["head"].wait(5)
        time.sleep(1.0)
        procs["head"] = _head(tmp_path, link, truth, "head2")          # at 0/0
        wait_for(lambda: event(log, "head_pose_unknown"), 30, "pose unknown", [procs["daemon"]])
        wait_for(lambda: event(log, "head_homed"), 60, "the head homed", [procs["daemon"]])
        _wait_frames(log, rec, 70, [procs["daemon"], procs["lidar"]])
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
        time.sleep(0.6)
    finally:
        stop_all(procs)
    stats = event(log, "stop")["stats"]
    assert abs(before["pan_deg"]) > 3.0, before          # the head had turned before it died
    assert stats["head_pose_unknown"] == 1 and stats["head_homed"] == 1 and stats["frames_pose_unknown"] > 0
    rows = read_truth(str(truth))                         # the restarted head's own truth
    r = RecordingReader(rec)
    cmds = r.records("commands")
    # no tracker command reached the head between its return and the end of homing
    homed_events = [e for e in r.records("daemon") if e.get("event") == "tracker_rebased"]
    assert homed_events and homed_events[-1]["reason"] == "head_homed"
    # the dead reckoning agrees with where the head really is (a wrong pose once locked onto the ground).
    # Compared at rest: the head runs on after the last frame until the shutdown STOP and its ramp
    # (up to 3.7 deg at 15 deg/s), so the last frame's estimate is not where the head stopped; replay,
    # equal to the run to the bit (asserted here), carries the dead reckoning through the STOP to rest.
    pan_rest, tilt_rest = _replays_to_the_bit(rec).final_pose_deg
    assert abs(pan_rest - rows[-1]["pan_deg"]) < 1.0, ((pan_rest, tilt_rest), rows[-1])
    assert abs(tilt_rest - rows[-1]["tilt_deg"]) < 0.5, ((pan_rest, tilt_rest), rows[-1])
    # tracking resumed: the UAV detected again after the homing, inside D (not the ground)
    dets = RecordingReader(rec).records("detections")
    t_home = homed_events[-1]["t0_s"]
    after = [d for d in dets if d["t_ns"] * 1e-9 > t_home]
    errs = [abs(d["error_pan_deg"]) for d in after if d["detected"]]
    assert len(errs) >= 10, errs
    # the UAV drifted on while the head was down and homing: the homing looked for it where it would be
    # when tracking resumed (0.2-3.4 deg off in 5 runs; looked for where it was when the plan was made,
    # it was 10-12 deg off, at the rim, and the paper's controller, stopping on every empty frame, took
    # over 7 s to bring it in), and the head stays on it
    assert np.median(errs[:5]) < 5.0 and min(errs[-3:]) < 5.0, errs
    # the UAV is ~12 m away; nothing else is taken for it, also while the head was gone (frames are not
    # tracked from the moment its link was lost: a dead-reckoned world without a head once saw 23-32 m)
    assert all(np.linalg.norm(d["xyz_m"]) < 20.0 for d in dets if d["detected"])
    assert any(c["source"] == "tracker" and c["written"] for c in cmds)


def test_fault5_a_nominal_speed_table_is_a_warning_at_start_in_the_log_and_the_status(tmp_path):
    from foveatrack.daemon import Daemon, load_config

    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    cfg = write_config(tmp_path / "d.toml", link, rec, free_udp_port(), speed_table="nominal")
    head = _head(tmp_path, link, truth)
    try:
        d = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out", tmp_path / "d.err")
        wait_for(lambda: event(log, "start"), 60, "the daemon to start", [d])
        # no lidar in this test: "no lidar data arrived" (3), or 0 where the stop came within the 3 s a
        # Livox may take to announce itself (RunStats.stopped_before_data)
        assert terminate(d) in (0, 3)
    finally:
        stop_all({"head": head})
    err = (tmp_path / "d.err").read_text()
    assert "WARNING" in err and 'speed_table = "nominal"' in err and "uncalibrated" in err and str(cfg) in err, err
    assert "foveatrack calibrate" in event(log, "warning")["message"]
    notes = Daemon(load_config(cfg), status=False, install_signals=False).status_notes()
    assert any("UNCALIBRATED" in n for n in notes)
    # a calibrated table: no warning (the shipped example has one, for its virtual unit 3)
    cfg2 = write_config(tmp_path / "d2.toml", link, rec, 0, speed_table=str(tmp_path / "t.json"))
    truth_speed_table(PTS303H(unit_seed=3)).save(tmp_path / "t.json")
    assert load_config(cfg2).warnings() == []
    from daemon_procs import ROOT
    ex = load_config(ROOT / "examples" / "daemon-virtual.toml")
    assert ex.warnings() == []
    truth3 = truth_speed_table(PTS303H(unit_seed=3))
    for axis in ("pan", "tilt"):     # the shipped table is unit 3's, within the calibration's 2 %
        got, want = getattr(ex.speed_table(), axis).speeds_array()[0], getattr(truth3, axis).speeds_array()[0]
        assert abs(got[63] / want[63] - 1) < 0.02 and abs(got[32] / want[32] - 1) < 0.02, (axis, got[63], want[63])


def test_fault6_a_killed_daemon_journaled_every_frame_its_head_got_and_logged_its_progress(tmp_path):
    """kill -9 (issue 16, fault 6): the frame in flight reached the head but not the recording, and the
    log held only 'start'.  The head here is a bare pty whose every byte the test reads."""
    master, slave = os.openpty()
    os.set_blocking(master, False)
    link = tmp_path / "head"
    os.symlink(os.ttyname(slave), link)
    rec, log = tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    cfg = write_config(tmp_path / "d.toml", link, rec, free_udp_port(), speed_table=str(tmp_path / "t.json"))
    truth_speed_table(PTS303H(unit_seed=3)).save(tmp_path / "t.json")
    got = bytearray()

    def drain():
        try:
            while True:
                got.extend(os.read(master, 4096))
        except (BlockingIOError, OSError):
            pass

    d = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out", tmp_path / "d.err")
    try:
        wait_for(lambda: event(log, "start"), 60, "the daemon to start", [d])
        # no lidar: the daemon stops the head at start and every second; wait for 3 progress events
        wait_for(lambda: (drain(), len([e for e in log_events(log) if e["event"] == "progress"]) >= 3)[1], 60,
                 "progress in the log", [d])
        d.kill()
        d.wait(10)
        drain()
    finally:
        if d.poll() is None:
            d.kill()
        os.close(master), os.close(slave)
    journal = [__import__("json").loads(x) for x in (tmp_path / "rec.mcap.commands.jsonl").read_text().splitlines()]
    sent = b"".join(bytes.fromhex(j["raw_hex"]) for j in journal)
    assert len(got) >= 14 and len(got) % 7 == 0          # whole Pelco-D frames, at least two STOPs
    assert sent[:len(got)] == bytes(got) and len(sent) - len(got) <= 7, (len(sent), len(got))
    prog = [e for e in log_events(log) if e["event"] == "progress"]
    assert prog[-1]["frames"] == 0 and "commands_written" in prog[-1]


def _journal_lines(path):
    import json

    return [json.loads(x) for x in path.read_text().splitlines()]


def _official_mcap_commands(path):
    """The /commands messages as the mcap package reads them (an error there fails the test)."""
    import json

    from mcap.reader import make_reader

    with open(path, "rb") as f:
        r = make_reader(f)
        s = r.get_summary()
        assert s is not None and s.statistics is not None, "no summary: the file is not complete"
        return [json.loads(m.data) for _s, c, m in r.iter_messages() if c.topic == "/commands"]


def test_fault6_a_killed_daemons_recording_is_completed_from_its_journal(tmp_path):
    """kill -9 while tracking over the virtual devices: the recording lacks the last frames' commands
    the head got (fault 6).  ``foveatrack recover`` completes it, and so does the daemon's next start
    with the same recording directory; the official mcap reader reads it whole, every journaled
    command is in it, and replay takes it."""
    import json
    import shutil
    import subprocess
    import sys

    from daemon_procs import ROOT, env

    procs, link, truth, rec, log, bport = _setup(tmp_path)
    journal = tmp_path / "rec.mcap.commands.jsonl"
    try:
        _wait_frames(log, rec, 30, list(procs.values()))
        procs["daemon"].kill()
        procs["daemon"].wait(10)
        lines = _journal_lines(journal)
        cut = RecordingReader(rec)
        n_recorded = len(cut.records("commands"))
        assert not cut.closed() and n_recorded < len(lines), (n_recorded, len(lines))
        with pytest.raises(Exception):
            _official_mcap_commands(rec)          # what kill -9 left: no summary
        # by hand, on a copy
        manual = tmp_path / "manual"
        manual.mkdir()
        shutil.copy2(rec, manual / "rec.mcap")
        shutil.copy2(journal, manual / "rec.mcap.commands.jsonl")
        out = subprocess.run([sys.executable, "-m", "foveatrack", "recover", str(manual / "rec.mcap")], cwd=ROOT,
                             env=env(), capture_output=True, text=True, timeout=300)
        assert out.returncode == 0 and "recovered:" in out.stdout, out
        assert "was killed: the head is where that run left it" in out.stderr, out.stderr   # as the daemon says
        cmds = _official_mcap_commands(manual / "rec.mcap")
        assert len(cmds) == len(lines), (len(cmds), len(lines))
        assert [c["raw_hex"] for c in cmds if not c.get("journal_only")] == \
            [j["raw_hex"] for j in lines if j["source"] not in ("", "homing")]
        added = [c for c in cmds if c.get("from_journal") and not c.get("journal_only")]
        assert added and all(c["source"] == "tracker" for c in added), added
        print(f"kill -9: {len(lines)} journal lines, {n_recorded} commands recorded, {len(added)} put back")
        again = subprocess.run([sys.executable, "-m", "foveatrack", "recover", str(manual / "rec.mcap")], cwd=ROOT,
                               env=env(), capture_output=True, text=True, timeout=300)
        assert again.returncode == 0 and "nothing to recover" in again.stdout, again
        # replay takes it, and says what came from the journal
        rp = subprocess.run([sys.executable, "-m", "foveatrack", "replay", str(manual / "rec.mcap")], cwd=ROOT,
                            env=env(), capture_output=True, text=True, timeout=300)
        assert rp.returncode == 0, rp
        assert f"commands: {len(lines)} in the recording, {len(lines) - n_recorded} of them put back" in rp.stdout, \
            rp.stdout
        res = replay_recording(manual / "rec.mcap")
        assert res.comparison["detections_equal"], res.comparison
        # the daemon's next start in the same directory completes it by itself, and says so
        cfg2 = write_config(tmp_path / "d2.toml", link, tmp_path / "rec2.mcap", bport, 0, 0,
                            speed_table=str(tmp_path / "unit3.json"))
        log2 = tmp_path / "d2.jsonl"
        procs["daemon"] = start(["daemon", "--config", str(cfg2), "--log", str(log2)], tmp_path / "d2.out",
                                tmp_path / "d2.err")
        wait_for(lambda: event(log2, "start"), 60, "the second daemon to start", [procs["daemon"]])
        wait_for(lambda: event(log2, "recording_recovered"), 120, "the recovery at start", [procs["daemon"]])
        # (3: no lidar data: the virtual lidar still streams to the killed daemon's ports)
        assert terminate(procs["daemon"]) in (0, 3), (tmp_path / "d2.err").read_text()
    finally:
        stop_all(procs)
    ev = event(log2, "recording_recovered")
    assert ev["recording"] == str(rec) and ev["commands_added"] == len(added), ev
    d2_err = (tmp_path / "d2.err").read_text()
    assert "recovered:" in d2_err
    assert ("the run before this one was killed (its recording was completed above): the head is where that run "
            "left it, and this run assumes it at pan 0 / tilt 0 deg") in d2_err, d2_err
    assert len(_official_mcap_commands(rec)) == len(lines)
    assert RecordingReader(rec2 := tmp_path / "rec2.mcap").closed(), rec2
    assert oct(rec.stat().st_mode & 0o777) == "0o600"
    assert json.loads(json.dumps(ev))      # the event is plain JSON


def test_fault7_on_start_home_drives_the_head_home_before_the_first_frame_is_tracked(tmp_path):
    # the head reports no pose: a second run assumed pan0/tilt0 with the head where the first had left
    # it (-61 deg: 1 frame of 374 detected).  With on_start = "home" the start drives it home by the
    # absolute moves a reconnect uses (home pan -6 deg here, so that the move is a real one from 0/0)
    procs, link, truth, rec, log, bport = _setup(
        tmp_path, config_extra='on_start = "home"\nhome_pan_deg = -6.0\nhome_tilt_deg = 0.0\nhome_wait_s = 3.0')
    try:
        wait_for(lambda: event(log, "head_homed"), 60, "the head homed", list(procs.values()))
        _wait_frames(log, rec, 40, list(procs.values()))
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
        time.sleep(0.6)
    finally:
        stop_all(procs)
    unknown = event(log, "head_pose_unknown")
    assert unknown["why"] == "start" and unknown["on_reconnect"] == "home"
    homed = event(log, "head_homed")
    assert homed["pan_deg"] == -6.0 and homed["tilt_deg"] == 0.0 and homed["frames"] == 0, homed
    stats = event(log, "stop")["stats"]
    assert stats["head_homed"] == 1
    # the head really went there (its own truth), and the dead reckoning agrees at rest
    rows = read_truth(str(truth))
    pan_rest, tilt_rest = _replays_to_the_bit(rec).final_pose_deg
    assert abs(pan_rest - rows[-1]["pan_deg"]) < 1.0 and abs(tilt_rest - rows[-1]["tilt_deg"]) < 0.5, (
        (pan_rest, tilt_rest), rows[-1])
    dets = [d for d in RecordingReader(rec).records("detections") if d["detected"]]
    assert len(dets) >= 20


def test_fault7b_a_start_homed_before_the_lidar_speaks_replays(tmp_path):
    # a lidar up after the daemon had homed the head (boot order): the rebase is at sensor time 0,
    # recorded as such; it was recorded as null and the replay refused the file as damaged
    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    bport = free_udp_port()
    table = tmp_path / "unit3.json"
    truth_speed_table(PTS303H(unit_seed=3)).save(table)
    cfg = write_config(tmp_path / "d.toml", link, rec, bport, speed_table=str(table))
    cfg.write_text(cfg.read_text().replace(
        "[tracker]\n", 'on_start = "home"\nhome_pan_deg = -6.0\nhome_tilt_deg = 0.0\nhome_wait_s = 2.0\n\n[tracker]\n', 1))
    procs = {"head": _head(tmp_path, link, truth)}
    try:
        procs["daemon"] = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out", tmp_path / "d.err")
        wait_for(lambda: event(log, "head_homed"), 60, "the head homed", list(procs.values()))
        assert event(log, "lidar_data") is None
        procs["lidar"] = _lidar(tmp_path, bport, truth)
        wait_for(lambda: event(log, "lidar_data"), 60, "lidar data at the daemon", list(procs.values()))
        _wait_frames(log, rec, 30, list(procs.values()))
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    assert event(log, "head_homed")["t0_s"] == 0.0
    _replays_to_the_bit(rec)
