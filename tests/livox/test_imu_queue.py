"""IMU packets are held only for a reader that takes them, and never more than a bounded queue
(issue 26: a daemon without attitude = "gyro" kept every packet of a Horizon, ~1 MB/min)."""

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P


def imu_packets(n, t0_ns=0):
    t = t0_ns + np.arange(n, dtype=np.int64) * 5_000_000          # 200 Hz
    return P.encode_imu_packets(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1))), t


def test_imu_packets_not_kept_when_nobody_takes_them():
    dec = P.DataDecoder(keep_imu=False)
    pkts, _ = imu_packets(1000)
    dec.decode(pkts)
    assert len(dec._imu) == 0 and len(dec.take_imu().t_ns) == 0
    assert dec.counters["imu_packets"] == 1000 and dec.counters["imu_packets_unused"] == 1000


def test_the_imu_queue_is_bounded_keeps_the_newest_and_counts_what_it_dropped():
    dec = P.DataDecoder(imu_queue_packets=300)
    pkts, t = imu_packets(1000)
    for a in range(0, 1000, 100):
        dec.decode(pkts[a:a + 100])
        assert len(dec._imu) <= 300
    got = dec.take_imu()
    assert np.array_equal(got.t_ns, t[-300:])
    assert dec.counters["imu_packets_dropped"] == 700 and dec.counters["imu_packets"] == 1000
    # taken in time: nothing dropped
    dec2 = P.DataDecoder(imu_queue_packets=300)
    n = 0
    for a in range(0, 1000, 100):
        dec2.decode(pkts[a:a + 100])
        n += len(dec2.take_imu().t_ns)
    assert n == 1000 and dec2.counters["imu_packets_dropped"] == 0


def test_a_bad_queue_size_is_a_clear_error():
    with pytest.raises(UserError, match="imu_queue_packets"):
        P.DataDecoder(imu_queue_packets=0)


def test_the_daemon_holds_imu_packets_only_with_attitude_gyro(tmp_path):
    """The daemon's decoder is set to keep IMU packets exactly when its tracker reads the gyro."""
    import os

    from foveatrack.daemon import Daemon, load_config

    master, slave = os.openpty()               # a bare pty stands in for the head
    os.symlink(os.ttyname(slave), tmp_path / "head")
    for attitude, keep in (("commands", False), ("gyro", True)):
        cfg = tmp_path / f"{attitude}.toml"
        cfg.write_text(f"""
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
cmd_port = 0
data_port = 0
broadcast_port = 0
[head]
port = "{tmp_path / 'head'}"
[tracker]
attitude = "{attitude}"
""")
        d = Daemon(load_config(cfg), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
        d._open()
        try:
            assert d.client.decoder.keep_imu is keep and d.rx.want_imu is keep
        finally:
            d.client.close()
            d.head.close()
    os.close(master), os.close(slave)
