"""Livox SDK v1 host side over UDP: discovery, handshake, heartbeat, start/stop sampling, point data.

Single-threaded and non-blocking: all socket work and all timers (handshake retries, the 0.8 s
heartbeat, the 3 s link timeout, sampling retries) run inside :meth:`LivoxClient.poll`, which returns
as soon as points have arrived or its timeout ends, so a 10 Hz loop calling it is never stalled.

Flow (facts: livox.md, "SDK v1 control")::

    lidar --broadcast MSG {code, dev_type}--> host:broadcast_port     (DISCOVERING)
    host  --handshake CMD {ip, data_port, cmd_port, imu_port}--> lidar cmd port  (HANDSHAKING)
    lidar --ACK ret 0-->                                                 (CONNECTED)
    host  --heartbeat every 0.8 s-->, --start sampling {1}-->; lidar --data packets--> host:data_port

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


def _udp_socket(ip: str, port: int, rcvbuf: int | None = None, reuse: bool = False) -> socket.socket:
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
        raise UserError(f"cannot bind UDP {ip or '*'}:{port} for the Livox link: {exc.strerror}") from None
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
    heartbeat_period_s, link_timeout_s, retry_period_s : float > 0 [s]
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
        self._fixed_rate = point_rate_hz
        self.decoder = P.DataDecoder(point_rate_hz or 240_000.0, keep_no_return)
        self._counters: Counter = Counter()

        self._sel = selectors.DefaultSelector()
        self._data = _udp_socket(self.host_ip, data_port, rcvbuf=8 << 20)
        self._cmd = _udp_socket(self.host_ip, cmd_port)
        self._bcast = None
        if broadcast_port is not None:
            try:
                # '' so that real broadcasts (255.255.255.255) reach us as well as unicast ones
                self._bcast = _udp_socket("", broadcast_port, reuse=True)
            except UserError:
                self._data.close()
                self._cmd.close()
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
        self._pending: dict[int, tuple[int, bytes]] = {}  # seq -> (cmd_id, payload)
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
        self._seq = (self._seq + 1) & 0xFFFF
        return self._seq

    def _send_cmd(self, cmd_id: int, payload: bytes = b"") -> None:
        if self.sensor_cmd_port is None:
            return
        seq = self._next_seq()
        self._pending[seq] = (cmd_id, payload)
        if len(self._pending) > 64:
            self._pending.pop(next(iter(self._pending)))
        try:
            self._cmd.sendto(P.make_cmd(cmd_id, seq, payload), (self.sensor_ip, self.sensor_cmd_port))
            self._counters["cmd_sent"] += 1
        except OSError:
            self._counters["cmd_send_errors"] += 1

    def _send_handshake(self, now: float) -> None:
        self._last_handshake_tx = now
        self._send_cmd(
            P.CMD_ID_HANDSHAKE, P.handshake_payload(self.host_ip, self.data_port, self.cmd_port, self.imu_port)
        )

    def start_sampling(self) -> None:
        """Ask for point data (sent now if connected, else right after the handshake; retried)."""
        self._want_sampling = True
        if self.connected:
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
        if frame.cmd_type != P.CMD_TYPE_ACK:
            self._counters["msgs_ignored"] += 1
            return
        pending = self._pending.pop(frame.seq, None)
        if pending is None or pending[0] != frame.cmd_id:
            self._counters["acks_unmatched"] += 1
            return
        self._last_rx = now
        if P.ret_code(frame.payload) != 0:
            self._counters["nacks"] += 1
            return
        if frame.cmd_id == P.CMD_ID_HANDSHAKE:
            if self.state != CONNECTED:
                self.state = CONNECTED
                self._counters["handshakes"] += 1
                self._last_heartbeat_tx = now
                self.sampling = False
                if self._want_sampling:
                    self._last_sampling_tx = now
                    self._send_cmd(P.CMD_ID_SAMPLING, P.sampling_payload(True))
        elif frame.cmd_id == P.CMD_ID_HEARTBEAT:
            self._counters["heartbeat_acks"] += 1
        elif frame.cmd_id == P.CMD_ID_SAMPLING:
            self.sampling = pending[1] == P.sampling_payload(True)

    def _timers(self, now: float) -> None:
        if self.state == HANDSHAKING and now - self._last_handshake_tx >= self.retry_period_s:
            self._send_handshake(now)
        elif self.state == CONNECTED:
            if now - self._last_rx > self.link_timeout_s:
                self._counters["link_lost"] += 1
                self.sampling = False
                self._pending.clear()
                self.state = HANDSHAKING if self._fixed_sensor_port else DISCOVERING
                return
            if now - self._last_heartbeat_tx >= self.heartbeat_period_s:
                self._last_heartbeat_tx = now
                self._send_cmd(P.CMD_ID_HEARTBEAT)
            if self._want_sampling != self.sampling and now - self._last_sampling_tx >= self.retry_period_s:
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
