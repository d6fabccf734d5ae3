"""The sensor-time guard: wrong packet times are dropped and counted, a restarted or jumped sensor
clock is re-anchored, and nothing is allocated by a time difference (issue 16, faults 1 and 2)."""

import time

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
    # (read as it came: the first 5 ms at once, the rest 0.3 s later; a first read that holds a gap
    # of more than CONTIGUOUS_S has no host time yet to say the sensor's clock got there)
    xyz, t, r = xyz[keep], t[keep], r[keep]
    out = g.push(xyz[:500], t[:500], r[:500], host_s=100.0)
    out += g.push(xyz[500:], t[500:], r[500:], host_s=100.3) + g.flush()
    assert sum(len(a) for a in out) == keep.sum() and all(a.epoch == 0 for a in out)
    assert np.array_equal(np.concatenate([a.t_ns for a in out]), t)
    assert g.counters["bad_time_points"] == 0 and g.counters["clock_jumps"] == 0


@pytest.mark.parametrize("bad_t_s", [1e9, 25.0, 0.0, 4.0])   # random, 20 s ahead, a reset-looking 0, backwards
def test_one_packet_with_a_wrong_time_is_dropped_and_counted(bad_t_s):
    g = SensorTimeGuard()
    xyz, t, r = packets(5.0, 50)
    t = t.copy()
    t[2000:2100] = int(bad_t_s * 1e9) + np.arange(100) * 10_000    # packet 20 of 50
    out = g.push(xyz, t, r, host_s=100.0) + g.flush()
    got = np.concatenate([a.t_ns for a in out])
    assert got.size == 4900 and not np.isin(t[2000:2100], got).any()
    assert g.counters["bad_time_segments"] == 1 and g.counters["bad_time_points"] == 100
    # named by what they are: ahead of the sensor's clock, or older than the stream
    kind = "early" if bad_t_s > 5.0 else "stale"
    assert g.counters[f"{kind}_points"] == 100 and g.counters[f"{kind}_segments"] == 1
    assert g.counters["duplicate_points"] == 0 and g.counters["late_points"] == 0 and g.counters["lost_slots"] == 0
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
    out += g.flush()
    assert g.epoch == 0
    # consecutive bad packets with random times are separate segments; each is counted
    assert g.counters["bad_time_points"] == bad.sum() * PKT
    assert sum(len(a) for a in out) == (~bad).sum() * PKT


def test_a_restarted_clock_is_reanchored_and_its_points_kept():
    g = SensorTimeGuard()
    out = feed(g, 42.0, 200, host_s=1000.0)          # 0.2 s of stream at sensor time 42 s
    out2 = feed(g, 0.0, 200, host_s=1005.0)          # the unit restarted: its clock is back at 0
    out2 += g.flush()
    assert g.epoch == 1 and g.counters["clock_jumps"] == 1
    # the candidate's points are handed on, not lost (out2[0]: the old clock's last held-back points)
    assert sum(len(a) for a in out2 if a.epoch == 1) == 200 * PKT
    assert [a.epoch for a in out2][:2] == [0, 1] and all(a.epoch == 1 for a in out2[1:])
    (jump,) = g.take_jumps()
    assert jump.last_t_s == pytest.approx(42.0 + 0.2 - 1e-5) and jump.new_t_s == 0.0
    assert g.counters["bad_time_points"] == 0


def test_a_forward_jump_longer_than_the_host_time_is_a_new_clock():
    g = SensorTimeGuard()
    feed(g, 1.0, 100, host_s=10.0)
    feed(g, 21.2, 200, host_s=10.1)                  # 20 s ahead, and it stays there (a sync change)
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
    assert off0 == pytest.approx(s.last_packet_mono - 500.0 - 0.03 + 1e-5, abs=0.05)
    # the unit restarts: its new clock streams in real time, and is re-anchored once it has run
    # alone for the guard's confirm time (host time)
    got = []
    for k in range(40):
        xyz, t, r = packets(0.01 * k, 10)
        c.batches = [PointBatch(xyz, r, t, r)]
        got += s.poll(0)[1]
        if s.epoch:
            break
        time.sleep(0.01)
    assert s.epoch == 1          # (how soon, in host time: test_a_restart_is_still_detected_within_a_second...)
    assert got[-1].epoch == 1 and s.offset_s == pytest.approx(off0 + 500.0, abs=0.6)


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
    out = g.push(xyz[keep][:500], t[keep][:500], r[keep][:500], host_s=100.0)
    out += g.push(xyz[keep][500:5000], t[keep][500:5000], r[keep][500:5000], host_s=100.2)
    out += g.push(xyz[keep][5000:], t[keep][5000:], r[keep][5000:], host_s=100.3)   # across batches too
    assert g.counters["lost_slots"] == 2100
    # the first point of a new clock is not a loss
    feed(g, 0.0, 200, host_s=105.0)
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


