"""A frame processed too late steers nothing: the daemon sends STOP, records why, and replay repeats it.

Found in CI: at start-up on a loaded machine the daemon processed its first frames ~0.6 s late in a
burst while the sensor-to-host clock offset was still settling, so the first command was placed
0.34 s early in the dead reckoning and the world-frame tilt stayed ~0.9 deg off for the whole run.
Here the daemon runs in-process with a fake head link and a fake receiver whose clock offset we set.
"""

import time
from types import SimpleNamespace

import numpy as np

from foveatrack.daemon import Daemon, load_config
from foveatrack.daemon.support import STALE_FRAME, RecordingThread
from foveatrack.frames import Frame
from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.replay import replay_recording

CONFIG = """
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
[head]
port = "/tmp/not-opened-in-this-test"
[tracker]
deadband_deg = 2.0
[daemon]
stale_frame_s = 0.2
"""


class FakeHead:
    connected = True

    def __init__(self):
        self.frames = []

    def send_frame(self, raw):
        self.frames.append(raw)
        return True


def _target_frame(k, period=0.1, az_deg=10.0, n=40):
    """A small cluster 12 m out, ``az_deg`` to the left: the tracker wants to pan left."""
    t0, t1 = k * period, (k + 1) * period
    rng = np.random.default_rng(k)
    a = np.radians(az_deg)
    xyz = np.array([12 * np.cos(a), 12 * np.sin(a), 0.5]) + rng.normal(0, 0.05, (n, 3))
    t_ns = np.linspace(t0 * 1e9, t1 * 1e9 - 1e3, n).astype(np.int64)
    return Frame(t0, t1, xyz, t_ns, np.full(n, 30, np.uint8))


def test_stale_frames_send_stop_and_replay_repeats_it(tmp_path):
    cfg_path = tmp_path / "d.toml"
    cfg_path.write_text(CONFIG)
    d = Daemon(load_config(cfg_path), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    rec = tmp_path / "rec.mcap"
    d.recorder = RecordingThread(RecordingWriter(rec, d._meta()), 50)
    d.head = FakeHead()
    d.rx = SimpleNamespace(offset_s=None)
    sent = []
    # A start-up burst: frames 0-5 are all processed at sensor time 0.75 s (0.65 ... 0.15 s late); from
    # frame 6 on, each is processed 10 ms after its end.
    for k in range(10):
        fr = _target_frame(k)
        now_s = 0.75 if k < 6 else fr.t_end_s + 0.01
        d.rx.offset_s = time.monotonic() - now_s
        d._process(fr, time.monotonic())
        sent.append(d.head.frames[-1])
    d.recorder.close()
    # 0.65 ... 0.25 s late: stale; frame 5 (0.15 s late) is within the 0.2 s bound and steers
    assert d.counters["frames_stale"] == 5
    stop_bytes = bytes.fromhex("ff010000000001")
    assert sent[:5] == [stop_bytes] * 5
    assert all(s != stop_bytes for s in sent[5:]), [s.hex() for s in sent]   # then it pans toward the UAV
    cmds = [c for c in RecordingReader(rec).records("commands") if c["source"] == "tracker"]
    assert [STALE_FRAME in c.get("limited", ()) for c in cmds] == [True] * 5 + [False] * 5
    assert all(c["tracker_command"][0] == 1 for c in cmds[:5])       # what the tracker wanted: pan left
    # the dead reckoning knows the head stayed put until the first command that left (~0.75 s)
    assert d.tracker.recon.angles_at(0.75)[0] == 0.0 and d.tracker.recon.angles_at(1.1)[0] > 0.1
    res = replay_recording(rec)
    assert res.comparison["commands_equal"] and res.comparison["detections_equal"], res.comparison
    assert res.comparison["commands_compared"] == 10
