"""A virtual Livox lidar that speaks the SDK v1 protocol over UDP, streaming simulated points.

``VirtualLivox(source, ...)`` behaves toward a host as a real unit of its :class:`sim.livox_units.
LivoxUnit` does (docs/livox.md has the full table):

* discovery: broadcasts ``{broadcast code (14-char serial + digit, NUL-terminated), device type}``
  every ``broadcast_period_s`` while no host holds it, and stops while one does;
* handshake: taken with cmd_type 0 (CMD) or 1 (the vendor SDK frames it as an ACK); the ACK goes back to
  the sender, the data to the handshake's IP and data port, IMU packets to its IMU port (the data port
  if 0).  A handshake naming a non-loopback host from a loopback-bound unit is refused (ret 1): the
  virtual unit never sends off the machine;
* heartbeat ACK ``{ret, work state, feature, status code}``; the link drops ``link_timeout_s`` (3 s)
  after the last heartbeat, and broadcasting resumes;
* the general command set (device information with the unit's firmware, sampling, coordinate system,
  disconnect, IP information, reboot, configuration parameters) and the lidar command set (mode,
  extrinsic, rain/fog, fan, return mode, IMU push frequency, UTC time), answered with return code
  0 (success) or 1 (fail: what the unit does not have, a bad payload, a command from a host that does
  not hold it), as the protocol defines them;
* data packets of the type the coordinate system and return mode select, each with the status code
  (``err_code``) in its header; a status code whose system_status is not 0 is also pushed to the host
  as an abnormal-state message (general 7) once a heartbeat period;
* IMU packets (data type 6) at 200 Hz on units with an IMU (Horizon, Tele-15, Avia) while sampling,
  unless the host set the push frequency to 0.  Values are those of a static sensor (``imu_source``
  can give others).

Data are paced in real time on the monotonic clock (``time_scale`` > 1 runs the stream faster).
The points come from ``source(t0_ns, t1_ns) -> (xyz, reflectivity, t_ns)``: the returns a simulated
lidar produces for the slots in ``[t0_ns, t1_ns)`` of *stream time* (``t_start_ns`` + elapsed wall time
× time_scale, counted from ``serve()``'s start with ``clock="start"``, or from the first start-sampling
command a host sends with ``clock="sampling"``: until then stream time stays ``t_start_ns``, and later
starts continue the same clock, as a unit's own time runs on between samplings).  A lidar fires at a fixed rate, one slot every ``1e9 / point_rate_hz`` ns (two or three
returns per slot for the dual and triple types, the simulator's single return being the first);
each returned point goes to the slot nearest its ``t_ns``, slots without a point go out as "no
return" (0, 0, 0), points beyond a slot's capacity or outside the interval are counted and dropped.
A source that produces points on the slot grid therefore comes out of
:class:`foveatrack.livox.client.LivoxClient` with the same times (±1 ns) and positions (±0.5 mm).

Faults for tests: ``loss_rate`` drops that fraction of data packets (seeded generator, one stream);
:meth:`VirtualLivox.set_status` sets status bits (e.g. ``dirty_warn=1, system_status=1``).

Use it in-process (``with VirtualLivox(...) as lidar:`` runs a thread) or blocking in a process of
its own (:func:`run_virtual_lidar`, which stops on SIGINT/SIGTERM; ``python -m sim.virtual_lidar``
serves a demo wall for manual tests).  The wall clock here only paces the stream; the source is
handed explicit stream times and never reads a clock.  ``control_log``, if a list, receives
``(direction 'rx'|'tx', bytes)`` of every control datagram (the fixtures of tests/livox were captured
this way from the vendor SDK).
"""

from __future__ import annotations

import argparse
import ipaddress
import selectors
import signal
import socket
import struct
import sys
import threading
import time
from collections import Counter
from typing import Callable

import numpy as np

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from sim.livox_units import HORIZON, LivoxUnit

