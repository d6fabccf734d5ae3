"""The daemon's gyro witnesses the head's turns (issue 25): a head that turns far more than its speed
table says stops the run with an error naming the axis, the commanded and the measured turn.

In-process (no lidar, no serial port), as tests/daemon/test_gyro_feed.py: a tracker with
``attitude = "gyro"`` sees a target 10 deg to the left and commands pan left; the test plays the
head, turning about the vertical at ``factor`` times the speed table's speed of the command the head
got (``factor`` 1: the table is right; 5: a head far faster than the table, as a ``heavy-worm`` on a
PTS-303's port), and sends the gyro's samples of that turn (bias and noise included) to the daemon.
"""

import time
from collections import deque
from types import SimpleNamespace

import numpy as np
import pytest

from foveatrack.daemon import Daemon, load_config
from foveatrack.daemon.support import RecordingThread
from foveatrack.errors import UserError
from foveatrack.live_devices import HeadLink
from foveatrack.recording import RecordingWriter

from inprocess import CONFIG, target_frame

RATE_HZ = 200
BIAS = np.array([0.004, -0.006, 0.005])     # rad/s: the BMI088's order


class TakesEveryWrite:
    connected = True

    def send_frame(self, raw):
        return True


def _run(tmp_path, factor: float, frames: int = 40) -> Daemon:
    cfg_path = tmp_path / "d.toml"
    cfg_path.write_text(CONFIG.replace("[tracker]\n", '[tracker]\nattitude = "gyro"\n'))
    d = Daemon(load_config(cfg_path), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    d.recorder = RecordingThread(RecordingWriter(tmp_path / "rec.mcap", d._meta()), 50)
    d.head = HeadLink(TakesEveryWrite(), d.cfg.head.address, d.cfg.head.protocol)
    d.rx = SimpleNamespace(offset_s=None, imu=deque())
    rng = np.random.default_rng(3)
    pan_axis = d.table.axis("pan")
    got = [(-np.inf, 0, 0)]                   # (send time, pan_dir, pan_byte) the head got

    def gyro(t):
        w = np.zeros((t.size, 3))
        for t_c, pd, pb in got:               # in time order: each command holds from its send time on
            w[t >= t_c, 2] = np.radians(factor * pd * pan_axis.speed_deg_s(pb)) if pd else 0.0
        return w + BIAS + rng.normal(0, np.radians(0.014) * np.sqrt(RATE_HZ), (t.size, 3))

    def push(t):
        acc = np.tile([0.0, 0.0, 1.0], (t.size, 1))    # level: the accelerometer reads +1 g up
        d.rx.imu.append(((t * 1e9).astype(np.int64), gyro(t), 0, acc))

    try:
        push(np.arange(-2 * RATE_HZ, 0) / RATE_HZ)       # the head at rest before the run
        for k in range(frames):
            fr = target_frame(k, az_deg=10.0)
            push(np.arange(round(fr.t_start_s * RATE_HZ), round(fr.t_end_s * RATE_HZ)) / RATE_HZ)
            d.rx.offset_s = time.monotonic() - (fr.t_end_s + 0.01)
            d._process(fr, time.monotonic())
            c = d.gate.head_cmd
            if (c.pan_dir, c.pan_byte) != got[-1][1:]:
                got.append((d._last_send_t, c.pan_dir, c.pan_byte))
    finally:
        d.recorder.close()
    return d


def test_a_head_turning_as_its_table_says_runs_on(tmp_path):
    d = _run(tmp_path, factor=1.0)
    assert d.counters["frames"] == 40
    w = d.witness
    assert w is not None and w.moving and w.unwitnessed == 0     # the move was watched all along
    assert w.witness.turned_deg["pan"] > 5.0                      # and it did turn (pan, left)


def test_a_head_turning_five_times_faster_than_its_table_stops_the_run(tmp_path):
    with pytest.raises(UserError) as err:
        _run(tmp_path, factor=5.0)
    msg = str(err.value)
    assert "the head turned pan +" in msg and "deg was commanded" in msg, msg
    measured = float(msg.split("the head turned pan ")[1].split(" ")[0])
    commanded = float(msg.split("deg where ")[1].split(" ")[0])
    assert measured > 3.0 + 1.5 * commanded > 0, msg
    assert "turn_mismatch" in (tmp_path / "d.jsonl").read_text()
