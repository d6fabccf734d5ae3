"""The virtual unit's command sets per model, and our client's state/error/IMU reporting against it."""

import socket
import struct
import time

import numpy as np
import pytest

from foveatrack.livox import protocol as P
from foveatrack.livox.client import CONNECTED, LivoxClient
from sim.livox_units import AVIA, GENERIC, HORIZON, MID40, MID70, TELE15, UNITS, unit_for_preset
from sim.virtual_lidar import VirtualLivox

RATE = 100_000.0


def empty_source(t0, t1):
    return np.zeros((0, 3)), np.zeros(0, np.uint8), np.zeros(0, np.int64)


class RawHost:
    """A bare host: handshakes, then sends single commands and returns the ACK payload."""

    def __init__(self, lidar):
        self.lidar = lidar
        self.cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.cmd.bind(("127.0.0.1", 0))
        self.cmd.settimeout(2.0)
        self.data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.data.bind(("127.0.0.1", 0))
        self.seq = 0

    def ask(self, cmd_set, cmd_id, payload=b"", raw=None):
        self.seq += 1
        buf = raw if raw is not None else P.make_cmd(cmd_id, self.seq, payload, cmd_set)
        self.cmd.sendto(buf, self.lidar.address)
        while True:
            f = P.parse_control(self.cmd.recvfrom(2048)[0])
            if f.cmd_type == P.CMD_TYPE_ACK:
                return f.payload

    def handshake(self):
        self.seq += 1
        return self.ask(0, 1, raw=P.make_handshake(self.seq, "127.0.0.1", self.data.getsockname()[1],
                                                   self.cmd.getsockname()[1]))

    def close(self):
        self.cmd.close()
        self.data.close()


def served(unit, **kw):
    return VirtualLivox(empty_source, cmd_port=0, broadcast_addr=("127.0.0.1", 9), point_rate_hz=RATE,
                        unit=unit, broadcast_period_s=60.0, **kw)


def test_unit_table_covers_every_preset_and_falls_back():
    for name in ("prototype", "mid40", "mid100", "mid70", "horizon", "tele15", "avia"):
        u = unit_for_preset(name)
        assert not u.fallback and len(u.broadcast_code()) == 15 and u.broadcast_code()[-1] == "1"
        assert u.has_imu == (name in ("horizon", "tele15", "avia"))
    assert unit_for_preset("mid40").data_type(0, 0) == 0 and unit_for_preset("mid40").data_type(1, 0) == 1
    assert unit_for_preset("horizon").data_type(0, 0) == 2 and unit_for_preset("horizon").data_type(0, 2) == 4
    assert UNITS["mid100"].heads == 3 and UNITS["mid100"].broadcast_code(3).endswith("3")
    assert unit_for_preset("no-such-preset") is GENERIC and GENERIC.fallback


def test_commands_before_handshake_are_refused_but_info_is_answered():
    lidar = served(MID40)
    host = RawHost(lidar)
    with lidar:
        try:
            assert host.ask(0, P.CMD_ID_SAMPLING, b"\x01") == b"\x01"
            assert P.parse_device_info(host.ask(0, P.CMD_ID_QUERY_INFO)) == (0, MID40.firmware)
            assert host.handshake() == b"\x00"
            assert not lidar.sampling
        finally:
            host.close()


