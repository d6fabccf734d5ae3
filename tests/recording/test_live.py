"""The live view: a WebSocket client (``websockets``, speaking Foxglove's WebSocket protocol)
connects to the SDK's server on loopback, subscribes to every advertised channel and receives the
recording's channels; the points it receives decode to the frame that was logged."""

import json
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from foveatrack.errors import UserError
from foveatrack.recording import RecordingWriter
from foveatrack.recording.format import decode_points_v4
from foveatrack.recording.live import LiveServer, Pacer
from foveatrack.recording.records import DetectionRecord, HeadEstimateRecord, TruthRecord, write_record
from foxglove_ws import advertised_channels, received, subscribe_all

META = {"tracker_table": {"space": {"kind": "box", "frame": "world", "min_xyz": [1, -5, -1], "max_xyz": [50, 5, 10]}}}


def log_frame(w, k, rng):
    t = 1_000_000_000 + k * 100_000_000
    xyz = rng.normal(0, 20, (50, 3))
    w.write_points(t, k, xyz, t - 50_000_000 + np.arange(50) * 1000, np.full(50, 7, np.uint8))
    write_record(w, DetectionRecord(t, k, True, (12.0, 0.1, 0.2), 9, t * 1e-9, 0.5, 0.9, "tracking", 0.1, 0.2))
    write_record(w, HeadEstimateRecord(t, k, 0.1 * k, 1.0, 0.01, 0.01, (12.0, 0.2, 1.0), 0.05))
    write_record(w, TruthRecord(t, k, 0.1 * k, 1.0, (12.0, 0.2, 1.0), 0.3, 9))
    return t, xyz