# ---------------------------------------------------------------------------------------------------
# Issue 26: what networks do to a stream -- late, early, duplicated and re-sent packets -- told from a
# restarted clock.  A Mid-40 stream in real time: packet k (1 ms, 100 points) leaves at sensor time
# T0 + (k + 1) ms and arrives 0.1 ms later; the receiver reads ``per_batch`` packets at a time.

T0_S, HOST0_S = 30.0, 500.0


def wire(n_packets):
    """The real stream: [(first point time [ns], arrival host time [s])] of each packet."""
    return [(int(T0_S * 1e9) + k * 1_000_000, HOST0_S + (k + 1) * 1e-3 + 1e-4) for k in range(n_packets)]


def deliver(g, sent, per_batch=5):
    """Push ``sent`` (as :func:`wire`, in arrival order) ``per_batch`` packets per read; everything
    handed on, flushed at the end."""
    out = []
    for a in range(0, len(sent), per_batch):
        chunk = sent[a:a + per_batch]
        t = np.concatenate([t0 + np.arange(PKT, dtype=np.int64) * 10_000 for t0, _ in chunk])
        xyz = np.column_stack([np.full(t.size, 10.0), np.zeros(t.size), np.zeros(t.size)])
        out += g.push(xyz, t, np.zeros(t.size, np.uint8), max(h for _, h in chunk))
    return out + g.flush()


def real_points(n_packets):
    return np.concatenate([t0 + np.arange(PKT, dtype=np.int64) * 10_000 for t0, _ in wire(n_packets)])


def assert_all_real_points_in_order(g, out, n_packets, **counts):
    """Every real point handed on once, in time order, in the first epoch; nothing reported lost; the
    counters as given (all other fault counters 0)."""
    got = np.concatenate([a.t_ns for a in out])
    assert all(a.epoch == 0 for a in out) and g.epoch == 0 and g.counters["clock_jumps"] == 0
    assert got.size == n_packets * PKT and np.array_equal(got, real_points(n_packets))
    assert g.counters["lost_slots"] == 0
    for name in ("duplicate_points", "stale_points", "early_points", "late_points", "bad_time_points"):
        assert g.counters[name] == counts.get(name, 0), (name, dict(g.counters))


@pytest.mark.parametrize("ahead_ms", [50, 100, 150])
@pytest.mark.parametrize("per_batch", [1, 5])
def test_one_packet_ahead_is_early_not_a_new_clock(ahead_ms, per_batch):
    g = SensorTimeGuard(point_rate_hz=RATE)
    sent = wire(1000)
    t0, h = sent[400]
    sent.insert(401, (t0 + ahead_ms * 1_000_000, h))        # a copy of packet 400, stamped ahead
    out = deliver(g, sent, per_batch)
    assert_all_real_points_in_order(g, out, 1000, early_points=PKT, bad_time_points=PKT)
    assert g.counters["early_segments"] == 1


def test_a_burst_of_100_packets_5_s_old_is_stale_not_a_new_clock():
    g = SensorTimeGuard(point_rate_hz=RATE)
    sent = wire(8000)
    h = sent[6000][1]
    sent[6001:6001] = [(t0, h) for t0, _ in sent[1000:1100]]   # replayed, all at once
    out = deliver(g, sent)
    assert_all_real_points_in_order(g, out, 8000, stale_points=100 * PKT, bad_time_points=100 * PKT)


