"""The daemon tracks several objects live (issue 28): with ``[tracker.sky]`` in its config it runs the
multi-object tracker, records every track (``/tracks``) and its table, takes an operator's pin over
its control socket (``foveatrack daemon pin ID``), records it before the frame it first steers, and
replay rebuilds the tracker and its tracks to the bit.

Three processes as in test_daemon_e2e: the virtual head on a pty, the daemon, the virtual Livox of
``scenes/two-drones-crossing.toml`` (two drones whose bearings cross 5 s in) on loopback."""

import json
import os
import re
import socket
import subprocess
import sys
import time

import pytest

from daemon_procs import (ROOT, env, event, first_line, free_udp_port, log_events, start, stop_all, terminate,
                          wait_for, write_config)
from foveatrack.errors import UserError
from gimbal.pts303h import PTS303H
from sim.loop import truth_speed_table

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")

SCENE = ROOT / "scenes" / "two-drones-crossing.toml"
# the Mid-40's field (the simulator's scan: 19.2 deg half-angle), which the daemon cannot know itself
SKY = """
[tracker.sky]
field_half_angle_deg = 19.2
"""


def _cli(*args, timeout_s=30.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "foveatrack", *args], cwd=ROOT, env=env(), capture_output=True,
                          text=True, timeout=timeout_s)


def _tracks(cfg) -> dict | None:
    """The daemon's answer to ``tracks`` (None while it has no control socket yet)."""
    from foveatrack.daemon.operator import ask_daemon
    from foveatrack.device_config import load_config

    try:
        return ask_daemon(load_config(cfg).control_socket_path(), {"command": "tracks"}, 5.0)
    except UserError:
        return None


