"""Livox SDK v1 host side over UDP: discovery, handshake, heartbeat, start/stop sampling, point data.

Single-threaded and non-blocking: all socket work and all timers (handshake retries, the 0.8 s
heartbeat, the 3 s link timeout, command time-outs, sampling retries) run inside
:meth:`LivoxClient.poll`, which returns as soon as points have arrived or its timeout ends, so a 10 Hz
loop calling it is never stalled.

Flow, as the vendor SDK 2.3.0 runs it (``device_discovery.cpp``, ``command_channel.cpp``; the bytes
it sends are fixtures in tests/livox/fixtures and our frames are checked equal to them)::

    lidar --broadcast MSG {code, dev_type}--> host:broadcast_port     (DISCOVERING)
    host  --handshake {ip, data_port, cmd_port, imu_port}--> lidar cmd port   (HANDSHAKING)
          framed with cmd_type 1 as the SDK does; imu_port 0 = the data port, as the SDK sets it
    lidar --ACK ret 0-->                                                 (CONNECTED)
    host  --heartbeat (at once, then every 0.8 s)-->, --query device information-->
    lidar --heartbeat ACK {ret, work state, feature, status code}-->
    host  --start sampling {1}--> once the work state is normal (1); in power-saving or standby
          it first asks for normal mode (lidar set 0)
    lidar --data packets (points; IMU type 6 into :meth:`LivoxClient.take_imu`)--> host:data_port

The link is lost 3 s after the last heartbeat ACK (the SDK counts only those); a command without an
ACK within 0.5 s has timed out (``cmd_timeouts``); an ACK with a non-zero return code is a refusal
(``nacks``, :attr:`LivoxClient.last_refusal`).  What the unit reports -- work state, feature, status
code from heartbeat ACKs, abnormal-state messages (general 7) and the err_code of data packets,
firmware from the device information -- is kept in :meth:`LivoxClient.unit_status`, and every
change of it is queued for :meth:`LivoxClient.take_events` (the daemon logs them).

Only datagrams whose source IP is ``sensor_ip`` are accepted; the rest are counted as
``foreign_source`` and dropped.  Malformed control frames and data packets are counted by reason
(see :mod:`foveatrack.livox.protocol`) and dropped; nothing a peer sends makes :meth:`poll` raise.
"""

from __future__ import annotations

import ipaddress
import selectors
import socket
import time
from collections import Counter
from typing import Callable

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.protocol import PointBatch

DISCOVERING = "discovering"
HANDSHAKING = "handshaking"
CONNECTED = "connected"

_RECV_BUF = 2048
_MAX_DATAGRAMS_PER_POLL = 20_000


