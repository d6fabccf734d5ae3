"""LivoxClient <-> VirtualLivox end to end on loopback (UDP, real sockets, real time)."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from child_procs import dies_with_this_process
from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.client import CONNECTED, LivoxClient
from foveatrack.livox.protocol import PointBatch
from sim.virtual_lidar import VirtualLivox

RATE = 100_000.0
SLOT_NS = 1e9 / RATE
ROOT = Path(__file__).resolve().parents[2]


def truth(i):
    """Analytic scene: slot i returns this point (every 10th slot: no return)."""
    i = np.asarray(i)
    xyz = np.stack([5.0 + (i % 1000) * 0.001, -2.0 + (i % 7) * 0.5, np.full(i.shape, 1.25)], axis=1)
    return xyz, (i % 151).astype(np.uint8), (i % 10) != 0


def analytic_source(t0_ns, t1_ns):
    i = np.arange(int(np.ceil(t0_ns / SLOT_NS - 1e-6)), int(np.ceil(t1_ns / SLOT_NS - 1e-6)))
    xyz, refl, ret = truth(i)
    return xyz[ret], refl[ret], np.round(i[ret] * SLOT_NS).astype(np.int64)


def make_pair(loss_rate=0.0, link_timeout_s=3.0, packet_type=2, sensor_ip="127.0.0.1", client_sensor_ip=None):
    client = LivoxClient(
        client_sensor_ip or sensor_ip, "127.0.0.1", cmd_port=0, data_port=0, broadcast_port=0,
        point_rate_hz=RATE, link_timeout_s=link_timeout_s, retry_period_s=0.1, heartbeat_period_s=0.1,
    )
    lidar = VirtualLivox(
        analytic_source, bind_ip=sensor_ip, cmd_port=0, broadcast_addr=("127.0.0.1", client.broadcast_port),
        point_rate_hz=RATE, packet_type=packet_type, loss_rate=loss_rate, seed=7, broadcast_period_s=0.05,
        link_timeout_s=link_timeout_s,
    )
    return client, lidar


def collect(client, seconds):
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += client.poll(0.02)
    return PointBatch.concat(out)


def check_against_truth(b: PointBatch):
    i = np.rint(b.t_ns / SLOT_NS).astype(np.int64)
    assert np.abs(b.t_ns - i * SLOT_NS).max() <= 2.0
    xyz, refl, ret = truth(i)
    assert ret.all()  # no-return slots never come out as points
    assert np.abs(b.xyz - xyz).max() <= 0.0005 + 1e-9
    np.testing.assert_array_equal(b.reflectivity, refl)
    return i


@pytest.mark.parametrize("packet_type", [0, 2, 4])
def test_discovery_handshake_sampling_and_points(packet_type):
    client, lidar = make_pair(packet_type=packet_type)
    with client, lidar:
        client.connect(timeout_s=3.0)
        assert client.state == CONNECTED
        assert client.device_broadcast_code == lidar.broadcast_code and client.device_type == 3
        assert client.poll(0.1) == []  # nothing before start sampling
        client.start_sampling()
        b = collect(client, 0.4)
        assert client.sampling
        i = check_against_truth(b)
        # consecutive slots, none lost on loopback: every returning slot in the span is there
        span = np.arange(i.min(), i.max() + 1)
        assert len(b) == truth(span)[2].sum()
        assert client.stats()["heartbeat_acks"] >= 1
        client.stop_sampling()
        collect(client, 0.2)  # drain what was in flight
        assert not client.sampling
        assert collect(client, 0.2).t_ns.size == 0
        assert client.stats()["dropped_total"] == 0
    assert lidar.counters["sampling_stop"] == 1


def test_garbage_from_other_address_and_bad_packets_are_counted_and_dropped():
    client, lidar = make_pair()
    junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    junk.bind(("127.0.0.2", 0))  # another host on the loopback net
    same_ip = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    same_ip.bind(("127.0.0.1", 0))
    good = P.encode_data_packets(np.ones((96, 3)), np.ones(96), 0, RATE)[0]
    with client, lidar, junk, same_ip:
        client.connect(3.0)
        client.start_sampling()
        collect(client, 0.1)
        for port in (client.data_port, client.cmd_port, client.broadcast_port):
            for _ in range(5):
                junk.sendto(b"\xaa\x01garbage" * 3, ("127.0.0.1", port))
                junk.sendto(good, ("127.0.0.1", port))  # well formed but foreign
        same_ip.sendto(good[:100], ("127.0.0.1", client.data_port))
        same_ip.sendto(b"\x05" + bytes(8) + b"\x09" + bytes(20), ("127.0.0.1", client.data_port))
        same_ip.sendto(b"\xaa\x01\x00", ("127.0.0.1", client.cmd_port))
        b = collect(client, 0.3)
        check_against_truth(b)
        assert len(b) > 0.2 * RATE * 0.9 * 0.9
        d = client.dropped
        assert d["foreign_source"] == 30
        assert d["data_truncated"] == 1 and d["data_unknown_type"] == 1
        assert d["ctrl_too_short"] == 1
        assert client.connected


def test_packet_loss_is_seeded_and_the_rest_arrives():
    client, lidar = make_pair(loss_rate=0.1)
    with client, lidar:
        client.connect(3.0)
        client.start_sampling()
        b = collect(client, 0.5)
        client.stop_sampling()
        b = PointBatch.concat([b, collect(client, 0.2)])
        check_against_truth(b)
        sent, lost = lidar.counters["packets_sent"], lidar.counters["packets_lost"]
        assert client.decoder.counters["packets"] == sent
        assert 0.03 < lost / (sent + lost) < 0.2


def test_client_ignores_a_lidar_at_another_address():
    client, lidar = make_pair(sensor_ip="127.0.0.2", client_sensor_ip="127.0.0.1")
    with client, lidar:
        with pytest.raises(UserError, match="127.0.0.1"):
            client.connect(timeout_s=0.4)
        assert client.counters["foreign_source"] >= 2


@pytest.mark.slow
def test_link_loss_and_recovery_with_a_restarted_lidar():
    client, lidar = make_pair(link_timeout_s=0.4)
    with client:
        lidar.start()
        client.connect(3.0)
        client.start_sampling()
        assert len(collect(client, 0.2)) > 0
        port = lidar.cmd_port
        lidar.stop()
        collect(client, 0.8)
        assert client.counters["link_lost"] == 1 and not client.connected
        lidar2 = VirtualLivox(
            analytic_source, cmd_port=port, broadcast_addr=("127.0.0.1", client.broadcast_port),
            point_rate_hz=RATE, broadcast_period_s=0.05,
        )
        with lidar2:
            # re-handshakes and asks for data again; how soon depends on the machine's load (seen: more
            # than 0.6 s beside three other test runs), so wait for it rather than for a fixed time
            parts, end = [], time.monotonic() + 10.0
            while time.monotonic() < end and not (client.connected and client.sampling and parts):
                b = collect(client, 0.2)
                if len(b):
                    parts.append(b)
            assert client.connected and client.sampling
            b = PointBatch.concat(parts + [collect(client, 0.2)])
            check_against_truth(b)
            assert len(b) > 0


def test_subprocess_entry_point_serves_and_stops_on_sigterm():
    client = LivoxClient("127.0.0.1", cmd_port=0, data_port=0, broadcast_port=0, point_rate_hz=240_000.0)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        dies_with_this_process([sys.executable, "-m", "sim.virtual_lidar", "--cmd-port", "0", "--broadcast-port",
                                str(client.broadcast_port), "--wall-m", "20"]),
        stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT,
    )
    try:
        assert proc.stdout.readline().startswith("READY 127.0.0.1 ")
        with client:
            client.connect(5.0)
            client.start_sampling()
            b = collect(client, 0.3)
            assert len(b) > 0
            np.testing.assert_allclose(b.xyz[:, 0], 20.0, atol=0.0006)  # the wall
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=5)
        assert proc.returncode == 0 and "packets_sent=" in out
    finally:
        if proc.poll() is None:
            proc.kill()


def test_stream_clock_follows_time_scale():
    lidar = VirtualLivox(analytic_source, cmd_port=0, broadcast_addr=("127.0.0.1", 9), time_scale=2.5, t_start_ns=1000)
    try:
        assert lidar.stream_time_ns(123.0) == 1000  # not started: the start time
        lidar._mono0 = 100.0
        assert lidar.stream_time_ns(100.4) == 1000 + 1_000_000_000
    finally:
        lidar._close()


def test_port_in_use_is_a_user_error():
    with VirtualLivox(analytic_source, cmd_port=0, broadcast_addr=("127.0.0.1", 9)) as a:
        with pytest.raises(UserError, match=f"cannot bind UDP 127.0.0.1:{a.cmd_port}"):
            VirtualLivox(analytic_source, cmd_port=a.cmd_port)
