"""Helpers for the tests that drive a Daemon in-process (no lidar, no serial port): a config, a frame
with a small target cluster, and a daemon wired to a recording and a fake head link."""

from types import SimpleNamespace

import numpy as np

from foveatrack.daemon import Daemon, load_config
from foveatrack.daemon.support import RecordingThread
from foveatrack.live_devices import HeadLink
from foveatrack.frames import Frame
from foveatrack.recording import RecordingWriter

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


def target_frame(k, period=0.1, az_deg=10.0, n=40):
    """A small cluster 12 m out, ``az_deg`` to the left: the tracker wants to pan left."""
    t0, t1 = k * period, (k + 1) * period
    rng = np.random.default_rng(k)
    a = np.radians(az_deg)
    xyz = np.array([12 * np.cos(a), 12 * np.sin(a), 0.5]) + rng.normal(0, 0.05, (n, 3))
    t_ns = np.linspace(t0 * 1e9, t1 * 1e9 - 1e3, n).astype(np.int64)
    return Frame(t0, t1, xyz, t_ns, np.full(n, 30, np.uint8))


def inprocess_daemon(tmp_path, head, head_extra: str = ""):
    """A daemon recording to ``tmp_path / "rec.mcap"``, writing to ``head`` (``send_frame(raw) ->
    bool``), with a fake receiver whose ``offset_s`` (host - sensor clock) the test sets;
    ``head_extra``: more ``[head]`` keys (TOML lines)."""
    cfg_path = tmp_path / "d.toml"
    cfg_path.write_text(CONFIG.replace('port = "/tmp/not-opened-in-this-test"\n',
                                       'port = "/tmp/not-opened-in-this-test"\n' + head_extra + "\n"))
    d = Daemon(load_config(cfg_path), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    rec = tmp_path / "rec.mcap"
    d.recorder = RecordingThread(RecordingWriter(rec, d._meta()), 50)
    d.head = HeadLink(head, d.cfg.head.address, d.cfg.head.protocol)   # the test's fake behind the real link
    d.rx = SimpleNamespace(offset_s=None)
    return d, rec
