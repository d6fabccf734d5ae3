"""The daemon feeds the lidar's IMU samples to a tracker whose attitude comes from the gyro.

In-process (no lidar, no serial port): the head link is a fake that takes every write but moves
nothing, so the true head stays at pan 0.  The tracker, seeing a target 10 deg left, commands pan
left: dead reckoning the commands turns the estimate left, the gyro (zero rate plus a bias) keeps it
at 0.  The IMU batches come as the receiver thread queues them (t_ns, gyro, clock epoch).
"""

import time
from collections import deque
from types import SimpleNamespace

import numpy as np
import pytest

from foveatrack.daemon import Daemon, load_config
from foveatrack.daemon.support import RecordingThread
from foveatrack.gyro_attitude import GyroAttitude, ImuFeed
from foveatrack.live_devices import HeadLink
from foveatrack.recording import RecordingWriter

from inprocess import CONFIG, target_frame


class StillHead:
    connected = True

    def send_frame(self, raw):
        return True


def _daemon(tmp_path):
    cfg_path = tmp_path / "d.toml"
    cfg_path.write_text(CONFIG.replace("[tracker]\n", '[tracker]\nattitude = "gyro"\n'))
    d = Daemon(load_config(cfg_path), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    d.recorder = RecordingThread(RecordingWriter(tmp_path / "rec.mcap", d._meta()), 50)
    d.head = HeadLink(StillHead(), d.cfg.head.address, d.cfg.head.protocol)
    d.rx = SimpleNamespace(offset_s=None, imu=deque())
    return d


def test_the_daemon_feeds_the_gyro_and_the_head_stays_put(tmp_path):
    d = _daemon(tmp_path)
    assert d.imu_feed is not None
    bias = np.array([0.01, -0.02, 0.015])          # rad/s (0.6-1.1 deg/s): the BMI088's order
    rng = np.random.default_rng(1)
    rate = 200
    t_all = np.arange(-3 * rate, 3 * rate) / rate   # 3 s of the head waiting, then 3 s of frames
    g_all = bias + rng.normal(0, np.radians(0.014) * np.sqrt(rate), (t_all.size, 3))
    wild = np.array([1e6])                          # a wild packet time: dropped, not fed
    d.rx.imu.append(((t_all[t_all < 0] * 1e9).astype(np.int64), g_all[t_all < 0], 0))
    d.rx.imu.append(((wild * 1e9).astype(np.int64), np.zeros((1, 3)), 0))
    for k in range(30):
        fr = target_frame(k, az_deg=10.0)
        sel = (t_all >= fr.t_start_s) & (t_all < fr.t_end_s)
        d.rx.imu.append(((t_all[sel] * 1e9).astype(np.int64), g_all[sel], 0))
        d.rx.offset_s = time.monotonic() - (fr.t_end_s + 0.01)
        d._process(fr, time.monotonic())
    d.recorder.close()
    g = d.tracker.recon
    assert isinstance(g, GyroAttitude)
    assert g.samples == np.sum(t_all < 3.0) and d.counters["imu_samples"] == g.samples
    assert d.counters["imu_samples_bad_time"] == 1
    assert np.all(np.abs(g.bias.b - bias) < 4 * np.radians(0.014) / np.sqrt(3.0))
    t_last = t_all[-1]
    cmd_pan = g.commands.angles_at(t_last)[0]
    gyro_pan = g.angles_at(t_last)[0]
    assert cmd_pan > 5.0                 # the commands say the head turned toward the target
    assert abs(gyro_pan) < 0.05          # the gyro says it did not (the fake link moved nothing)


def test_imu_feed_releases_in_time_order_before_the_frame_end():
    f = ImuFeed()
    f.push([300_000_000, 100_000_000], [[3, 3, 3], [1, 1, 1]])
    f.push([200_000_000, 50_000_000_000], [[2, 2, 2], [9, 9, 9]])
    t, g, _ = f.release(0.25)
    assert t.tolist() == pytest.approx([0.1, 0.2], abs=1e-15) and g[:, 0].tolist() == [1, 2]
    assert f.bad_time == 1               # 50 s: more than AHEAD_S past the frame
    f.push([150_000_000], [[5, 5, 5]])   # late: before what was already released
    t, g, _ = f.release(0.35)
    assert t.tolist() == pytest.approx([0.3], abs=1e-15) and f.late == 1
    f.restart(10.0)
    f.push([9_000_000_000, 10_050_000_000], [[1, 1, 1], [2, 2, 2]])
    t, _, _ = f.release(10.1)
    assert t.tolist() == pytest.approx([10.05], abs=1e-12)


def test_the_daemon_records_what_it_fed_and_replay_feeds_it_again(tmp_path):
    # The batches come as the receiver queues them, accelerometer included (a Horizon's data type 6),
    # some out of order across packets and one late (before a frame already released: dropped):
    # /imu holds per frame exactly what the tracker got, and the replay's gyro attitude is the
    # daemon's, frame by frame, to the bit (while dead reckoning the commands would be degrees off).
    from foveatrack.recording import RecordingReader
    from foveatrack.replay import replay_recording

    d = _daemon(tmp_path)
    rng = np.random.default_rng(2)
    rate = 200
    t_all = np.arange(-2 * rate, 2 * rate) / rate
    t_ns_all = (t_all * 1e9).astype(np.int64) + 1_234          # the sensor's ns, off the 5 ms grid
    g_all = np.array([0.01, -0.02, 0.015]) + rng.normal(0, 0.003, (t_all.size, 3))
    a_all = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.01, (t_all.size, 3))
    fed = []
    pre = t_all < 0
    d.rx.imu.append((t_ns_all[pre], g_all[pre], 0, a_all[pre]))
    for k in range(20):
        fr = target_frame(k, az_deg=10.0)
        sel = np.flatnonzero((t_all >= fr.t_start_s) & (t_all < fr.t_end_s))
        half = sel[: sel.size // 2]
        d.rx.imu.append((t_ns_all[sel[half.size:]], g_all[sel[half.size:]], 0, a_all[sel[half.size:]]))
        d.rx.imu.append((t_ns_all[half], g_all[half], 0, a_all[half]))     # the earlier packet second
        if k == 10:
            d.rx.imu.append((t_ns_all[:1], g_all[:1], 0, a_all[:1]))     # late: long released
        d.rx.offset_s = time.monotonic() - (fr.t_end_s + 0.01)
        d._process(fr, time.monotonic())
        fed.append(d.tracker.recon.samples)
    d.recorder.close()
    assert d.imu_feed.late == 1
    got = list(RecordingReader(tmp_path / "rec.mcap").imu())
    assert [b.frame_id for b in got] == list(range(20))
    assert np.diff([0] + fed).tolist() == [len(b) for b in got]     # what the tracker took, frame by frame
    t = np.concatenate([b.t_s for b in got])
    n = int(np.sum(t_ns_all * 1e-9 < target_frame(19).t_end_s))
    assert t.tobytes() == (t_ns_all[:n] * 1e-9).tobytes()          # the daemon's own floats, in time order
    assert np.concatenate([b.gyro_rad_s for b in got]).tobytes() == g_all[:n].tobytes()
    assert np.concatenate([b.accel_g for b in got]).tobytes() == a_all[:n].tobytes()
    res = replay_recording(tmp_path / "rec.mcap")
    c = res.comparison
    assert c["gyro_samples_recorded"] is True
    assert c["detections_equal"] and c["commands_equal"] and c["commands_compared"] == 20, c
    assert np.array_equal(res.frames["head_pan_deg"], res.recorded["head_pan_deg"])
    assert np.array_equal(res.frames["head_tilt_deg"], res.recorded["head_tilt_deg"])
    g = d.tracker.recon
    assert g.commands.angles_at(1.9)[0] - g.angles_at(1.9)[0] > 1.0   # the two attitudes do differ here