@pytest.mark.parametrize("unit,cmd_set,cmd_id,payload,expect_ret", [
    (MID40, 0, P.CMD_ID_COORDINATE_SYSTEM, b"\x01", 0),      # Mid-40: spherical = type 1
    (MID40, 1, P.LIDAR_ID_SET_FAN, b"\x01", 1),              # no fan on a Mid-40
    (HORIZON, 1, P.LIDAR_ID_SET_FAN, b"\x01", 0),
    (MID40, 1, P.LIDAR_ID_SET_IMU_FREQ, b"\x01", 1),         # no IMU
    (TELE15, 1, P.LIDAR_ID_SET_IMU_FREQ, b"\x00", 0),
    (MID40, 1, P.LIDAR_ID_SET_RETURN_MODE, b"\x02", 1),      # single return only
    (HORIZON, 1, P.LIDAR_ID_SET_RETURN_MODE, b"\x02", 0),    # dual: type 4
    (HORIZON, 1, P.LIDAR_ID_SET_RETURN_MODE, b"\x03", 1),    # triple is Avia's
    (MID40, 1, P.LIDAR_ID_RAIN_FOG, b"\x01", 0),
    (HORIZON, 1, P.LIDAR_ID_RAIN_FOG, b"\x01", 1),
    (HORIZON, 1, P.LIDAR_ID_SET_MODE, b"\x07", 1),           # no such mode
    (HORIZON, 1, P.LIDAR_ID_WRITE_EXTRINSIC, b"\x00" * 23, 1),
    (HORIZON, 0, P.CMD_ID_SET_IP, b"\x01" + bytes(12), 1),   # a virtual unit keeps its address
    (HORIZON, 2, 0, b"", 1),                                 # hub set: this is a lidar
    (HORIZON, 0, 0x30, b"", 1),                              # unknown id
])
def test_command_answers(unit, cmd_set, cmd_id, payload, expect_ret):
    lidar = served(unit)
    host = RawHost(lidar)
    with lidar:
        try:
            assert host.handshake() == b"\x00"
            assert host.ask(cmd_set, cmd_id, payload)[0] == expect_ret
        finally:
            host.close()


def test_settings_round_trip_and_change_the_data_type():
    lidar = served(HORIZON)
    host = RawHost(lidar)
    with lidar:
        try:
            host.handshake()
            ext = struct.pack("<fffiii", 1.5, -2.0, 90.0, 100, -200, 300)
            assert host.ask(1, P.LIDAR_ID_WRITE_EXTRINSIC, ext) == b"\x00"
            assert host.ask(1, P.LIDAR_ID_READ_EXTRINSIC) == b"\x00" + ext
            assert host.ask(1, P.LIDAR_ID_SET_RETURN_MODE, b"\x02") == b"\x00"
            assert host.ask(1, P.LIDAR_ID_GET_RETURN_MODE) == b"\x00\x02" and lidar.packet_type == 4
            assert host.ask(1, P.LIDAR_ID_SET_IMU_FREQ, b"\x00") == b"\x00"
            assert host.ask(1, P.LIDAR_ID_GET_IMU_FREQ) == b"\x00\x00"
            assert host.ask(1, P.LIDAR_ID_GET_FAN) == b"\x00\x01"
            ip = host.ask(0, P.CMD_ID_GET_IP)
            assert ip[:2] == b"\x00\x01" and ip[2:6] == bytes((127, 0, 0, 1)) and len(ip) == 14
            # power-saving: sampling refused until normal again; the heartbeat tells the state
            assert host.ask(1, P.LIDAR_ID_SET_MODE, b"\x02") == b"\x00"
            assert P.parse_heartbeat_ack(host.ask(0, P.CMD_ID_HEARTBEAT))[1] == 2
            assert host.ask(0, P.CMD_ID_SAMPLING, b"\x01") == b"\x01"
            assert host.ask(1, P.LIDAR_ID_SET_MODE, b"\x01") == b"\x00"
            assert host.ask(0, P.CMD_ID_SAMPLING, b"\x01") == b"\x00" and lidar.sampling
        finally:
            host.close()


