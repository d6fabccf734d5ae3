"""When a served scene's time starts, and what the serve says once it passes the scene's end.

A user's cold start took ~45 s to READY, and the daemon's first data were 37.4 s into a 15 s scene:
the clock had started with ``lidar serve``.  It now starts when a host first starts sampling
(``--clock sampling``, the default; ``--clock start`` keeps the old origin), each sampling start says
on stderr at what scene time it is, and passing ``duration_s`` is said once (the stream goes on).
"""

import json
import time

import numpy as np
import pytest

from foveatrack.livox.client import LivoxClient
from foveatrack.livox.protocol import PointBatch
from sim.virtual_lidar import VirtualLivox

from daemon_procs import first_line, start, terminate, wait_for

RATE = 100_000.0
SLOT_NS = 1e9 / RATE


def wall(t0_ns, t1_ns):
    """A point at 10 m in every slot of [t0_ns, t1_ns)."""
    i = np.arange(int(np.ceil(t0_ns / SLOT_NS - 1e-6)), int(np.ceil(t1_ns / SLOT_NS - 1e-6)))
    return np.tile([10.0, 0.0, 0.0], (i.size, 1)), np.full(i.size, 40, np.uint8), np.round(i * SLOT_NS).astype(np.int64)


def _client(**kw):
    return LivoxClient("127.0.0.1", cmd_port=0, data_port=0, broadcast_port=0, point_rate_hz=RATE,
                       keep_no_return=True, **kw)


def _collect(client, seconds, until=None):
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        out += client.poll(0.02)
        if until is not None and out and until(PointBatch.concat(out)):
            break
    return PointBatch.concat(out)


@pytest.mark.parametrize("clock", ["sampling", "start"])
def test_stream_time_starts_at_the_first_sampling_and_runs_on_between_samplings(clock):
    client = _client(heartbeat_period_s=0.1, retry_period_s=0.1)
    starts = []
    lidar = VirtualLivox(wall, cmd_port=0, broadcast_addr=("127.0.0.1", client.broadcast_port), point_rate_hz=RATE,
                         packet_type=0, broadcast_period_s=0.05, clock=clock,
                         on_sampling_start=lambda t_ns, host: starts.append((t_ns, host)))
    with client, lidar:
        host = ("127.0.0.1", client.data_port)
        client.connect(5.0)
        _collect(client, 0.8)                       # connected, not sampling: a host that looks later
        if clock == "sampling":
            assert lidar.stream_time_ns() == 0 and lidar.clock_zero_mono is None
        else:
            assert lidar.stream_time_ns() > 0.7e9
        client.start_sampling()
        first = _collect(client, 5.0, until=len)
        client.stop_sampling()
        _collect(client, 0.5)
        client.start_sampling()
        again = _collect(client, 5.0, until=len)
    t_first = first.t_ns.min() * 1e-9
    if clock == "sampling":
        assert t_first == 0.0 and starts[0][0] == 0    # the first slot of the stream is scene time 0
    else:
        assert t_first >= 0.75 and abs(starts[0][0] * 1e-9 - t_first) < 1e-6
    assert starts[0][1] == host
    # a later start continues the same clock (as a unit's time runs on): not back to 0
    assert len(starts) == 2 and again.t_ns.min() * 1e-9 >= t_first + 0.5 and starts[1][0] == again.t_ns.min()


def test_a_followed_head_is_mapped_through_the_lidar_clock_zero(tmp_path):
    """``--head-truth``: scene time t is the head's pose at monotonic (lidar clock zero + t), whenever
    that clock started (here late, as at a first sampling)."""
    from sim.lidar_server import TruthTail, _FollowingSource
    from sim.scene import scene_from_mapping

    scene = scene_from_mapping({"scene": {"name": "t", "duration_s": 1.0, "seed": 1}, "lidar": {"preset": "mid40"},
                                "gimbal": {"frozen": True}, "background": [{"type": "ground", "height_m": 1.5}]})
    f = tmp_path / "truth.jsonl"
    f.write_text("".join(json.dumps({"t_s": t, "pan_deg": 2.0 * t, "tilt_deg": 0.0}) + "\n" for t in range(0, 21)))
    tail = TruthTail(str(f), clock_zero=1000.0, keep_s=30.0)     # head time 0 at monotonic 1000
    tail.poll(0.0)
    src = _FollowingSource(scene, tail, 1.0)

    class Lidar:
        clock_zero_mono = None

    src.lidar = Lidar()
    assert src.mono0 is None
    Lidar.clock_zero_mono = 1012.0                  # the lidar's clock started 12 s into the head's
    pan, _ = src._pose(np.array([0.0, 3.5]))
    np.testing.assert_allclose(pan, [24.0, 31.0])


SCENE = """
[scene]
name = "short"
duration_s = 1.0
seed = 3

[lidar]
preset = "mid40"

[gimbal]
frozen = true

[[background]]
type = "ground"
height_m = 1.5
"""


@pytest.mark.parametrize("clock", ["sampling", "start"])
def test_lidar_serve_scene_time_at_sampling_and_past_the_end(tmp_path, clock):
    """The serve as a user runs it, a host looking 2 s after READY: by default its first packet is scene
    time 0 and stderr says so; with ``--clock start`` it is 2 s in, past this 1 s scene's end.  Either
    way the end is said once, and the stream goes on past it."""
    scene = tmp_path / "short.toml"
    scene.write_text(SCENE)
    client = _client()
    out, err = tmp_path / "l.out", tmp_path / "l.err"
    proc = start(["lidar", "serve", str(scene), "--cmd-port", "0", "--broadcast-port", str(client.broadcast_port),
                  "--clock", clock], out, err)
    try:
        with client:
            assert wait_for(lambda: first_line(out), 120, "READY", [proc]).startswith("READY 127.0.0.1 ")
            time.sleep(2.0)
            client.connect(10.0)
            client.start_sampling()
            first = _collect(client, 10.0, until=len)
            assert len(first), err.read_text()
            t_first = first.t_ns.min() * 1e-9
            # then past the scene's 1 s end: the stream goes on
            late = _collect(client, 10.0, until=lambda b: b.t_ns.max() > t_first * 1e9 + 1.5e9)
            assert late.t_ns.max() * 1e-9 > max(t_first, 1.0) + 0.4
            wait_for(lambda: "past the scene's duration_s" in err.read_text(), 5, "the end's note", [proc])
        assert terminate(proc) == 0, err.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
    text = err.read_text()
    counters = json.loads(out.read_text().splitlines()[-1])
    assert counters["sampling_start"] == 1
    said = [ln for ln in text.splitlines() if "started sampling at scene time" in ln]
    assert len(said) == 1, text
    assert text.count("past the scene's duration_s = 1 s; serving on") == 1, text
    if clock == "sampling":
        assert t_first == 0.0
        assert "the scene's clock starts when a host first starts sampling; the scene lasts 1 s" in text
        assert "at scene time 0.00 s, of the scene's 1 s; the scene's clock starts now" in said[0], said
    else:
        assert t_first > 1.9
        assert "the scene's clock starts now (--clock start)" in text
        assert f"at scene time {t_first:.2f} s, past the scene's end (duration_s = 1 s)" in said[0], (said, t_first)
