"""The live view's Origin check (issue 32): any web page in a local browser could open
``ws://127.0.0.1:PORT`` and read the stream.  A connection whose handshake names a foreign
``Origin`` is refused (HTTP 403, and one line saying how to allow it); one without an ``Origin`` (the
Foxglove app, scripts), from Foxglove's web app, or from an origin given with ``--live-origin`` is
served.  A ``websockets`` client on loopback speaks the Foxglove protocol through the gate."""

import json

import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from foveatrack.cli import main
from foveatrack.errors import UserError
from foveatrack.recording import RecordingWriter
from foveatrack.recording.live import LiveServer
from foveatrack.recording.origin_gate import request_origin

SUBPROTOCOL = ["foxglove.sdk.v1"]


def first_op(ws) -> str:
    return json.loads(ws.recv(timeout=10))["op"]


@pytest.fixture
def live():
    said = []
    w = RecordingWriter(None, {})
    server = LiveServer(w.context, port=0, allowed_origins=["http://localhost:3000"], say=said.append)
    yield server, said
    server.stop()
    w.close()


@pytest.mark.parametrize("origin", ["https://evil.example", "http://localhost:3001", "null"])
def test_a_web_page_of_a_foreign_origin_is_refused(live, origin):
    server, said = live
    with pytest.raises(InvalidStatus) as exc:
        connect(f"ws://127.0.0.1:{server.port}", subprotocols=SUBPROTOCOL, origin=origin, open_timeout=10)
    assert exc.value.response.status_code == 403
    assert len(said) == 1 and repr(origin) in said[0] and f"--live-origin {origin}" in said[0]
    with pytest.raises(InvalidStatus):      # said once per origin, refused every time
        connect(f"ws://127.0.0.1:{server.port}", subprotocols=SUBPROTOCOL, origin=origin, open_timeout=10)
    assert len(said) == 1


@pytest.mark.parametrize("origin", [None, "http://localhost:3000", "HTTP://LOCALHOST:3000/",
                                    "https://app.foxglove.dev"])
def test_no_origin_an_allowed_one_and_foxgloves_web_app_are_served(live, origin):
    server, said = live
    with connect(f"ws://127.0.0.1:{server.port}", subprotocols=SUBPROTOCOL, origin=origin, open_timeout=10) as ws:
        assert first_op(ws) == "serverInfo"      # the SDK's server answered through the gate
    assert said == []


def test_star_allows_any_origin_and_stop_closes_served_connections():
    w = RecordingWriter(None, {})
    server = LiveServer(w.context, port=0, allowed_origins=["*"], say=lambda t: None)
    try:
        with connect(f"ws://127.0.0.1:{server.port}", subprotocols=SUBPROTOCOL, origin="https://any.example",
                     open_timeout=10) as ws:
            assert first_op(ws) == "serverInfo"
            server.stop()
            with pytest.raises(ConnectionClosed):
                while True:
                    ws.recv(timeout=5)
    finally:
        server.stop()
        w.close()


def test_an_origin_that_is_not_one_is_a_one_line_error():
    w = RecordingWriter(None, {})
    with pytest.raises(UserError, match="--live-origin 'evil.example'"):
        LiveServer(w.context, port=0, allowed_origins=["evil.example"])
    w.close()


def test_live_origin_without_live_is_an_error(tmp_path, capsys):
    assert main(["simulate", "no-such.toml", "--live-origin", "http://localhost:3000"]) == 2
    assert "add --live" in capsys.readouterr().err


def test_the_origin_header_is_found_in_any_case():
    req = b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\noRiGiN:  https://x.example \r\nUpgrade: websocket"
    assert request_origin(req) == "https://x.example"
    assert request_origin(b"GET / HTTP/1.1\r\nHost: 127.0.0.1") is None