def test_configuration_parameters_per_unit():
    kv = struct.pack("<HHB", P.PARAM_KEY_HIGH_SENSITIVITY, 1, 0)
    for unit, ok in ((AVIA, True), (TELE15, True), (MID70, False), (HORIZON, False)):
        lidar = served(unit)
        host = RawHost(lidar)
        with lidar:
            try:
                host.handshake()
                ack = host.ask(0, P.CMD_ID_WRITE_PARAMS, kv)
                if ok:
                    assert ack == struct.pack("<BHB", 0, 0, 0)
                    rd = host.ask(0, P.CMD_ID_READ_PARAMS, struct.pack("<BH", 1, P.PARAM_KEY_HIGH_SENSITIVITY))
                    assert rd == struct.pack("<BHB", 0, 0, 0) + struct.pack("<HHB", 1, 1, 0)
                else:
                    assert ack == struct.pack("<BHB", 1, P.PARAM_KEY_HIGH_SENSITIVITY, P.KEY_NOT_SUPPORTED)
            finally:
                host.close()


def test_non_loopback_host_is_refused():
    lidar = served(MID40)
    host = RawHost(lidar)
    with lidar:
        try:
            host.seq += 1
            ack = host.ask(0, 1, raw=P.make_handshake(host.seq, "192.0.2.7", 56001, 55501))
            assert ack == b"\x01" and lidar.host is None
        finally:
            host.close()


def test_status_codes_round_trip():
    for name, (bit, width) in P.STATUS_FIELDS.items():
        v = (1 << width) - 1
        code = P.encode_status_code(**{name: v})
        assert code == v << bit and P.decode_status_code(code)[name] == v
        assert sum(P.decode_status_code(code).values()) == v
    with pytest.raises(ValueError):
        P.encode_status_code(motor_status=4)


def make_client(**kw):
    return LivoxClient("127.0.0.1", "127.0.0.1", cmd_port=0, data_port=0, broadcast_port=0, point_rate_hz=RATE,
                       retry_period_s=0.1, heartbeat_period_s=0.1, **kw)


def analytic_source(t0_ns, t1_ns):
    i = np.arange(int(np.ceil(t0_ns * RATE / 1e9 - 1e-6)), int(np.ceil(t1_ns * RATE / 1e9 - 1e-6)))
    xyz = np.stack([np.full(i.size, 10.0), np.zeros(i.size), np.zeros(i.size)], axis=1)
    return xyz, np.full(i.size, 50, np.uint8), np.round(i * 1e9 / RATE).astype(np.int64)


def run_until(client, cond, timeout_s=4.0):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and not cond():
        client.poll(0.02)
    return cond()


def test_client_reports_firmware_state_status_and_decodes_imu():
    client = make_client()
    lidar = VirtualLivox(analytic_source, cmd_port=0, broadcast_addr=("127.0.0.1", client.broadcast_port),
                         point_rate_hz=RATE, unit=HORIZON, broadcast_period_s=0.05)
    with client, lidar:
        client.connect(3.0)
        client.start_sampling()
        assert run_until(client, lambda: client.sampling and client.firmware is not None)
        st = client.unit_status()
        assert st["firmware"] == "06.11.0000" and st["work_state_name"] == "normal" and st["problems"] == []
        run_until(client, lambda: False, 0.5)
        imu = client.take_imu()
        assert len(imu) >= 40  # 200 Hz over 0.5 s (and what came before)
        assert set(np.diff(imu.t_ns)) == {5_000_000}  # every sample of the 200 Hz grid, in order
        assert np.abs(imu.acc_g.mean(axis=0) - [0, 0, 1]).max() < 0.01
        assert np.abs(imu.gyro_rad_s).max() < 0.02
        ev = [e["event"] for e in client.take_events()]
        assert ev[0] == "connected" and "work_state" in ev and "firmware" in ev
        # a dirty window: the unit's status bits reach the client (data err_code, heartbeat, push)
        lidar.set_status(dirty_warn=1, system_status=1)
        assert run_until(client, lambda: "dirty/blocked 1" in client.unit_status()["problems"])
        assert "system warning" in client.unit_status()["problems"]
        assert run_until(client, lambda: client.counters.get("abnormal_pushes", 0) >= 1)
        assert any(e["event"] == "status" for e in client.take_events())
        # a refusal is reported with its command and return code
        client.send_command(P.CMD_SET_LIDAR, P.LIDAR_ID_SET_RETURN_MODE, b"\x03")  # triple: not a Horizon's
        assert run_until(client, lambda: client.last_refusal is not None)
        assert "set 1 id 6" in client.last_refusal and "return code 1" in client.last_refusal