def _udp_socket(ip: str, port: int, rcvbuf: int | None = None, reuse: bool = False, key: str = "") -> socket.socket:
    """A bound UDP socket; a UserError naming ``key`` (the config's key for the port) if it cannot be."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    if reuse:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    if rcvbuf:
        try:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        except OSError:  # pragma: no cover - capped by the OS, not fatal
            pass
    try:
        s.bind((ip, port))
    except OSError as exc:
        s.close()
        raise UserError(f"cannot bind UDP {ip or '*'}:{port} for the Livox link{f' ({key})' if key else ''}: "
                        f"{exc.strerror}") from None
    s.setblocking(False)
    return s


class LivoxClient:
    """Host side of one Livox lidar (SDK v1).

    sensor_ip : str, the lidar's IPv4 address; datagrams from any other address are dropped
    host_ip : str, this host's address on the lidar's network (sent in the handshake; sockets bind it)
    cmd_port, data_port : int in [0, 65535], host UDP ports (0 = any free port; see the attributes)
    broadcast_port : int or None, host port the lidar broadcasts to (55000); None = no discovery,
        then ``sensor_cmd_port`` is required and the handshake is sent straight away
    sensor_cmd_port : int or None, the lidar's command port; default: the source port of its broadcast
    point_rate_hz : float > 0 or None [points/s], for per-point times; None = from the device type
    broadcast_code : str or None, if given, broadcasts with another code are ignored
    heartbeat_period_s, link_timeout_s, retry_period_s, cmd_timeout_s : float > 0 [s]
    imu_port : int, host port for IMU packets; 0 = the data port (the SDK sends the same port twice)
    clock : callable returning monotonic seconds (tests may pass a fake)

    Attributes: ``state`` (discovering / handshaking / connected), ``sampling`` (acknowledged),
    ``counters`` (flat dict: packets, points, foreign_source, dropped_<reason>, link_lost, ...),
    ``dropped`` (Counter by reason), ``device_broadcast_code``, ``device_type``.
    """

    def __init__(
        self,
        sensor_ip: str,
        host_ip: str = "127.0.0.1",
        cmd_port: int = 56001,
        data_port: int = 56000,
        broadcast_port: int | None = P.DEFAULT_BROADCAST_PORT,
        sensor_cmd_port: int | None = None,
        point_rate_hz: float | None = None,
        broadcast_code: str | None = None,
        keep_no_return: bool = False,
        heartbeat_period_s: float = 0.8,
        link_timeout_s: float = 3.0,
        retry_period_s: float = 0.5,
        imu_port: int = 0,
        cmd_timeout_s: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
    ):
        try:
            self.sensor_ip = str(ipaddress.IPv4Address(sensor_ip))
            self.host_ip = str(ipaddress.IPv4Address(host_ip))
        except ValueError as exc:
            raise UserError(f"Livox client: {exc}; give dotted IPv4 addresses like 192.168.1.50") from None
        for name, port in (("cmd_port", cmd_port), ("data_port", data_port), ("imu_port", imu_port)):
            if not 0 <= int(port) <= 65535:
                raise UserError(f"Livox client: {name} {port} is not in 0..65535")
        if broadcast_port is None and sensor_cmd_port is None:
            raise UserError("Livox client: without discovery (broadcast_port=None) give sensor_cmd_port")
        if point_rate_hz is not None and not point_rate_hz > 0:
            raise UserError(f"Livox client: point_rate_hz must be > 0, got {point_rate_hz}")
        self._clock = clock
        self.broadcast_code = broadcast_code
        self.heartbeat_period_s = heartbeat_period_s
        self.link_timeout_s = link_timeout_s
        self.retry_period_s = retry_period_s
        self.imu_port = imu_port
        self.cmd_timeout_s = cmd_timeout_s
        self._fixed_rate = point_rate_hz
        self.decoder = P.DataDecoder(point_rate_hz or 240_000.0, keep_no_return)
        self._counters: Counter = Counter()

        self._sel = selectors.DefaultSelector()
        self._data = _udp_socket(self.host_ip, data_port, rcvbuf=8 << 20, key="[lidar] data_port")
        try:
            self._cmd = _udp_socket(self.host_ip, cmd_port, key="[lidar] cmd_port")
        except UserError:
            self._data.close()
            raise
        self._bcast = None
        if broadcast_port is not None:
            try:
                # '' so that real broadcasts (255.255.255.255) reach us as well as unicast ones.
                # Exclusive (no SO_REUSEADDR): with a shared port a second process silently took 15 of
                # 17 broadcasts; now the second one is told at start.
                self._bcast = _udp_socket("", broadcast_port, key="[lidar] broadcast_port")
            except UserError as exc:
                self._data.close()
                self._cmd.close()
                if "in use" in str(exc):
                    raise UserError(f"{exc}: another process on this host holds the Livox discovery port "
                                    f"{broadcast_port} (a second daemon, a calibration, the Livox SDK or viewer?); "
                                    "only one may listen for the lidars' broadcasts: stop it, or give "
                                    "broadcast_port = false with the lidar's sensor_cmd_port") from None
                raise
            self._sel.register(self._bcast, selectors.EVENT_READ, "bcast")
        self._sel.register(self._cmd, selectors.EVENT_READ, "cmd")
        self._sel.register(self._data, selectors.EVENT_READ, "data")

        self.sensor_cmd_port = sensor_cmd_port
        self._fixed_sensor_port = sensor_cmd_port is not None
        self.device_broadcast_code: str | None = None
        self.device_type: int | None = None
        self.foreign_addresses: set[str] = set()  # senders other than sensor_ip seen (at most 8 kept)
        self.state = DISCOVERING
        self.sampling = False
        self._want_sampling = False
        self._seq = 0
        self._last_handshake_tx = -1e18
        self._last_heartbeat_tx = -1e18
        self._last_sampling_tx = -1e18
        self._last_rx = 0.0
        self._pending: dict[int, tuple[int, int, bytes, float]] = {}  # seq -> (cmd_set, cmd_id, payload, sent)
        # what the unit reports (see unit_status)
        self.work_state: int | None = None
        self.feature: int | None = None
        self.status_code: int | None = None
        self.firmware: tuple[int, int, int, int] | None = None
        self.last_refusal: str | None = None
        self._events: list[dict] = []
        self._last_mode_tx = -1e18
        self._last_data_code: int | None = None
        if self._fixed_sensor_port:
            self.state = HANDSHAKING
        self._closed = False

    # ------------------------------------------------------------------ properties

    @property
    def cmd_port(self) -> int:
        return self._cmd.getsockname()[1]

    @property
    def data_port(self) -> int:
        return self._data.getsockname()[1]

    @property
    def broadcast_port(self) -> int | None:
        return None if self._bcast is None else self._bcast.getsockname()[1]

    @property
    def connected(self) -> bool:
        return self.state == CONNECTED

    @property
    def dropped(self) -> Counter:
        """Datagrams dropped, by reason (control and data reasons and ``foreign_source``)."""
        out = Counter(self.decoder.dropped)
        for k, v in self._counters.items():
            if k.startswith("ctrl_") or k == "foreign_source":
                out[k] += v
        return out

    @property
    def counters(self) -> dict:
        """All counters in one flat dict: packets, points, no_return_points, imu_packets,
        foreign_source, dropped_<reason>, dropped_total, handshakes, heartbeat_acks, link_lost, ..."""
        d = dict(self._counters)
        d.update(self.decoder.counters)
        for k, v in self.dropped.items():
            d[f"dropped_{k}"] = v
        d["dropped_total"] = sum(self.dropped.values())
        return d

    def stats(self) -> dict:
        """:attr:`counters` plus ``state`` and ``sampling``."""
        return {**self.counters, "state": self.state, "sampling": self.sampling}

    # ------------------------------------------------------------------ commands

    def _next_seq(self) -> int:
        # as the SDK's GenerateSeq: 1..65535, 0 skipped on wrap
        self._seq = self._seq + 1 if self._seq < 0xFFFF else 1
        return self._seq

    def _send_frame(self, buf: bytes) -> None:
        try:
            self._cmd.sendto(buf, (self.sensor_ip, self.sensor_cmd_port))
            self._counters["cmd_sent"] += 1
        except OSError:
            self._counters["cmd_send_errors"] += 1

    def _send_cmd(self, cmd_id: int, payload: bytes = b"", cmd_set: int = P.CMD_SET_GENERAL) -> None:
        if self.sensor_cmd_port is None:
            return
        seq = self._next_seq()
        self._pending[seq] = (cmd_set, cmd_id, payload, self._clock())
        if len(self._pending) > 64:
            self._pending.pop(next(iter(self._pending)))
        self._send_frame(P.make_cmd(cmd_id, seq, payload, cmd_set))

    def send_command(self, cmd_set: int, cmd_id: int, payload: bytes = b"") -> None:
        """Send any command of the general or lidar set (the ACK is matched and a refusal reported;
        its payload is not kept).  Used for the unit's settings, e.g. lidar set 8 {0} (IMU off)."""
        if not self.connected:
            raise UserError(f"Livox client: not connected to {self.sensor_ip}; cannot send command "
                            f"set {cmd_set} id {cmd_id}")
        self._send_cmd(cmd_id, payload, cmd_set)

    def _send_handshake(self, now: float) -> None:
        self._last_handshake_tx = now
        if self.sensor_cmd_port is None:
            return
        seq = self._next_seq()
        self._pending[seq] = (P.CMD_SET_GENERAL, P.CMD_ID_HANDSHAKE, b"", now)
        self._send_frame(P.make_handshake(seq, self.host_ip, self.data_port, self.cmd_port,
                                          self.imu_port or self.data_port))

    # ------------------------------------------------------------------ what the unit reports

    def unit_status(self) -> dict:
        """Work state (number and name), feature, status code (u32 and its named fields, and the
        words for what is not normal), firmware ('AA.BB.CCDD'), the last refused command."""
        code = self.status_code
        return {
            "work_state": self.work_state,
            "work_state_name": None if self.work_state is None else P.LIDAR_STATES.get(self.work_state, "?"),
            "feature": self.feature,
            "status_code": code,
            "status": None if code is None else P.decode_status_code(code),
            "problems": [] if code is None else P.status_problems(code),
            "firmware": None if self.firmware is None else P.firmware_str(self.firmware),
            "last_refusal": self.last_refusal,
        }

    def take_events(self) -> list[dict]:
        """Changes of what the unit reports since the last call, oldest first (dicts with ``event``:
        work_state, status, firmware, refused, timeout, link_lost, connected)."""
        ev, self._events = self._events, []
        return ev

    def take_imu(self) -> P.ImuBatch:
        """IMU samples (data type 6) received since the last call: gyro [rad/s], acc [g], t_ns."""
        return self.decoder.take_imu()

    def _event(self, kind: str, **kw) -> None:
        if len(self._events) < 256:
            self._events.append({"event": kind, **kw})

    def _set_status(self, code: int, source: str) -> None:
        if code != self.status_code:
            self.status_code = code
            self._event("status", status_code=code, problems=P.status_problems(code), source=source)

    def start_sampling(self) -> None:
        """Ask for point data: sent once connected and the unit's work state is normal (retried)."""
        self._want_sampling = True
        if self.connected and self.work_state == P.LIDAR_MODE_NORMAL:
            self._last_sampling_tx = self._clock()
            self._send_cmd(P.CMD_ID_SAMPLING, P.sampling_payload(True))

    def stop_sampling(self) -> None:
        self._want_sampling = False
        if self.connected:
            self._last_sampling_tx = self._clock()
            self._send_cmd(P.CMD_ID_SAMPLING, P.sampling_payload(False))

    def connect(self, timeout_s: float = 5.0) -> None:
        """Block (polling) until the handshake is acknowledged; raise UserError after ``timeout_s``."""
        end = self._clock() + timeout_s
        while not self.connected:
            left = end - self._clock()
            if left <= 0:
                raise UserError(
                    f"no Livox lidar at {self.sensor_ip} answered within {timeout_s:g} s "
                    f"(state {self.state}; broadcast port {self.broadcast_port}, host {self.host_ip})"
                )
            self.poll(min(left, 0.05))

    # ------------------------------------------------------------------ receive

    def poll(self, timeout_s: float = 0.0) -> list[PointBatch]:
        """Run timers and read all pending datagrams; wait up to ``timeout_s`` for point data.

        Returns the point batches decoded (possibly empty).  Never raises for anything received.
        """
        if self._closed:
            raise RuntimeError("LivoxClient is closed")
        end = self._clock() + max(0.0, timeout_s)
        out: list[PointBatch] = []
        while True:
            now = self._clock()
            self._timers(now)
            wait = max(0.0, min(end - now, self.retry_period_s / 2))
            events = self._sel.select(wait)
            data: list[bytes] = []
            for key, _ in events:
                self._drain(key.fileobj, key.data, data)
            if data:
                out.extend(self.decoder.decode(data))
            if out or self._clock() >= end:
                return out

    def _drain(self, sock: socket.socket, kind: str, data: list[bytes]) -> None:
        for _ in range(_MAX_DATAGRAMS_PER_POLL):
            try:
                buf, addr = sock.recvfrom(_RECV_BUF)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self._counters["recv_errors"] += 1
                return
            if addr[0] != self.sensor_ip:
                self._counters["foreign_source"] += 1
                if len(self.foreign_addresses) < 8:  # named in the daemon's "no lidar data" hint
                    self.foreign_addresses.add(addr[0])
                continue
            if kind == "data":
                data.append(buf)
            else:
                self._on_control(buf, addr)

    def _on_control(self, buf: bytes, addr) -> None:
        frame, reason = P.parse_control_safe(buf)
        if frame is None:
            self._counters[reason] += 1
            return
        now = self._clock()
        if frame.cmd_type == P.CMD_TYPE_MSG and frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_BROADCAST):
            try:
                code, dev_type = P.parse_broadcast(frame.payload)
            except P.PacketError as exc:
                self._counters[exc.reason] += 1
                return
            if self.broadcast_code and code != self.broadcast_code:
                self._counters["other_broadcast_code"] += 1
                return
            self._counters["broadcasts"] += 1
            self.device_broadcast_code, self.device_type = code, dev_type
            if self._fixed_rate is None:
                self.decoder.point_rate_hz = float(P.DEVICE_POINT_RATE_HZ.get(dev_type, 240_000))
            if not self._fixed_sensor_port:
                self.sensor_cmd_port = addr[1]
            if self.state == DISCOVERING:
                self.state = HANDSHAKING
                self._send_handshake(now)
            return
        if frame.cmd_type == P.CMD_TYPE_MSG and frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_PUSH_ABNORMAL_STATE):
            self._counters["abnormal_pushes"] += 1
            if len(frame.payload) >= 4:
                self._set_status(int.from_bytes(frame.payload[:4], "little"), "abnormal-state message")
            return
        if frame.cmd_type != P.CMD_TYPE_ACK:
            self._counters["msgs_ignored"] += 1
            return
        pending = self._pending.pop(frame.seq, None)
        if pending is None or pending[:2] != frame.key:
            if frame.key != (P.CMD_SET_GENERAL, P.CMD_ID_HEARTBEAT):
                self._counters["acks_unmatched"] += 1
                return
            # as the SDK (command_channel.cpp): a heartbeat ACK keeps the link whatever its seq or
            # delay, so a unit slow to answer (> cmd_timeout_s) is not taken for a lost one
            self._counters["heartbeat_acks_late"] += 1
            pending = (P.CMD_SET_GENERAL, P.CMD_ID_HEARTBEAT, b"", now)
        cmd_set, cmd_id, payload, _sent = pending
        ret = P.ret_code(frame.payload)
        if ret != 0:
            self._counters["nacks"] += 1
            self.last_refusal = f"command set {cmd_set} id {cmd_id} refused by the unit (return code {ret})"
            self._event("refused", cmd_set=cmd_set, cmd_id=cmd_id, ret_code=ret)
            return
        if frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_HANDSHAKE):
            if self.state != CONNECTED:
                self.state = CONNECTED
                self._counters["handshakes"] += 1
                self._last_rx = now
                self.sampling = False
                self.work_state = None
                self._event("connected", broadcast_code=self.device_broadcast_code, device_type=self.device_type)
                # as the SDK: a heartbeat at once (its ACK gives the work state), then the device information
                self._last_heartbeat_tx = now
                self._send_cmd(P.CMD_ID_HEARTBEAT)
                self._send_cmd(P.CMD_ID_QUERY_INFO)
        elif frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_HEARTBEAT):
            self._counters["heartbeat_acks"] += 1
            self._last_rx = now
            try:
                _ret, state, feature, status = P.parse_heartbeat_ack(frame.payload)
            except P.PacketError as exc:
                self._counters[exc.reason] += 1
                return
            if state != self.work_state:
                self.work_state = state
                self._event("work_state", work_state=state, name=P.LIDAR_STATES.get(state, "?"))
                if state == P.LIDAR_MODE_NORMAL and self._want_sampling and not self.sampling:
                    self._last_sampling_tx = now
                    self._send_cmd(P.CMD_ID_SAMPLING, P.sampling_payload(True))
            self.feature = feature
            if state != 0:  # in the init state the field is the progress, not a status code
                self._set_status(status, "heartbeat")
        elif frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_QUERY_INFO):
            try:
                _ret, fw = P.parse_device_info(frame.payload)
            except P.PacketError as exc:
                self._counters[exc.reason] += 1
                return
            if fw != self.firmware:
                self.firmware = fw
                self._event("firmware", firmware=P.firmware_str(fw))
        elif frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_SAMPLING):
            self.sampling = payload == P.sampling_payload(True)

    def _timers(self, now: float) -> None:
        if self._pending:
            late = [q for q, v in self._pending.items() if now - v[3] > self.cmd_timeout_s]
            for q in late:
                cmd_set, cmd_id, _pl, _t = self._pending.pop(q)
                if (cmd_set, cmd_id) != (P.CMD_SET_GENERAL, P.CMD_ID_HEARTBEAT):  # the SDK times them out silently too
                    self._counters["cmd_timeouts"] += 1
                    self._event("timeout", cmd_set=cmd_set, cmd_id=cmd_id)
        if self.state == HANDSHAKING and now - self._last_handshake_tx >= self.retry_period_s:
            self._send_handshake(now)
        elif self.state == CONNECTED:
            if now - self._last_rx > self.link_timeout_s:
                self._counters["link_lost"] += 1
                self._event("link_lost", after_s=round(now - self._last_rx, 3))
                self.sampling = False
                self.work_state = None
                self._pending.clear()
                self.state = HANDSHAKING if self._fixed_sensor_port else DISCOVERING
                return
            if now - self._last_heartbeat_tx >= self.heartbeat_period_s:
                self._last_heartbeat_tx = now
                self._send_cmd(P.CMD_ID_HEARTBEAT)
            code = self.decoder.last_err_code  # the status code of the newest data packet
            if code is not None and code != self._last_data_code:
                self._last_data_code = code
                self._set_status(code, "data packet")
            if self._want_sampling and self.work_state in (P.LIDAR_MODE_POWER_SAVING, P.LIDAR_MODE_STANDBY) \
                    and now - self._last_mode_tx >= self.retry_period_s:
                self._last_mode_tx = now
                self._counters["mode_requests"] += 1
                self._send_cmd(P.LIDAR_ID_SET_MODE, bytes((P.LIDAR_MODE_NORMAL,)), P.CMD_SET_LIDAR)
            elif self._want_sampling != self.sampling and now - self._last_sampling_tx >= self.retry_period_s \
                    and (self.work_state == P.LIDAR_MODE_NORMAL or not self._want_sampling):
                self._last_sampling_tx = now
                self._send_cmd(P.CMD_ID_SAMPLING, P.sampling_payload(self._want_sampling))

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        """Stop sampling (best effort, not waited for) and close the sockets."""
        if self._closed:
            return
        if self.connected and (self.sampling or self._want_sampling):
            self._send_cmd(P.CMD_ID_SAMPLING, P.sampling_payload(False))
        self._closed = True
        for s in (self._bcast, self._cmd, self._data):
            if s is not None:
                try:
                    self._sel.unregister(s)
                except (KeyError, ValueError):
                    pass
                s.close()
        self._sel.close()

    def __enter__(self) -> "LivoxClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