Source = Callable[[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]
ImuSource = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

_RETURNS_PER_SLOT = {4: 2, 5: 2, 7: 3, 8: 3}


#: When stream time starts: at ``serve()``, or at the first start-sampling command (``VirtualLivox(clock=)``).
CLOCKS = ("start", "sampling")

#: The longest the served IMU waits behind the stream for its source (``imu_ready_ns``) [s].
IMU_MAX_WAIT_S = 2.0


def static_imu_source(seed: int = 0, gyro_noise_rad_s: float = 0.002, acc_noise_g: float = 0.002) -> ImuSource:
    """IMU of a level sensor at rest: gyro N(0, gyro_noise) [rad/s], acc (0, 0, 1) + N(0, acc_noise) [g]
    (specific force; Z up).  Noise levels of the order of a MEMS IMU's; one seeded stream."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 6]))

    def imu(t_ns: np.ndarray):
        n = len(t_ns)
        gyro = rng.normal(0.0, gyro_noise_rad_s, (n, 3))
        acc = rng.normal(0.0, acc_noise_g, (n, 3)) + np.array([0.0, 0.0, 1.0])
        return gyro, acc

    return imu


class VirtualLivox:
    """A Livox lidar on UDP (SDK v1), fed by ``source``.

    source : callable(t0_ns, t1_ns) -> (xyz (n,3) [m] lidar frame, reflectivity (n,) u8, t_ns (n,) int)
    unit : :class:`sim.livox_units.LivoxUnit` (default Horizon): device type, code, firmware, types
    head : 1..unit.heads, which unit of a multi-unit product (last digit of the broadcast code)
    bind_ip : str, the lidar's address (e.g. 127.0.0.1, or 127.0.0.2 to look like another host)
    cmd_port : int, the lidar's command port (65000 on real lidars, and the vendor SDK sends only
        there; 0 = any free port)
    broadcast_addr : (ip, port), where discovery broadcasts go (host port 55000 on a real network)
    point_rate_hz : float > 0 [slots/s]
    packet_type : None (the unit's Cartesian single-return type) or a data type it has (sets the
        coordinate system and return mode that give it); any of 0..4 for a custom ``dev_type``
    broadcast_code, dev_type : override the unit's (tests)
    time_scale : float > 0, stream seconds per wall second
    loss_rate : float in [0, 1), fraction of data packets dropped; seed : int for that generator
    t_start_ns : int, stream time at start(); batch_period_s : wall seconds between source calls
    imu_source : callable(t_ns (n,)) -> (gyro (n,3) rad/s, acc (n,3) g); default a static sensor
    imu_lag_s : float >= 0 [s], the IMU samples leave this long after their time (a source that
        differentiates a followed head's pose needs that pose a little after each sample)
    imu_ready_ns : optional callable() -> stream time [ns] up to which ``imu_source`` can compute its
        samples from what it knows (a pose it follows from a file): samples wait for it, at most
        ``IMU_MAX_WAIT_S`` behind the stream (then they go with what the source has)
    clock : "start" (stream time runs from ``serve()``'s start) or "sampling" (from the first time a
        host starts sampling; ``lidar serve``'s default, so a scene begins when a host first looks)
    on_sampling_start : optional callable(t_ns, host (ip, data port)), called at every accepted
        start-sampling command with the stream time of the first slot it sends
    """

    def __init__(
        self,
        source: Source,
        bind_ip: str = "127.0.0.1",
        cmd_port: int = P.DEFAULT_SENSOR_CMD_PORT,
        broadcast_addr: tuple[str, int] = ("127.0.0.1", P.DEFAULT_BROADCAST_PORT),
        point_rate_hz: float = 240_000.0,
        packet_type: int | None = None,
        broadcast_code: str | None = None,
        dev_type: int | None = None,
        time_scale: float = 1.0,
        loss_rate: float = 0.0,
        seed: int = 0,
        t_start_ns: int = 0,
        batch_period_s: float = 0.01,
        broadcast_period_s: float = 0.5,
        link_timeout_s: float = 3.0,
        timestamp_type: int = 0,
        unit: LivoxUnit = HORIZON,
        head: int = 1,
        imu_source: ImuSource | None = None,
        control_log: list | None = None,
        imu_lag_s: float = 0.0,
        imu_ready_ns=None,
        clock: str = "start",
        on_sampling_start: Callable[[int, tuple], None] | None = None,
    ):
        if not point_rate_hz > 0 or not time_scale > 0 or not 0 <= loss_rate < 1:
            raise ValueError("need point_rate_hz > 0, time_scale > 0 and 0 <= loss_rate < 1")
        if clock not in CLOCKS:
            raise ValueError(f"clock must be one of {CLOCKS}, got {clock!r}")
        self.clock = clock
        self.on_sampling_start = on_sampling_start
        self.unit = unit
        self.coordinate_system, self.return_mode = 0, 0
        if packet_type is None:
            packet_type = unit.data_type(0, 0)
        elif packet_type not in P.POINT_DATA_TYPES:
            raise ValueError(f"packet_type must be one of {P.POINT_DATA_TYPES}, got {packet_type}")
        else:
            mode = unit.mode_of_data_type(packet_type)
            if mode is not None:
                self.coordinate_system, self.return_mode = mode
        self.source = source
        self.point_rate_hz = float(point_rate_hz)
        self.packet_type = packet_type
        self.broadcast_code = P.check_broadcast_code(broadcast_code or unit.broadcast_code(head))
        self.dev_type = unit.dev_type if dev_type is None else dev_type
        self.time_scale = float(time_scale)
        self.loss_rate = float(loss_rate)
        self.t_start_ns = int(t_start_ns)
        self.batch_period_s = batch_period_s
        self.broadcast_period_s = broadcast_period_s
        self.link_timeout_s = link_timeout_s
        self.timestamp_type = timestamp_type
        self.broadcast_addr = broadcast_addr
        self.imu_source = imu_source or static_imu_source(seed)
        self.imu_lag_ns = int(round(max(0.0, imu_lag_s) * 1e9))
        self.imu_ready_ns = imu_ready_ns
        self.control_log = control_log
        self._rng = np.random.default_rng(np.random.SeedSequence(seed))
        self.counters: Counter = Counter()

        # unit state a host can read and change
        self.work_state = P.LIDAR_MODE_NORMAL
        self.feature = 0  # 1 = rain/fog suppression on
        self.fan_on = unit.has_fan
        self.imu_freq = P.IMU_FREQ_200HZ if unit.has_imu else P.IMU_FREQ_OFF
        self.extrinsic = (0.0, 0.0, 0.0, 0, 0, 0)  # roll, pitch, yaw [deg]; x, y, z [mm]
        self.params = dict(unit.param_keys)
        self.status_code = self._sync_status_bits()

        self._bind_loopback = ipaddress.IPv4Address(bind_ip).is_loopback
        self._cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._cmd.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            self._cmd.bind((bind_ip, cmd_port))
            self._data.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 << 20)
            self._data.bind((bind_ip, 0))
        except OSError as exc:
            self._cmd.close()
            self._data.close()
            raise UserError(f"virtual lidar cannot bind UDP {bind_ip}:{cmd_port}: {exc.strerror or exc}") from None
        self._cmd.setblocking(False)
        self._sel = selectors.DefaultSelector()
        self._sel.register(self._cmd, selectors.EVENT_READ)

        self.host: tuple[str, int] | None = None  # (ip, data_port) after a handshake
        self.host_imu: tuple[str, int] | None = None
        self.host_cmd: tuple[str, int] | None = None  # where pushed messages go
        self.sampling = False
        self._last_heartbeat = 0.0
        self._last_push = 0.0
        self._seq = 0
        self._mono0: float | None = None
        self._next_slot = 0  # index of the next slot to send (slot k is at t_start + k / rate)
        self._next_imu = 0   # index of the next IMU sample (sample k at t_start + k / 200 Hz)
        self._silent_until = 0.0  # rebooting: no broadcasts, no answers
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    # ------------------------------------------------------------------ info

    @property
    def address(self) -> tuple[str, int]:
        """(ip, command port) of the lidar."""
        return self._cmd.getsockname()

    @property
    def cmd_port(self) -> int:
        return self._cmd.getsockname()[1]

    @property
    def slot_ns(self) -> float:
        return 1e9 / self.point_rate_hz

    @property
    def returns_per_slot(self) -> int:
        return _RETURNS_PER_SLOT.get(self.packet_type, 1)

    @property
    def clock_zero_mono(self) -> float | None:
        """``time.monotonic()`` at stream time ``t_start_ns``; None until the clock starts (``clock``)."""
        return self._mono0

    def stream_time_ns(self, mono: float | None = None) -> int:
        mono = time.monotonic() if mono is None else mono
        if self._mono0 is None:
            return self.t_start_ns
        return self.t_start_ns + int((mono - self._mono0) * self.time_scale * 1e9)

    def set_status(self, **fields: int) -> None:
        """Set status-code fields (see :data:`foveatrack.livox.protocol.STATUS_FIELDS`); the others
        keep the sync bits the timestamp type implies.  A non-zero system_status is pushed to the host."""
        self.status_code = self._sync_status_bits() | P.encode_status_code(**fields)

    def _sync_status_bits(self) -> int:
        # time_sync_status follows the timestamp type (0 none, 1 PTP, 3 PPS+GPS, 4 PPS); the signal bits with it
        tt = self.timestamp_type
        return P.encode_status_code(time_sync_status=tt if tt in (1, 3, 4) else 0,
                                    ptp_status=int(tt == 1), pps_status=int(tt in (3, 4)))

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> "VirtualLivox":
        """Serve in a background thread."""
        self._thread = threading.Thread(target=self._run_guarded, name="virtual-livox", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop serving, close the sockets; re-raise an exception the source raised in the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        self._close()
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def __enter__(self) -> "VirtualLivox":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _close(self) -> None:
        for s in (self._cmd, self._data):
            try:
                self._sel.unregister(s)
            except (KeyError, ValueError):
                pass
            s.close()

    def _run_guarded(self) -> None:
        try:
            self.serve(self._stop)
        except BaseException as exc:  # noqa: BLE001 - handed to stop() so it is not lost
            self._error = exc

    def serve(self, stop: threading.Event) -> None:
        """Serve until ``stop`` is set (blocking)."""
        t0 = time.monotonic()
        if self.clock == "start":
            self._mono0 = t0
        next_bcast = 0.0
        next_batch = t0
        while not stop.is_set():
            now = time.monotonic()
            if self.host is not None and now - self._last_heartbeat > self.link_timeout_s:
                self.counters["link_timeouts"] += 1
                self._drop_host()
            if self.host is None and now >= next_bcast and now >= self._silent_until:
                self._send_broadcast()
                next_bcast = now + self.broadcast_period_s
            if self.sampling and now >= next_batch:
                t_now = self.stream_time_ns(now)
                self._stream_until(t_now)
                if self.unit.has_imu and self.imu_freq == P.IMU_FREQ_200HZ:
                    t_imu = t_now - self.imu_lag_ns
                    if self.imu_ready_ns is not None:
                        # wait for the source's pose to cover the samples (a loaded machine delays
                        # the head's truth), but never more than IMU_MAX_WAIT_S behind the stream
                        t_imu = min(t_imu, int(max(self.imu_ready_ns(), t_now - IMU_MAX_WAIT_S * 1e9)))
                    self._imu_until(t_imu)
                next_batch = now + self.batch_period_s
            if self.host is not None and P.decode_status_code(self.status_code)["system_status"] \
                    and now - self._last_push >= 0.8:
                self._push_abnormal(now)
            deadline = next_batch if self.sampling else next_bcast if self.host is None else now + 0.05
            for _key, _ in self._sel.select(max(0.0, min(deadline - time.monotonic(), 0.05))):
                self._drain_cmd()

    # ------------------------------------------------------------------ control

    def _sendto(self, buf: bytes, addr) -> None:
        try:
            self._cmd.sendto(buf, addr)
            if self.control_log is not None:
                self.control_log.append(("tx", buf))
        except OSError:
            self.counters["send_errors"] += 1

    def _send_broadcast(self) -> None:
        self._seq = (self._seq + 1) & 0xFFFF
        self._sendto(P.make_broadcast(self._seq, self.broadcast_code, self.dev_type), self.broadcast_addr)
        self.counters["broadcasts"] += 1

    def _push_abnormal(self, now: float) -> None:
        self._last_push = now
        self._seq = (self._seq + 1) & 0xFFFF
        frame = P.ControlFrame(P.CMD_TYPE_MSG, self._seq, P.CMD_SET_GENERAL, P.CMD_ID_PUSH_ABNORMAL_STATE,
                               struct.pack("<I", self.status_code))
        self._sendto(P.encode_control(frame), self.host_cmd)
        self.counters["abnormal_pushes"] += 1

    def _drop_host(self) -> None:
        self.host = self.host_imu = self.host_cmd = None
        self.sampling = False

    def _drain_cmd(self) -> None:
        while True:
            try:
                buf, addr = self._cmd.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self.counters["recv_errors"] += 1
                return
            if self.control_log is not None:
                self.control_log.append(("rx", bytes(buf)))
            if time.monotonic() < self._silent_until:
                self.counters["ignored_rebooting"] += 1
                continue
            frame, reason = P.parse_control_safe(buf)
            if frame is None:
                self.counters[reason] += 1
                continue
            handshake = frame.key == (P.CMD_SET_GENERAL, P.CMD_ID_HANDSHAKE)
            # the SDK frames its handshake as an ACK (cmd_type 1); every other request is a CMD
            if frame.cmd_type == P.CMD_TYPE_MSG or (frame.cmd_type == P.CMD_TYPE_ACK and not handshake):
                self.counters["ignored"] += 1
                continue
            self._on_cmd(frame, addr)

    def _reply(self, frame: P.ControlFrame, addr, payload: bytes = b"\0") -> None:
        self._sendto(P.make_ack(frame, payload), addr)

    def _on_cmd(self, frame: P.ControlFrame, addr) -> None:
        now = time.monotonic()
        key = frame.key
        fail = bytes((P.RET_FAIL,))
        if key == (P.CMD_SET_GENERAL, P.CMD_ID_HANDSHAKE):
            self._on_handshake(frame, addr, now)
            return
        if key == (P.CMD_SET_GENERAL, P.CMD_ID_QUERY_INFO):  # read-only: answered to anyone
            self.counters["info_queries"] += 1
            self._reply(frame, addr, P.device_info_payload(self.unit.firmware))
            return
        if self.host is None or addr[0] != self.host[0]:
            self.counters["not_connected"] += 1
            self._reply(frame, addr, fail)
            return
        if frame.cmd_set == P.CMD_SET_GENERAL:
            self._on_general(frame, addr, now)
        elif frame.cmd_set == P.CMD_SET_LIDAR:
            self._on_lidar(frame, addr)
        else:  # hub commands: this is a lidar
            self.counters["unsupported_cmd"] += 1
            self._reply(frame, addr, fail)

    def _on_handshake(self, frame: P.ControlFrame, addr, now: float) -> None:
        try:
            ip, data_port, cmd_port, imu_port = P.parse_handshake(frame.payload)
        except P.PacketError as exc:
            self.counters[exc.reason] += 1
            self._reply(frame, addr, bytes((P.RET_FAIL,)))
            return
        if self._bind_loopback and not ipaddress.IPv4Address(ip).is_loopback:
            self.counters["handshake_not_loopback"] += 1  # never stream off the machine
            self._reply(frame, addr, bytes((P.RET_FAIL,)))
            return
        if self.host is not None and addr[0] != self.host[0]:
            self.counters["handshake_while_held"] += 1
            self._reply(frame, addr, bytes((P.RET_FAIL,)))
            return
        self.host = (ip, data_port)
        self.host_imu = (ip, imu_port or data_port)
        self.host_cmd = addr
        self._last_heartbeat = now
        self.counters["handshakes"] += 1
        self._reply(frame, addr)

    def _on_general(self, frame: P.ControlFrame, addr, now: float) -> None:
        cid, pl = frame.cmd_id, frame.payload
        ok, fail = bytes((P.RET_SUCCESS,)), bytes((P.RET_FAIL,))
        if cid == P.CMD_ID_HEARTBEAT:
            self._last_heartbeat = now
            self.host_cmd = addr
            self.counters["heartbeats"] += 1
            self._reply(frame, addr, P.heartbeat_ack_payload(P.RET_SUCCESS, self.work_state, self.feature,
                                                             self.status_code))
        elif cid == P.CMD_ID_SAMPLING:
            if len(pl) < 1 or pl[0] > 1:
                self._reply(frame, addr, fail)
                return
            start = pl[0] == 1
            if start and self.work_state != P.LIDAR_MODE_NORMAL:
                self.counters["sampling_refused_state"] += 1  # motor off in power-saving / standby
                self._reply(frame, addr, fail)
                return
            first = start and not self.sampling
            if first:
                if self._mono0 is None:  # clock "sampling": stream time starts with the first sampling
                    self._mono0 = now
                self._restart_stream(now)
            self.sampling = start
            self.counters["sampling_start" if start else "sampling_stop"] += 1
            self._reply(frame, addr, ok)
            if first and self.on_sampling_start is not None:
                self.on_sampling_start(self._slot_time_ns(self._next_slot), self.host)
        elif cid == P.CMD_ID_COORDINATE_SYSTEM:
            cs = pl[0] if len(pl) >= 1 else 255
            dt = self.unit.data_type(cs, self.return_mode) if cs in (0, 1) else None
            if dt is None:
                self._reply(frame, addr, fail)
                return
            self.coordinate_system, self.packet_type = cs, dt
            self._reply(frame, addr, ok)
        elif cid == P.CMD_ID_DISCONNECT:
            self._reply(frame, addr, ok)
            self._drop_host()
        elif cid == P.CMD_ID_GET_IP:
            ip = ipaddress.IPv4Address(self.address[0]).packed
            if self.unit.dev_type == 1:  # a Mid-40 answers without mask and gateway (SDK IsMidDeviceIpResponse)
                self._reply(frame, addr, ok + b"\x01" + ip)
            else:
                self._reply(frame, addr, ok + b"\x01" + ip + bytes((255, 0, 0, 0)) + ip)
        elif cid == P.CMD_ID_SET_IP:
            self.counters["set_ip_refused"] += 1  # a virtual unit cannot move to another address
            self._reply(frame, addr, fail)
        elif cid == P.CMD_ID_REBOOT:
            delay_ms = struct.unpack_from("<H", pl)[0] if len(pl) >= 2 else 0
            self._reply(frame, addr, ok)
            self._drop_host()
            self._silent_until = now + delay_ms / 1000.0 + 1.0
            self.counters["reboots"] += 1
        elif cid == P.CMD_ID_WRITE_PARAMS:
            self._reply(frame, addr, self._write_params(pl))
        elif cid == P.CMD_ID_READ_PARAMS:
            self._reply(frame, addr, self._read_params(pl))
        elif cid == P.CMD_ID_RESET_PARAMS:
            self.params = dict(self.unit.param_keys)
            self._reply(frame, addr, ok)
        else:
            self.counters["unsupported_cmd"] += 1
            self._reply(frame, addr, fail)

    def _write_params(self, pl: bytes) -> bytes:
        off = 0
        while off + 4 <= len(pl):
            key, n = struct.unpack_from("<HH", pl, off)
            value = pl[off + 4: off + 4 + n]
            if key not in self.params:
                return struct.pack("<BHB", P.RET_FAIL, key, P.KEY_NOT_SUPPORTED)
            if len(value) != n or n != len(self.params[key]):
                return struct.pack("<BHB", P.RET_FAIL, key, P.KEY_VALUE_LENGTH_ERROR)
            self.params[key] = bytes(value)
            off += 4 + n
        if off != len(pl) or off == 0:
            return struct.pack("<BHB", P.RET_FAIL, 0, P.KEY_VALUE_LENGTH_ERROR)
        return struct.pack("<BHB", P.RET_SUCCESS, 0, P.KEY_NO_ERROR)

    def _read_params(self, pl: bytes) -> bytes:
        if len(pl) < 1 or len(pl) != 1 + 2 * pl[0]:
            return struct.pack("<BHB", P.RET_FAIL, 0, P.KEY_VALUE_LENGTH_ERROR)
        keys = struct.unpack_from(f"<{pl[0]}H", pl, 1)
        body = b""
        for key in keys:
            if key not in self.params:
                return struct.pack("<BHB", P.RET_FAIL, key, P.KEY_NOT_SUPPORTED)
            body += struct.pack("<HH", key, len(self.params[key])) + self.params[key]
        return struct.pack("<BHB", P.RET_SUCCESS, 0, P.KEY_NO_ERROR) + body

    def _on_lidar(self, frame: P.ControlFrame, addr) -> None:
        cid, pl, u = frame.cmd_id, frame.payload, self.unit
        ok, fail = bytes((P.RET_SUCCESS,)), bytes((P.RET_FAIL,))
        arg = pl[0] if len(pl) >= 1 else None
        if cid == P.LIDAR_ID_SET_MODE:
            if arg not in (P.LIDAR_MODE_NORMAL, P.LIDAR_MODE_POWER_SAVING, P.LIDAR_MODE_STANDBY):
                self._reply(frame, addr, fail)
                return
            self.work_state = arg
            if arg != P.LIDAR_MODE_NORMAL:
                self.sampling = False
            self._reply(frame, addr, ok)
        elif cid == P.LIDAR_ID_WRITE_EXTRINSIC:
            if len(pl) != 24:
                self._reply(frame, addr, fail)
                return
            self.extrinsic = struct.unpack("<fffiii", pl)
            self._reply(frame, addr, ok)
        elif cid == P.LIDAR_ID_READ_EXTRINSIC:
            self._reply(frame, addr, ok + struct.pack("<fffiii", *self.extrinsic))
        elif cid == P.LIDAR_ID_RAIN_FOG and u.rain_fog and arg in (0, 1):
            self.feature = arg
            # a scene's source drops its droplet returns (sim.sensor, effect weather) while it is on
            switch = getattr(self.source, "set_rain_fog_suppression", None)
            if switch is not None:
                switch(bool(arg))
            self._reply(frame, addr, ok)
        elif cid == P.LIDAR_ID_SET_FAN and u.has_fan and arg in (0, 1):
            self.fan_on = bool(arg)
            self._reply(frame, addr, ok)
        elif cid == P.LIDAR_ID_GET_FAN and u.has_fan:
            self._reply(frame, addr, ok + bytes((int(self.fan_on),)))
        elif cid == P.LIDAR_ID_SET_RETURN_MODE and arg in u.return_modes \
                and u.data_type(self.coordinate_system, arg) is not None:
            self.return_mode = arg
            self.packet_type = u.data_type(self.coordinate_system, arg)
            self._reply(frame, addr, ok)
        elif cid == P.LIDAR_ID_GET_RETURN_MODE:
            self._reply(frame, addr, ok + bytes((self.return_mode,)))
        elif cid == P.LIDAR_ID_SET_IMU_FREQ and u.has_imu and arg in (P.IMU_FREQ_OFF, P.IMU_FREQ_200HZ):
            if arg == P.IMU_FREQ_200HZ and self.imu_freq != arg:
                self._next_imu = self._imu_index_at(self.stream_time_ns())
            self.imu_freq = arg
            self._reply(frame, addr, ok)
        elif cid == P.LIDAR_ID_GET_IMU_FREQ and u.has_imu:
            self._reply(frame, addr, ok + bytes((self.imu_freq,)))
        elif cid == P.LIDAR_ID_SET_UTC and len(pl) == 8:
            # accepted; the stamps stay of their type (no PPS line to latch the time on)
            self.counters["utc_updates"] += 1
            self._reply(frame, addr, ok)
        else:
            self.counters["unsupported_cmd"] += 1
            self._reply(frame, addr, fail)

    # ------------------------------------------------------------------ data

    def _restart_stream(self, now: float) -> None:
        t = self.stream_time_ns(now)
        self._next_slot = int(np.ceil((t - self.t_start_ns) / self.slot_ns))
        self._next_imu = self._imu_index_at(t)

    def _imu_index_at(self, t_ns: int) -> int:
        return int(np.ceil((t_ns - self.t_start_ns) * P.IMU_RATE_HZ / 1e9))

    def _imu_until(self, t_now_ns: int) -> None:
        """Send the IMU samples (200 Hz grid) up to ``t_now_ns``."""
        k1 = int((t_now_ns - self.t_start_ns) * P.IMU_RATE_HZ // 1e9) + 1
        if k1 <= self._next_imu:
            return
        k = np.arange(self._next_imu, k1)
        t = self.t_start_ns + np.round(k * (1e9 / P.IMU_RATE_HZ)).astype(np.int64)
        gyro, acc = self.imu_source(t)
        for pkt in P.encode_imu_packets(t, gyro, acc, self.timestamp_type, self.status_code):
            try:
                self._data.sendto(pkt, self.host_imu)
                self.counters["imu_packets_sent"] += 1
            except OSError:
                self.counters["send_errors"] += 1
        self._next_imu = k1

    def _stream_until(self, t_now_ns: int) -> None:
        """Send every whole packet whose slots all lie before ``t_now_ns``."""
        n_per = P.POINTS_PER_PACKET[self.packet_type]
        n_slots = int((t_now_ns - self.t_start_ns) // self.slot_ns) - self._next_slot
        n_pk = n_slots // n_per
        if n_pk <= 0:
            return
        n_slots = n_pk * n_per
        t0 = self._slot_time_ns(self._next_slot)
        t1 = self._slot_time_ns(self._next_slot + n_slots)
        xyz, refl, t_ns = self.source(t0, t1)
        xyz_s, refl_s = self._to_slots(t0, n_slots, xyz, refl, t_ns)
        packets = P.encode_data_packets(
            xyz_s, refl_s, t0, self.point_rate_hz, self.packet_type, timestamp_type=self.timestamp_type,
            err_code=self.status_code,
        )
        if self.loss_rate > 0:
            keep = self._rng.random(len(packets)) >= self.loss_rate
            self.counters["packets_lost"] += int(len(packets) - keep.sum())
            packets = [p for p, k in zip(packets, keep) if k]
        host = self.host
        for p in packets:
            try:
                self._data.sendto(p, host)
                self.counters["packets_sent"] += 1
            except OSError:
                self.counters["send_errors"] += 1
        self._next_slot += n_slots

    def _slot_time_ns(self, k: int) -> int:
        return self.t_start_ns + int(round(k * self.slot_ns))

    def _to_slots(self, t0: int, n_slots: int, xyz, refl, t_ns) -> tuple[np.ndarray, np.ndarray]:
        per = self.returns_per_slot
        out_xyz = np.zeros((n_slots * per, 3))
        out_refl = np.zeros(n_slots * per, np.uint8)
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        if xyz.shape[0] == 0:
            return out_xyz, out_refl
        refl = np.asarray(refl).reshape(-1)
        slot = np.rint((np.asarray(t_ns, dtype=np.float64) - t0) / self.slot_ns).astype(np.int64)
        inside = (slot >= 0) & (slot < n_slots)
        self.counters["source_points_outside"] += int((~inside).sum())
        idx = np.nonzero(inside)[0]
        slot = slot[idx]
        order = np.argsort(slot, kind="stable")
        idx, slot = idx[order], slot[order]
        first = np.searchsorted(slot, slot, side="left")
        rank = np.arange(slot.size) - first
        fits = rank < per
        self.counters["source_points_collided"] += int((~fits).sum())
        dest = slot[fits] * per + rank[fits]
        out_xyz[dest] = xyz[idx[fits]]
        out_refl[dest] = np.clip(refl[idx[fits]], 0, 255).astype(np.uint8)
        self.counters["points_sent"] += int(fits.sum())
        return out_xyz, out_refl


def run_virtual_lidar(
    source: Source,
    duration_s: float | None = None,
    ready: Callable[["VirtualLivox"], None] | None = None,
    **kwargs,
) -> dict:
    """Serve a :class:`VirtualLivox` in the calling thread until SIGINT/SIGTERM or ``duration_s``.

    The subprocess entry point (``foveatrack lidar serve`` builds ``source`` from a scene and calls
    this).  ``ready(lidar)`` is called once the sockets are bound.  Returns the counters.
    """
    lidar = VirtualLivox(source, **kwargs)
    stop = threading.Event()
    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, lambda *_: stop.set())
    timer = None
    if duration_s is not None:
        timer = threading.Timer(duration_s, stop.set)
        timer.daemon = True
        timer.start()
    try:
        if ready is not None:
            ready(lidar)
        lidar.serve(stop)
    finally:
        if timer is not None:
            timer.cancel()
        for sig, h in old.items():
            signal.signal(sig, h)
        lidar._close()
    return dict(lidar.counters)


def wall_source(distance_m: float, point_rate_hz: float, fov_deg: float = 38.4, reflectivity: int = 40) -> Source:
    """Demo source: a rosette-like scan (two counter-rotating phases) hitting a wall ``distance_m`` ahead.

    Deterministic in its arguments; one point per slot on the slot grid.
    """
    slot_ns = 1e9 / point_rate_hz
    half = np.deg2rad(fov_deg / 2)

    def source(t0_ns: int, t1_ns: int):
        i0 = int(np.ceil(t0_ns / slot_ns - 1e-9))
        i1 = int(np.ceil(t1_ns / slot_ns - 1e-9))
        i = np.arange(i0, i1)
        t_s = i * (slot_ns * 1e-9)
        a = 2 * np.pi * 7294.0 / 60.0 * t_s
        b = -2 * np.pi * 4664.0 / 60.0 * t_s
        u = 0.5 * half * (np.cos(a) + np.cos(b))
        v = 0.5 * half * (np.sin(a) + np.sin(b))
        xyz = np.stack([np.full_like(u, distance_m), distance_m * np.tan(u), distance_m * np.tan(v)], axis=1)
        return xyz, np.full(i.size, reflectivity, np.uint8), np.round(i * slot_ns).astype(np.int64)

    return source


def main(argv: list[str] | None = None) -> int:
    """``python -m sim.virtual_lidar``: serve a demo wall (prints ``READY <ip> <cmd_port>``)."""
    ap = argparse.ArgumentParser(prog="python -m sim.virtual_lidar", description=main.__doc__)
    ap.add_argument("--bind-ip", default="127.0.0.1")
    ap.add_argument("--cmd-port", type=int, default=P.DEFAULT_SENSOR_CMD_PORT)
    ap.add_argument("--broadcast-ip", default="127.0.0.1")
    ap.add_argument("--broadcast-port", type=int, default=P.DEFAULT_BROADCAST_PORT)
    ap.add_argument("--rate-hz", type=float, default=240_000.0)
    ap.add_argument("--packet-type", type=int, default=None, choices=P.POINT_DATA_TYPES)
    ap.add_argument("--wall-m", type=float, default=20.0)
    ap.add_argument("--loss-rate", type=float, default=0.0)
    ap.add_argument("--time-scale", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration-s", type=float, default=None)
    a = ap.parse_args(argv)

    def ready(lidar: VirtualLivox) -> None:
        print(f"READY {lidar.address[0]} {lidar.cmd_port}", flush=True)

    counters = run_virtual_lidar(
        wall_source(a.wall_m, a.rate_hz),
        duration_s=a.duration_s,
        ready=ready,
        bind_ip=a.bind_ip,
        cmd_port=a.cmd_port,
        broadcast_addr=(a.broadcast_ip, a.broadcast_port),
        point_rate_hz=a.rate_hz,
        packet_type=a.packet_type,
        loss_rate=a.loss_rate,
        time_scale=a.time_scale,
        seed=a.seed,
    )
    print(" ".join(f"{k}={v}" for k, v in sorted(counters.items())), flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