def test_daemon_tracks_two_drones_takes_a_pin_and_replays_its_tracks(tmp_path):
    from foveatrack.recording import RecordingReader
    from foveatrack.replay import replay_recording
    from foveatrack.replay.recorded import TrackPinned, recorded_frames

    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    bport = free_udp_port()
    table = tmp_path / "unit3.json"
    truth_speed_table(PTS303H(unit_seed=3)).save(table)
    cfg = write_config(tmp_path / "d.toml", link, rec, bport, speed_table=str(table), tracker_extra=SKY)
    procs = {}
    try:
        procs["head"] = start(["gimbal", "serve", "--link", str(link), "--truth", str(truth), "--unit-seed", "3"],
                              tmp_path / "head.out", tmp_path / "head.err")
        wait_for(lambda: first_line(tmp_path / "head.out"), 20, "the head's pty", [procs["head"]])
        procs["daemon"] = start(["daemon", "--config", str(cfg), "--log", str(log)], tmp_path / "d.out",
                                tmp_path / "d.err")
        # the daemon listens before the lidar starts: it sees the scene from its first second
        wait_for(lambda: event(log, "start"), 60, "the daemon to start", [procs["daemon"]])
        sock = event(log, "control_socket")
        assert sock is not None and sock["path"] == str(tmp_path / "d.control.sock")   # beside the recording
        procs["lidar"] = start(["lidar", "serve", str(SCENE), "--cmd-port", "0", "--broadcast-port", str(bport),
                                "--head-truth", str(truth), "--seed", "5"], tmp_path / "l.out", tmp_path / "l.err")
        wait_for(lambda: event(log, "lidar_data"), 60, "lidar data at the daemon", list(procs.values()))
        # both drones confirmed (drone-b ~4.5 s in, in the simulator)
        both = wait_for(lambda: (r := _tracks(cfg)) is not None and len(r["tracks"]) >= 2 and r, 30,
                        "two live confirmed tracks", list(procs.values()))
        ids = [t["track_id"] for t in both["tracks"]]
        # the operator pins the track that is not the priority, then the other one: the second pin
        # certainly moves the priority (the first may race the threat scores), and then unpins
        first = next(i for i in ids if i != _tracks(cfg)["priority"])
        second = next(i for i in ids if i != first)
        for pick, hold_s in ((first, 0.8), (second, 1.2)):
            ok = _cli("daemon", "pin", str(pick), "--config", str(cfg))
            assert ok.returncode == 0 and f"pinned track {pick} (" in ok.stdout, (ok.stdout, ok.stderr)
            # the attention's priority from the next frame on
            wait_for(lambda: _tracks(cfg)["priority"] == pick, 2, f"track {pick} to be the priority",
                     list(procs.values()))
            time.sleep(hold_s)
        # (a pinned track that is deleted unpins itself: seen once in 8 runs, drone-a's track lost
        # ~0.6 s after its pin, 8.4 s into the scene)
        now = _tracks(cfg)
        listed = _cli("daemon", "tracks", "--config", str(cfg))
        assert listed.returncode == 0 and "live confirmed tracks: " in listed.stdout, (listed.stdout, listed.stderr)
        still = second in [t["track_id"] for t in now["tracks"]]
        assert not still or f"pinned: {second}" in listed.stdout, (listed.stdout, now)
        off = _cli("daemon", "unpin", "--config", str(cfg))
        assert off.returncode == 0, off.stderr
        assert (f"unpinned track {second}" if still else "no track was pinned") in off.stdout, off.stdout
        # a bad id is refused, naming the live tracks; nothing is pinned or recorded for it.  The tracks
        # live before and after the request were live at it (a deleted id never comes back); one
        # confirmed or deleted in between may or may not be named (seen: a third track confirmed
        # between the refusal and a later query, on a loaded machine)
        before = {t["track_id"] for t in _tracks(cfg)["tracks"]}
        bad = _cli("daemon", "pin", "999", "--config", str(cfg))
        after = {t["track_id"] for t in _tracks(cfg)["tracks"]}
        assert bad.returncode == 2 and "track 999 is not a live confirmed track; nothing pinned" in bad.stderr
        named = {int(i) for i in re.findall(r"(\d+) \(", bad.stderr.split("live confirmed tracks: ", 1)[1])}
        assert before & after <= named <= before | after, (bad.stderr, before, after)
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    assert not (tmp_path / "d.control.sock").exists()         # removed at shutdown
    stats = event(log, "stop")["stats"]
    # an unpin is not a pin (the stop's counters read "3 pins" for two pins and an unpin); where the
    # second pinned track was deleted first, it unpinned itself and the unpin changed nothing
    assert stats["operator_pins"] == 2 and stats["operator_unpins"] == int(still)
    assert stats["recording_dropped"] == 0
    pins = [e for e in log_events(log) if e["event"] == "track_pinned"]
    assert [p["track_id"] for p in pins] == [first, second] + ([None] if still else [])

    # the recording: the multi-object tracker's table, every frame's tracks, each pin between two frames
    r = RecordingReader(rec)
    assert r.meta["sky"]["field_half_angle_deg"] == 19.2 and "attention" in r.meta["sky"]
    frames = list(recorded_frames(r))
    assert all(f.tracks is not None for f in frames) and len(frames) == stats["frames"]
    assert max(sum(t.confirmed for t in f.tracks.tracks) for f in frames) >= 2
    at = [(k, a.track_id) for k, f in enumerate(frames) for a in f.after if isinstance(a, TrackPinned)]
    assert [p for _, p in at] == [first, second, None], at
    for k, pick in at[:2]:
        # recorded after frame k: the pin is in the tracks from frame k + 1 on
        assert frames[k].tracks.pinned != pick and frames[k + 1].tracks.pinned == pick
    assert frames[at[2][0] + 1].tracks.pinned is None
    # followed: once the second pin holds, the fovea turns to that track (from the first pin's: the
    # priority moved) and serves it; the attention's revisits of the other drone go on meanwhile
    held = []
    for f in frames[at[1][0] + 1:]:
        if f.tracks.pinned != second:
            break
        held.append(f.tracks)
    assert len(held) >= 5 and held[0].next_target == second, [t.next_target for t in held]
    assert any(t.fixated == second for t in held), [t.fixated for t in held]

    # replay rebuilds the multi-object tracker from the recorded table, applies the pin where it was
    res = replay_recording(rec)
    tr = res.comparison["tracks"]
    assert tr["identical_all"], tr
    assert res.comparison["commands_equal"], res.comparison


def test_pin_without_a_daemon_or_a_sky_table_says_what_is_wrong(tmp_path):
    cfg = write_config(tmp_path / "d.toml", tmp_path / "head", tmp_path / "rec.mcap", free_udp_port(),
                       tracker_extra=SKY)
    # no daemon: no socket
    r = _cli("daemon", "pin", "3", "--config", str(cfg))
    assert r.returncode == 2 and "no daemon is running there" in r.stderr and "d.control.sock" in r.stderr
    # a socket file left by a killed daemon: nobody listens
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(str(tmp_path / "d.control.sock"))
    s.close()
    r = _cli("daemon", "unpin", "--config", str(cfg))
    assert r.returncode == 2 and "nothing listens on control socket" in r.stderr, r.stderr
    # a daemon config without [tracker.sky]: the paper's tracker has no tracks
    plain = write_config(tmp_path / "p.toml", tmp_path / "head", tmp_path / "rec.mcap", free_udp_port())
    r = _cli("daemon", "pin", "3", "--config", str(plain))
    assert r.returncode == 2 and "has no [tracker.sky] table" in r.stderr
    # a track id that is no id
    r = _cli("daemon", "pin", "three", "--config", str(cfg))
    assert r.returncode == 2 and "a track id is a whole number >= 0" in r.stderr


