"""``foveatrack daemon --live``: the daemon's frames reach a Foxglove WebSocket client through the
recording thread (the same channels as its recording), on loopback."""

import json
import time

from websockets.sync.client import connect

from inprocess import inprocess_daemon, target_frame


class FakeHead:
    connected = True

    def send_frame(self, raw):
        return True


def test_daemon_live_view_serves_its_frames(tmp_path):
    d, rec = inprocess_daemon(tmp_path, FakeHead())
    d.live_port = 0
    d._open_live()
    try:
        with connect(d.live.url, subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            channels = {}
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and "/points" not in {c["topic"] for c in channels.values()}:
                msg = json.loads(ws.recv(timeout=5))
                if msg.get("op") == "advertise":
                    channels.update({c["id"]: c for c in msg["channels"]})
            subs = {i + 1: cid for i, cid in enumerate(channels)}
            ws.send(json.dumps({"op": "subscribe",
                                "subscriptions": [{"id": s, "channelId": c} for s, c in subs.items()]}))
            got = set()
            want = {"/points", "/detections", "/head", "/commands", "/tf", "/scene"}
            k = 0
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline and not want <= got:
                fr = target_frame(k)
                d.rx.offset_s = time.monotonic() - (fr.t_end_s + 0.01)
                d._process(fr, time.monotonic())
                k += 1
                try:
                    while True:
                        data = ws.recv(timeout=0.2)
                        if isinstance(data, bytes) and data[0] == 0x01:
                            got.add(channels[subs[int.from_bytes(data[1:5], "little")]]["topic"])
                except TimeoutError:
                    pass
            assert want <= got, got
    finally:
        d.recorder.close()
        d.live.stop()
