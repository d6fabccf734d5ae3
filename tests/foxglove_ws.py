"""A minimal Foxglove WebSocket client for the live-view tests (foxglove.sdk.v1 over ``websockets``)."""

import json
import time


def advertised_channels(ws, until_topic: str = "/points", timeout_s: float = 10.0) -> dict:
    """Channel id -> channel, from the server's "advertise" messages, once ``until_topic`` is among them."""
    channels = {}
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and until_topic not in {c["topic"] for c in channels.values()}:
        msg = json.loads(ws.recv(timeout=5))
        if msg.get("op") == "advertise":
            channels.update({c["id"]: c for c in msg["channels"]})
    return channels


def subscribe_all(ws, channels: dict) -> dict:
    """Subscribe to every channel; returns subscription id -> channel id."""
    subs = {i + 1: cid for i, cid in enumerate(channels)}
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": s, "channelId": c} for s, c in subs.items()]}))
    return subs


def received(ws, channels: dict, subs: dict, wait_s: float = 0.2) -> list[tuple[str, int, bytes]]:
    """The message-data frames that arrive until ``wait_s`` passes without one: (topic, log time [ns],
    payload) each."""
    out = []
    try:
        while True:
            data = ws.recv(timeout=wait_s)
            if isinstance(data, bytes) and data[0] == 0x01:     # message data
                topic = channels[subs[int.from_bytes(data[1:5], "little")]]["topic"]
                out.append((topic, int.from_bytes(data[5:13], "little"), data[13:]))
    except TimeoutError:
        pass
    return out