def test_a_websocket_client_subscribes_and_receives_the_channels():
    rng = np.random.default_rng(5)
    w = RecordingWriter(None, META)          # no file: the live view only
    with LiveServer(w.context, port=0) as live, \
            connect(f"ws://127.0.0.1:{live.port}", subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
        assert live.url.startswith("ws://127.0.0.1:")
        channels = advertised_channels(ws)
        by_topic = {c["topic"]: c for c in channels.values()}
        assert {"/points", "/detections", "/head", "/truth", "/tf", "/scene"} <= set(by_topic)
        assert by_topic["/points"]["schemaName"] == "foxglove.PointCloud"
        assert by_topic["/points"]["encoding"] == "protobuf"
        subs = subscribe_all(ws, channels)
        got: dict[str, list] = {}
        sent = {}
        k = 0
        deadline = time.monotonic() + 15
        want = {"/points", "/detections", "/head", "/truth", "/tf", "/scene"}
        while time.monotonic() < deadline and not want <= set(got):
            t, xyz = log_frame(w, k, rng)
            sent[t] = (k, xyz)
            k += 1
            for topic, log_time, payload in received(ws, channels, subs):
                got.setdefault(topic, []).append((log_time, payload))
    w.close()
    assert want <= set(got), set(got)
    for log_time, payload in got["/points"]:
        f = decode_points_v4(payload)     # the frame index is the /detections record's
        k, xyz = sent[f.t_ns]
        assert log_time == f.t_ns and np.array_equal(f.xyz, xyz)
    det = json.loads(got["/detections"][0][1])
    assert det["detected"] is True and det["xyz_m"] == [12.0, 0.1, 0.2]


def test_only_loopback_is_served_and_bad_ports_are_named():
    w = RecordingWriter(None, {})
    with pytest.raises(UserError, match="loopback"):
        LiveServer(w.context, port=0, host="0.0.0.0")
    with pytest.raises(UserError, match="0-65535"):
        LiveServer(w.context, port=70000)
    with LiveServer(w.context, port=0) as a:
        with pytest.raises(UserError, match=f"--live {a.port}: cannot serve"):
            LiveServer(w.context, port=a.port)
    w.close()


def test_the_pacer_holds_virtual_time_to_the_wall_clock():
    p = Pacer(speed=20.0)
    t0 = time.monotonic()
    for k in range(6):
        p.wait(k * 0.1)          # 0.5 s of virtual time at 20x: at least 25 ms of wall time
    assert time.monotonic() - t0 >= 0.5 / 20.0
    with pytest.raises(UserError, match="--speed"):
        Pacer(0)


FIXTURE = __import__("pathlib").Path(__file__).parent / "fixtures" / "fig12-v1.mcap"
ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def test_simulate_and_replay_live_from_the_cli(capsys):
    from foveatrack.cli import main

    assert main(["simulate", str(ROOT / "scenes" / "fig12-tracking.toml"), "--duration", "0.3", "--live", "0",
                 "--speed", "50", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "live view on ws://127.0.0.1:" in err and "50x real time" in err
    assert main(["replay", str(FIXTURE), "--live", "0", "--speed", "100", "--wait-s", "0"]) == 0
    cap = capsys.readouterr()
    assert "live view: served 40 messages" in cap.err          # 8 frames x 5 records of a format-1 file
    assert "same as recorded" in cap.out


@pytest.mark.parametrize("args,msg", [(["--live", "abc"], "--live 'abc'"), (["--live", "99999"], "0-65535"),
                                      (["--live", "0", "--speed", "0"], "--speed 0")])
def test_live_flags_are_checked(args, msg, capsys):
    from foveatrack.cli import main

    code = main(["simulate", str(ROOT / "scenes" / "fig12-tracking.toml"), "--duration", "0.2", "--no-progress",
                 *args])
    assert code != 0 and msg in capsys.readouterr().err


@pytest.mark.parametrize("args", [["--speed", "4"], ["--wait-s", "0"], ["--linger-s", "5"],
                                  ["--live-origin", "https://example.org"]])
def test_replay_refuses_a_live_view_option_without_live(args, capsys):
    # before: `replay run.mcap --speed 4` replayed as fast as it could and said nothing of the --speed
    from foveatrack.cli import main

    code = main(["replay", str(FIXTURE), *args])
    err = capsys.readouterr().err
    assert code != 0 and f"{args[0]}: for the live view only" in err and "add --live" in err, err


def test_replay_live_waits_for_a_viewer_and_serves_it_until_it_leaves(tmp_path):
    # before: --wait-s was a fixed sleep, and the server closed with the last message, under a viewer
    import threading

    from foveatrack.recording.live import stream_recording

    path = tmp_path / "run.mcap"
    rng = np.random.default_rng(3)
    with RecordingWriter(path, META) as w:
        for k in range(3):
            log_frame(w, k, rng)
    said, result = [], {}
    port = _free_port()
    th = threading.Thread(target=lambda: result.setdefault("n", stream_recording(
        path, port, speed=1000.0, wait_for_client_s=60.0, say=said.append, linger_s=60.0)))
    th.start()
    try:
        deadline = time.monotonic() + 20
        while not any("waiting up to 60 s" in s for s in said) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        assert th.is_alive() and "n" not in result        # nothing streamed yet: it waits for a viewer
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            channels = advertised_channels(ws, until_topic="/head")
            subs = subscribe_all(ws, channels)
            got = []
            deadline = time.monotonic() + 20
            while len([t for t, _, _ in got if t == "/head"]) < 3 and time.monotonic() < deadline:
                got += received(ws, channels, subs)
            assert [t for t, _, _ in got].count("/head") == 3     # the whole recording, from its start
            time.sleep(0.5)
            assert th.is_alive(), "the server stays up while the viewer is connected"
            assert any("until the viewer disconnects" in s for s in said)
        th.join(20)
        assert not th.is_alive() and result["n"] == 3 * 4     # closed once the viewer left (4 records a frame)
    finally:
        th.join(70)


def test_no_viewer_no_waiting_after_the_run():
    # wait_for_viewer gives up after its timeout; linger returns at once when nobody watches
    w = RecordingWriter(None, META)
    with LiveServer(w.context, 0) as live:
        assert live.wait_for_viewer(0.2) is False and live.viewers == 0
        assert live.linger(60.0) is True
    w.close()


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
