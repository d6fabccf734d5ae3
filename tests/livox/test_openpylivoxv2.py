"""A third-party driver, ``openpylivoxv2`` (PyPI), discovers, connects to and records from the virtual
lidar, unpatched.

What the harness does around it (the driver's own choices, not the unit's):
- its discovery sends to 255.255.255.255 (ports 65000 and 56000): ``socket.socket.sendto`` is wrapped
  for the test so that the port-65000 query goes to the virtual unit's loopback address instead;
  nothing is broadcast;
- the Mid-360 (HAP) discovery to port 56000 is swallowed (not sent): wherever it lands on this machine
  it reaches the driver's own 0.0.0.0:56000 socket, and the driver then blocks for ever in a
  ``recvfrom`` without timeout waiting for an answer from port 56000 (its bug; a real broadcast is
  looped back the same way);
- it listens for broadcasts on 0.0.0.0:55000 (fixed) and looks for ones from source port 65000
  (fixed), so the unit binds 127.0.0.77:65000; the test is skipped if either port is taken;
- it waits for a broadcast only 0.5 s per discovery, so the unit broadcasts every 0.2 s here;
- its ``dataStart()`` and ``dataStart_RT()`` raise TypeError in 1.0.2 (a missing constructor
  argument), so the test records with ``dataStart_RT_B()`` (real-time binary file), and reads that
  file's layout ("openpylivoxv2", firmware type i16, data type i16, then x, y, z i32 mm, reflectivity
  u8, time f64 s per point);
- it takes a point with y == 0 for "no return" (it tests only y), so the test scene has no y == 0.
"""

import struct
import socket
import threading
import time

import numpy as np
import pytest

from sim.livox_units import MID40
from sim.virtual_lidar import VirtualLivox

openpylivoxv2 = pytest.importorskip("openpylivoxv2")

LIDAR_IP = "127.0.0.77"
RATE = 100_000.0
SLOT_NS = 1e9 / RATE


def truth(i):
    i = np.asarray(i)
    xyz = np.stack([5.0 + (i % 100) * 0.01, (i % 7) * 0.1 - 0.35, np.full(i.shape, 1.25)], axis=1)
    return xyz, (i % 100).astype(np.uint8)


def source(t0_ns, t1_ns):
    i = np.arange(int(np.ceil(t0_ns / SLOT_NS - 1e-6)), int(np.ceil(t1_ns / SLOT_NS - 1e-6)))
    keep = i % 10 != 0  # every 10th slot: no return
    xyz, refl = truth(i[keep])
    return xyz, refl, np.round(i[keep] * SLOT_NS).astype(np.int64)


def _port_free(ip, port, reuse=False):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        if reuse:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((ip, port))
        return True
    except OSError:
        return False
    finally:
        s.close()


@pytest.fixture
def no_broadcast(monkeypatch):
    """Send the driver's 255.255.255.255 datagrams to the virtual unit's address instead."""
    real = socket.socket.sendto
    redirected = []

    def sendto(self, data, *args):
        addr = args[-1]
        if isinstance(addr, tuple) and addr[0] in ("255.255.255.255", "<broadcast>"):
            redirected.append(addr)
            if addr[1] == 56000:
                return len(data)
            addr = (LIDAR_IP, addr[1])
        assert isinstance(addr, tuple) and addr[0].startswith("127."), f"datagram to {addr} off loopback"
        return real(self, data, *args[:-1], addr)

    monkeypatch.setattr(socket.socket, "sendto", sendto)
    return redirected


@pytest.mark.slow
def test_openpylivoxv2_discovers_connects_and_records(tmp_path, no_broadcast, capsys):
    if not _port_free(LIDAR_IP, 65000) or not _port_free("0.0.0.0", 55000, reuse=True):
        pytest.skip("UDP port 65000 on 127.0.0.77 or 55000 is in use")
    lidar = VirtualLivox(source, bind_ip=LIDAR_IP, cmd_port=65000, broadcast_addr=("127.0.0.1", 55000),
                         point_rate_hz=RATE, unit=MID40, broadcast_period_s=0.2)
    out = tmp_path / "rec.bin"
    with lidar:
        sensor = openpylivoxv2.openpylivoxv2(showMessages=True)
        sensor.auto_connect("127.0.0.1")
        try:
            assert sensor._isConnected, capsys.readouterr().out
            assert sensor._deviceType.strip() == "Mid-40"
            assert sensor._serial in ("UNKNOWN", MID40.serial)  # auto_connect does not keep it
            assert sensor.firmware() == "03.08.0000"  # it records only with a known firmware
            sensor.dataStart_RT_B()
            assert sensor._isData
            sensor.saveDataToFile(str(out), 0.1, 0.5)
            end = time.monotonic() + 30.0
            while time.monotonic() < end and sensor._captureStream.thread.is_alive():
                time.sleep(0.1)
            sensor.closeFile()
            sensor.dataStop()
        finally:
            sensor.disconnect()
    printed = capsys.readouterr().out
    assert "Discovered a Livox sensor" in printed and MID40.serial in printed
    assert ("255.255.255.255", 65000) in no_broadcast
    assert lidar.counters["handshakes"] >= 1 and lidar.counters["sampling_start"] >= 1
    raw = out.read_bytes()
    assert raw[:13] == b"openpylivoxv2" and struct.unpack_from("<hh", raw, 13) == (1, 0)  # single return, type 0
    rec = np.frombuffer(raw[17:], np.dtype([("x", "<i4"), ("y", "<i4"), ("z", "<i4"), ("refl", "u1"), ("t", "<f8")]))
    assert len(rec) > 0.5 * RATE * 0.9 * 0.8  # ~0.5 s of 90 % returns (its Python loop may fall behind)
    i = np.rint(rec["t"] * 1e9 / SLOT_NS).astype(np.int64)
    assert np.abs(rec["t"] * 1e9 - i * SLOT_NS).max() < 100  # its times on our 10 us slot grid
    xyz, refl = truth(i)
    mm = np.stack([rec["x"], rec["y"], rec["z"]], axis=1)
    assert np.abs(mm - np.round(xyz * 1000)).max() == 0
    np.testing.assert_array_equal(rec["refl"], refl)
    assert not np.any(i % 10 == 0)  # no-return slots are its "null" points, not records