def test_client_wakes_a_unit_in_standby_before_sampling():
    client = make_client()
    lidar = VirtualLivox(analytic_source, cmd_port=0, broadcast_addr=("127.0.0.1", client.broadcast_port),
                         point_rate_hz=RATE, unit=MID40, broadcast_period_s=0.05)
    lidar.work_state = P.LIDAR_MODE_STANDBY
    with client, lidar:
        client.connect(3.0)
        client.start_sampling()
        assert run_until(client, lambda: client.sampling)
        assert client.counters["mode_requests"] >= 1 and lidar.work_state == P.LIDAR_MODE_NORMAL
        assert run_until(client, lambda: len(client.poll(0.05)) > 0)
        assert client.state == CONNECTED


def test_daemon_status_line_names_what_the_unit_reports():
    from foveatrack.daemon.support import format_status

    plain = format_status(10.0, 9980, "tracking", 1.2, -0.3, 11.0, 0, True)
    noted = format_status(10.0, 9980, "tracking", 1.2, -0.3, 11.0, 0, True, "lidar standby, dirty/blocked 1")
    assert noted == plain + "  [lidar standby, dirty/blocked 1]" and "[" not in plain


@pytest.mark.slow
def test_late_heartbeat_acks_keep_the_link():
    """A unit answering heartbeats later than the 0.5 s command time-out (a loaded machine) is not
    lost: as in the SDK, any heartbeat ACK keeps the link; with none for 3 s it is lost."""
    import threading

    unit = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    unit.bind(("127.0.0.1", 0))
    unit.settimeout(0.05)
    client = LivoxClient("127.0.0.1", "127.0.0.1", cmd_port=0, data_port=0, broadcast_port=None,
                         sensor_cmd_port=unit.getsockname()[1], point_rate_hz=RATE, retry_period_s=0.1)
    stop, answer = threading.Event(), threading.Event()
    answer.set()

    def serve():
        late = []
        while not stop.is_set():
            try:
                buf, addr = unit.recvfrom(2048)
                f = P.parse_control(buf)
                if f.key == (0, 1):
                    unit.sendto(P.make_ack(f), addr)
                elif f.key == (0, 3) and answer.is_set():
                    late.append((time.monotonic() + 0.7, f, addr))
            except socket.timeout:
                pass
            while late and late[0][0] <= time.monotonic():
                _, f, addr = late.pop(0)
                unit.sendto(P.make_ack(f, P.heartbeat_ack_payload(0, 1, 0, 0)), addr)

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    try:
        with client:
            client.connect(2.0)
            run_until(client, lambda: False, 4.0)
            assert client.state == CONNECTED and client.counters.get("link_lost", 0) == 0
            assert client.counters["heartbeat_acks_late"] >= 3
            answer.clear()
            assert run_until(client, lambda: client.counters.get("link_lost", 0) == 1, 5.0)
    finally:
        stop.set()
        th.join(2)
        unit.close()


def test_lidar_serve_refuses_a_data_type_its_unit_does_not_send():
    from foveatrack.errors import UserError
    from sim.lidar_server import serve_scene
    from sim.scene import scene_from_mapping

    scene = scene_from_mapping({"scene": {"name": "t", "duration_s": 1.0, "seed": 1}, "lidar": {"preset": "mid40"},
                                "gimbal": {"frozen": True}, "background": [{"type": "ground", "height_m": 1.5}]})
    with pytest.raises(UserError, match=r"a Mid-40 sends data types \[0, 1\]"):
        serve_scene(scene, cmd_port=0, packet_type=2, duration_s=0.1)