def test_a_daemon_answers_over_its_socket_between_frames(tmp_path):
    """The server's end without devices: a request is answered, a stale socket file is replaced, a
    live one refuses a second daemon."""
    from foveatrack.daemon.operator import ControlSocket, ask_daemon

    path = tmp_path / "c.sock"
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    stale.bind(str(path))
    stale.close()
    server = ControlSocket(path, "test")        # replaces the stale file
    try:
        assert oct(os.stat(path).st_mode & 0o777) == "0o600"
        with pytest.raises(UserError, match="another daemon listens"):
            ControlSocket(path, "test")
        import threading

        def serve():
            end = time.monotonic() + 5
            while time.monotonic() < end:
                for addr, req, err in server.requests():
                    server.answer(addr, {"ok": True, "message": json.dumps(req)})
                    return
                time.sleep(0.01)

        t = threading.Thread(target=serve)
        t.start()
        reply = ask_daemon(path, {"command": "tracks"}, 5.0)
        t.join()
        assert json.loads(reply["message"]) == {"command": "tracks"}
        with pytest.raises(UserError, match="did not answer within 0.2 s"):
            ask_daemon(path, {"command": "tracks"}, 0.2)
    finally:
        server.close()
    assert not path.exists()


def test_the_control_socket_path_is_checked_as_the_start_uses_it(tmp_path):
    """``daemon --check`` and the start ask the same of the control socket's path: a recording
    directory the daemon will make (``make_dirs``) holds it; another missing directory, or a file that
    is not a socket, is refused naming the key (``--check`` passed both, and the run then failed)."""
    from types import SimpleNamespace

    from foveatrack.daemon.operator import Operator
    from foveatrack.device_config import load_config

    # the recording's directory, not there yet, with make_dirs: accepted, and the start makes it
    made = write_config(tmp_path / "m.toml", tmp_path / "head", tmp_path / "runs" / "rec.mcap", free_udp_port(),
                        tracker_extra=SKY, recording_extra="make_dirs = true")
    cfg = load_config(made)
    cfg.check_control_socket()
    closed = []
    op = Operator()
    op.cfg, op.tracker, op.counters = cfg, SimpleNamespace(pin=None), {}
    op.client = op.head = SimpleNamespace(close=lambda: closed.append(1))
    op.log = SimpleNamespace(event=lambda *a, **k: None)
    op._open_control()
    try:
        assert (tmp_path / "runs" / "m.control.sock").exists() and not closed
    finally:
        op.control.close()
    # the same without make_dirs: the recording check names its key first; the socket's own check too
    missing = write_config(tmp_path / "n.toml", tmp_path / "head", tmp_path / "gone" / "rec.mcap", free_udp_port(),
                           tracker_extra=SKY)
    with pytest.raises(UserError, match=r"\[daemon\] control_socket: the directory .*gone does not exist"):
        load_config(missing).check_control_socket()
    # a file that is not a socket: --check refuses it, and pin says it is no control socket
    precious = tmp_path / "precious.txt"
    precious.write_text("keep me")
    plain = write_config(tmp_path / "f.toml", tmp_path / "head", tmp_path / "rec.mcap", free_udp_port(),
                         tracker_extra=SKY)
    plain.write_text(plain.read_text().replace("[daemon]\n", f'[daemon]\ncontrol_socket = "{precious}"\n'))
    r = _cli("daemon", "--check", "--config", str(plain))
    assert r.returncode == 2 and "control_socket" in r.stderr and "is not a socket" in r.stderr, r.stderr
    r = _cli("daemon", "tracks", "--config", str(plain))
    assert r.returncode == 2 and "is not a control socket" in r.stderr, r.stderr
    assert precious.read_text() == "keep me"


def test_an_unpin_with_nothing_pinned_changes_nothing_and_records_nothing():
    from types import SimpleNamespace

    from foveatrack.daemon.operator import Operator

    events, recorded = [], []
    op = Operator()
    op.tracker = SimpleNamespace(pinned=None, confirmed_tracks=lambda: (), pin=lambda tid: events.append(("pin", tid)),
                                 last_output=None, attention=SimpleNamespace(priority=None))
    op.log = SimpleNamespace(event=lambda *a, **k: events.append(a))
    op._record = lambda *a: recorded.append(a)
    op.counters = {"operator_pins": 0, "operator_unpins": 0, "frames": 7}
    op.last_frame_end_s = 1.0
    reply = op._operator_request({"command": "unpin"})
    assert reply["ok"] and "no track was pinned" in reply["message"]
    assert events == [] and recorded == [] and op.counters["operator_pins"] == 0
