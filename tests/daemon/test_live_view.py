"""``foveatrack daemon --live``: the daemon's frames reach a Foxglove WebSocket client through the
recording thread (the same channels as its recording), on loopback."""

import time

from websockets.sync.client import connect

from foxglove_ws import advertised_channels, received, subscribe_all
from inprocess import inprocess_daemon, target_frame


class FakeHead:
    connected = True

    def send_frame(self, raw):
        return True


def test_daemon_live_view_serves_its_frames(tmp_path, capsys):
    d, rec = inprocess_daemon(tmp_path, FakeHead())
    d.live_port = 0
    d.recorder.close()
    d.recorder = None           # the live view without a recording: the daemon's own writer
    started_utc_ns = time.time_ns()
    d._open_live()
    # the URL on stderr, as simulate and replay print it (before: only in the JSON log)
    assert f"live view on {d.live.url} (Foxglove" in capsys.readouterr().err
    try:
        with connect(d.live.url, subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            channels = advertised_channels(ws)
            subs = subscribe_all(ws, channels)
            got = set()
            want = {"/points", "/detections", "/head", "/commands", "/tf", "/scene"}
            k = 0
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline and not want <= got:
                fr = target_frame(k)
                d.rx.offset_s = time.monotonic() - (fr.t_end_s + 0.01)
                d._process(fr, time.monotonic())
                k += 1
                msgs = received(ws, channels, subs)
                got.update(topic for topic, _, _ in msgs)
                # log times: the host's clock (UTC), not the Livox clock the frames carry
                assert all(started_utc_ns <= t <= time.time_ns() for _, t, _ in msgs)
            assert want <= got, got
    finally:
        d.recorder.close()
        d.live.stop()