@pytest.mark.parametrize("age_ms", [50, 2])
def test_a_packet_re_sent_every_tenth_packet_is_a_duplicate(age_ms):
    g = SensorTimeGuard(point_rate_hz=RATE)
    real = wire(5000)
    sent = []
    for k, (t0, h) in enumerate(real):
        sent.append((t0, h))
        if 500 <= k < 4500 and k % 10 == 0:                   # 4 s of re-sends: 400
            sent.append((real[k - age_ms][0], h))
    out = deliver(g, sent)
    assert_all_real_points_in_order(g, out, 5000, duplicate_points=400 * PKT)
    assert g.counters["duplicate_segments"] == 400


@pytest.mark.parametrize("per_batch", [1, 5])
def test_every_packet_duplicated_is_dropped_and_counted(per_batch):
    g = SensorTimeGuard(point_rate_hz=RATE)
    sent = []
    for k, p in enumerate(wire(4000)):
        sent += [p, p] if 1000 <= k < 3000 else [p]           # 2 s of every packet twice
    out = deliver(g, sent, per_batch)
    assert_all_real_points_in_order(g, out, 4000, duplicate_points=2000 * PKT)


@pytest.mark.parametrize("per_batch", [1, 2, 5])
def test_adjacent_packets_swapped_are_late_accepted_and_put_in_order(per_batch):
    """Overtaken packets: their slots are not lost and their points come out in time order (read
    alone, in the same read as the overtaking packet, or in the next read)."""
    g = SensorTimeGuard(point_rate_hz=RATE)
    sent = wire(3000)
    for k in range(1001, 2000, 2):                            # 500 pairs swapped
        sent[k], sent[k + 1] = sent[k + 1], sent[k]
    out = deliver(g, sent, per_batch)
    assert_all_real_points_in_order(g, out, 3000, late_points=500 * PKT)


def test_a_late_packet_into_a_gap_withdraws_only_its_own_lost_slots():
    g = SensorTimeGuard(point_rate_hz=RATE)
    real = wire(1000)
    sent = [p for k, p in enumerate(real) if k not in (300, 301, 302)]
    sent.insert(302, real[301])                                # 300 and 302 lost, 301 late by 2 packets
    out = deliver(g, sent, 1)
    got = np.concatenate([a.t_ns for a in out])
    assert got.size == 998 * PKT and np.all(np.diff(got) > 0)
    assert g.counters["lost_slots"] == 2 * PKT and g.counters["late_points"] == PKT


def test_a_restart_is_still_detected_within_a_second_and_its_points_kept():
    """Also when the new clock's times fall on the old clock's (a unit 0.3 s after power-on restarts:
    its grid is the old one's), so they read as duplicates until the new clock has run alone."""
    for old_s in (0.3, 42.0):
        g = SensorTimeGuard(point_rate_hz=RATE)
        out = feed(g, old_s - 0.3, 300, host_s=1000.0)         # 0.3 s of the first clock
        host_restart = 1001.0
        out2 = feed(g, 0.0, 500, host_s=host_restart)          # back at 0, in real time
        out2 += g.flush()
        (jump,) = g.take_jumps()
        assert g.epoch == 1 and jump.host_s - host_restart < 1.0 and jump.new_t_s == 0.0
        new = np.concatenate([a.t_ns for a in out2 if a.epoch == 1])
        assert new.size == 500 * PKT and np.all(np.diff(new) > 0)   # every point of the new clock
        assert g.counters["duplicate_points"] == g.counters["stale_points"] == 0
        assert g.counters["lost_slots"] == 0


def test_memory_is_bounded_under_loss():
    g = SensorTimeGuard(point_rate_hz=RATE)
    sent = [p for k, p in enumerate(wire(20000)) if k % 3]    # a third of the packets lost, 20 s
    deliver(g, sent)
    assert len(g._starts) <= 1.0 * 1000 and g.held_points == 0


def test_filled_gaps_join_so_what_is_remembered_stays_small():
    g = SensorTimeGuard(point_rate_hz=RATE)
    sent = wire(3000)
    for k in range(1, 2999, 2):                               # every pair swapped
        sent[k], sent[k + 1] = sent[k + 1], sent[k]
    deliver(g, sent, 1)
    assert len(g._starts) == 1 and g.counters["lost_slots"] == 0
