"""The sensor-time guard: wrong packet times are dropped and counted, a restarted or jumped sensor
clock is re-anchored, and nothing is allocated by a time difference (issue 16, faults 1 and 2)."""

import numpy as np
import pytest

from foveatrack.frames import FrameSlicer
from foveatrack.sensor_time import SensorTimeGuard

RATE = 100_000          # points/s (a Mid-40)
PKT = 100               # points per packet: 1 ms


def packets(t0_s, n_packets):
    """``n_packets`` consecutive packets of points from sensor time ``t0_s`` (one point per 10 us)."""
    t = int(t0_s * 1e9) + np.arange(n_packets * PKT, dtype=np.int64) * (10**9 // RATE)
    xyz = np.column_stack([np.full(t.size, 10.0), np.zeros(t.size), np.zeros(t.size)])
    return xyz, t, np.zeros(t.size, np.uint8)


def feed(guard, t0_s, n_packets, host_s, per_batch=10):
    """Feed packets as batches of ``per_batch`` arriving at host time host_s + their sensor span."""
    out = []
    xyz, t, r = packets(t0_s, n_packets)
    step = per_batch * PKT
    for a in range(0, t.size, step):
        out += guard.push(xyz[a:a + step], t[a:a + step], r[a:a + step], host_s + (t[min(a + step, t.size) - 1] - t[0]) * 1e-9)
    return out


def test_a_continuous_stream_with_lost_packets_passes_whole():
    g = SensorTimeGuard()
    xyz, t, r = packets(5.0, 300)
    keep = np.ones(t.size, bool)
    keep[1000:3000] = False          # 20 lost packets (20 ms): a forward step the host time allows
    out = g.push(xyz[keep], t[keep], r[keep], host_s=100.0)
    assert len(out) == 1 and len(out[0]) == keep.sum() and out[0].epoch == 0
    assert g.counters["bad_time_points"] == 0 and g.counters["clock_jumps"] == 0


@pytest.mark.parametrize("bad_t_s", [1e9, 25.0, 0.0, 4.0])   # random, 20 s ahead, a reset-looking 0, backwards
def test_one_packet_with_a_wrong_time_is_dropped_and_counted(bad_t_s):
    g = SensorTimeGuard()
    xyz, t, r = packets(5.0, 50)
    t = t.copy()
    t[2000:2100] = int(bad_t_s * 1e9) + np.arange(100) * 10_000    # packet 20 of 50
    out = g.push(xyz, t, r, host_s=100.0)
    got = np.concatenate([a.t_ns for a in out])
    assert got.size == 4900 and not np.isin(t[2000:2100], got).any()
    assert g.counters["bad_time_segments"] == 1 and g.counters["bad_time_points"] == 100
    assert g.epoch == 0 and g.counters["clock_jumps"] == 0


def test_random_times_in_two_percent_of_packets_never_reanchor():
    rng = np.random.default_rng(3)
    g = SensorTimeGuard()
    xyz, t, r = packets(5.0, 2000)
    t = t.copy()
    bad = rng.random(2000) < 0.02
    for k in np.flatnonzero(bad):
        t[k * PKT:(k + 1) * PKT] = rng.integers(0, 2**62) + np.arange(PKT) * 10_000
    out = []
    for a in range(0, t.size, 1000):
        out += g.push(xyz[a:a + 1000], t[a:a + 1000], r[a:a + 1000], host_s=100.0 + a * 1e-5)
    assert g.epoch == 0
    # consecutive bad packets with random times are separate segments; each is counted
    assert g.counters["bad_time_points"] == bad.sum() * PKT
    assert sum(len(a) for a in out) == (~bad).sum() * PKT


def test_a_restarted_clock_is_reanchored_and_its_points_kept():
    g = SensorTimeGuard()
    out = feed(g, 42.0, 200, host_s=1000.0)          # 0.2 s of stream at sensor time 42 s
    out2 = feed(g, 0.0, 200, host_s=1005.0)          # the unit restarted: its clock is back at 0
    assert g.epoch == 1 and g.counters["clock_jumps"] == 1
    assert sum(len(a) for a in out2) == 200 * PKT    # the candidate's points are handed on, not lost
    assert all(a.epoch == 1 for a in out2[-1:]) and out2[0].epoch == 1
    (jump,) = g.take_jumps()
    assert jump.last_t_s == pytest.approx(42.0 + 0.2 - 1e-5) and jump.new_t_s == 0.0
    assert g.counters["bad_time_points"] == 0


def test_a_forward_jump_longer_than_the_host_time_is_a_new_clock():
    g = SensorTimeGuard()
    feed(g, 1.0, 100, host_s=10.0)
    feed(g, 21.2, 100, host_s=10.1)                  # 20 s ahead, and it stays there (a sync change)
    assert g.epoch == 1
    # a gap the host time allows (the lidar paused 3 s) is the same clock
    feed(g, 24.5, 100, host_s=13.5)
    assert g.epoch == 1


def test_the_stream_via_livestream_resets_the_offset_on_a_new_clock():
    from foveatrack.live_devices import LidarStream
    from foveatrack.livox.protocol import PointBatch

    class FakeClient:
        def __init__(self):
            self.batches, self.counters = [], {"packets": 0}

        def poll(self, timeout_s):
            b, self.batches = self.batches, []
            self.counters["packets"] += len(b)
            return b

    c = FakeClient()
    s = LidarStream(c)
    xyz, t, r = packets(500.0, 30)
    c.batches = [PointBatch(xyz, r, t, r)]
    s.poll(0)
    off0 = s.offset_s
    assert off0 == pytest.approx(s.last_packet_mono - 500.0 - 0.003 + 1e-5, abs=0.05)
    xyz, t, r = packets(0.0, 30)
    c.batches = [PointBatch(xyz, r, t, r)]
    _, got = s.poll(0)
    assert s.epoch == 1 and got[0].epoch == 1 and s.offset_s == pytest.approx(off0 + 500.0, abs=0.05)


def test_the_slicer_never_allocates_by_a_wild_time():
    sl = FrameSlicer(10.0)
    xyz, t, r = packets(1.0, 300)
    frames = sl.push(xyz, t, r)
    # one point 2.6e9 s ahead once asked for a (26113021067,) array; now the slicer restarts there
    frames += sl.push(np.ones((1, 3)), np.array([2**61], np.int64), np.zeros(1, np.uint8))
    assert sl.restarts == 1 and sl.gap_dropped_points > 0
    more = sl.push(np.ones((1, 3)), np.array([2**61 + 250_000_000], np.int64), np.zeros(1, np.uint8))
    assert len(more) == 2 and more[0].n_points == 1 and more[0].t_ns[0] == 2**61
    assert len(sl.flush()) == 1
    # a plain gap within max_gap_frames still gives its empty frames
    sl2 = FrameSlicer(10.0)
    sl2.push(*packets(1.0, 1)[:2])
    assert len(sl2.push(np.ones((1, 3)), np.array([int(31.05e9)], np.int64))) == 300


def test_lost_packets_are_counted_by_the_slots_missing_between_points():
    g = SensorTimeGuard(point_rate_hz=RATE)
    xyz, t, r = packets(5.0, 300)
    keep = np.ones(t.size, bool)
    keep[1000:3000] = False            # 20 packets
    keep[10_000:10_100] = False        # 1 packet
    out = g.push(xyz[keep][:5000], t[keep][:5000], r[keep][:5000], host_s=100.0)
    out += g.push(xyz[keep][5000:], t[keep][5000:], r[keep][5000:], host_s=100.1)   # across batches too
    assert g.counters["lost_slots"] == 2100
    # the first point of a new clock is not a loss
    g.push(*packets(0.0, 30), host_s=105.0)
    assert g.counters["lost_slots"] == 2100 and g.epoch == 1


def test_a_stalled_receiver_then_a_lidar_that_skipped_time_is_the_same_clock():
    """Read late (the receiver stalled 0.4 s), then the next packets 0.5 s later in sensor time (the
    lidar skipped) only 0.1 s of host time later: the host clock says the sensor can read that now."""
    g = SensorTimeGuard()
    feed(g, 10.0, 100, host_s=100.0)                 # sensor 10.0-10.1 s read at host 100.0-100.1
    feed(g, 10.1, 10, host_s=100.5)                  # sensor 10.1-10.11 s read late at host 100.5
    feed(g, 10.6, 100, host_s=100.6)                 # sensor 10.6 s at host 100.6: on time
    assert g.epoch == 0 and g.counters["bad_time_points"] == 0
    # but a time later than the host clock allows is still a wrong one
    feed(g, 12.0, 1, host_s=100.75)
    feed(g, 10.75, 10, host_s=100.76)
    assert g.counters["bad_time_points"] == 100 and g.epoch == 0
