"""A virtual Livox lidar that speaks the SDK v1 protocol over UDP, streaming simulated points.

``VirtualLivox(source, ...)`` answers discovery (it broadcasts until a host handshakes), handshake,
heartbeat and start/stop sampling exactly like a lidar (facts: livox.md), and while sampling sends
data packets paced in real time on the monotonic clock (``time_scale`` > 1 runs the stream faster).

The points come from ``source(t0_ns, t1_ns) -> (xyz, reflectivity, t_ns)``: the returns a simulated
lidar produces for the slots in ``[t0_ns, t1_ns)`` of *stream time* (``t_start_ns`` + elapsed wall time
× time_scale).  A lidar fires at a fixed rate, one slot every ``1e9 / point_rate_hz`` ns (two returns
per slot for the dual type 4); each returned point goes to the slot nearest its ``t_ns``, slots
without a point go out as "no return" (0, 0, 0), points beyond a slot's capacity or outside the
interval are counted and dropped.  A source that produces points on the slot grid therefore comes out
of :class:`foveatrack.livox.client.LivoxClient` with the same times (±1 ns) and positions (±0.5 mm).

Faults for tests: ``loss_rate`` drops that fraction of data packets (seeded generator, one stream).

Use it in-process (``with VirtualLivox(...) as lidar:`` runs a thread) or blocking in a process of
its own (:func:`run_virtual_lidar`, which stops on SIGINT/SIGTERM; ``python -m sim.virtual_lidar``
serves a demo wall for manual tests).  The wall clock here only paces the stream; the source is
handed explicit stream times and never reads a clock.
"""

from __future__ import annotations

import argparse
import selectors
import signal
import socket
import sys
import threading
import time
from collections import Counter
from typing import Callable

import numpy as np

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P

Source = Callable[[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]


class VirtualLivox:
    """A Livox lidar on UDP (SDK v1), fed by ``source``.

    source : callable(t0_ns, t1_ns) -> (xyz (n,3) [m] lidar frame, reflectivity (n,) u8, t_ns (n,) int)
    bind_ip : str, the lidar's address (e.g. 127.0.0.1, or 127.0.0.2 to look like another host)
    cmd_port : int, the lidar's command port (65000 on real lidars; 0 = any free port)
    broadcast_addr : (ip, port), where discovery broadcasts go (host port 55000 on a real network)
    point_rate_hz : float > 0 [slots/s]; packet_type : 0..4 (2 extended Cartesian, as Horizon)
    time_scale : float > 0, stream seconds per wall second
    loss_rate : float in [0, 1), fraction of data packets dropped; seed : int for that generator
    t_start_ns : int, stream time at start(); batch_period_s : wall seconds between source calls
    """

    def __init__(
        self,
        source: Source,
        bind_ip: str = "127.0.0.1",
        cmd_port: int = P.DEFAULT_SENSOR_CMD_PORT,
        broadcast_addr: tuple[str, int] = ("127.0.0.1", P.DEFAULT_BROADCAST_PORT),
        point_rate_hz: float = 240_000.0,
        packet_type: int = 2,
        broadcast_code: str = "VLIVOX0000000001",
        dev_type: int = P.DEVICE_TYPES["horizon"],
        time_scale: float = 1.0,
        loss_rate: float = 0.0,
        seed: int = 0,
        t_start_ns: int = 0,
        batch_period_s: float = 0.01,
        broadcast_period_s: float = 0.5,
        link_timeout_s: float = 3.0,
        timestamp_type: int = 0,
    ):
        if packet_type not in P.POINT_DATA_TYPES:
            raise ValueError(f"packet_type must be one of {P.POINT_DATA_TYPES}, got {packet_type}")
        if not point_rate_hz > 0 or not time_scale > 0 or not 0 <= loss_rate < 1:
            raise ValueError("need point_rate_hz > 0, time_scale > 0 and 0 <= loss_rate < 1")
        self.source = source
        self.point_rate_hz = float(point_rate_hz)
        self.packet_type = packet_type
        self.broadcast_code = broadcast_code
        self.dev_type = dev_type
        self.time_scale = float(time_scale)
        self.loss_rate = float(loss_rate)
        self.t_start_ns = int(t_start_ns)
        self.batch_period_s = batch_period_s
        self.broadcast_period_s = broadcast_period_s
        self.link_timeout_s = link_timeout_s
        self.timestamp_type = timestamp_type
        self.broadcast_addr = broadcast_addr
        self._rng = np.random.default_rng(np.random.SeedSequence(seed))
        self.counters: Counter = Counter()

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
        self.sampling = False
        self._last_heartbeat = 0.0
        self._seq = 0
        self._mono0: float | None = None
        self._next_slot = 0  # index of the next slot to send (slot k is at t_start + k / rate)
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

    def stream_time_ns(self, mono: float | None = None) -> int:
        mono = time.monotonic() if mono is None else mono
        if self._mono0 is None:
            return self.t_start_ns
        return self.t_start_ns + int((mono - self._mono0) * self.time_scale * 1e9)

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
        self._mono0 = time.monotonic()
        next_bcast = 0.0
        next_batch = self._mono0
        while not stop.is_set():
            now = time.monotonic()
            if self.host is not None and now - self._last_heartbeat > self.link_timeout_s:
                self.counters["link_timeouts"] += 1
                self.host, self.sampling = None, False
            if self.host is None and now >= next_bcast:
                self._send_broadcast()
                next_bcast = now + self.broadcast_period_s
            if self.sampling and now >= next_batch:
                self._stream_until(self.stream_time_ns(now))
                next_batch = now + self.batch_period_s
            deadline = next_batch if self.sampling else next_bcast if self.host is None else now + 0.05
            for _key, _ in self._sel.select(max(0.0, min(deadline - time.monotonic(), 0.05))):
                self._drain_cmd()

    # ------------------------------------------------------------------ control

    def _send_broadcast(self) -> None:
        self._seq = (self._seq + 1) & 0xFFFF
        try:
            self._cmd.sendto(P.make_broadcast(self._seq, self.broadcast_code, self.dev_type), self.broadcast_addr)
            self.counters["broadcasts"] += 1
        except OSError:
            self.counters["send_errors"] += 1

    def _drain_cmd(self) -> None:
        while True:
            try:
                buf, addr = self._cmd.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self.counters["recv_errors"] += 1
                return
            frame, reason = P.parse_control_safe(buf)
            if frame is None:
                self.counters[reason] += 1
                continue
            if frame.cmd_type != P.CMD_TYPE_CMD or frame.cmd_set != P.CMD_SET_GENERAL:
                self.counters["ignored"] += 1
                continue
            self._on_cmd(frame, addr)

    def _reply(self, frame: P.ControlFrame, addr, payload: bytes = b"\0") -> None:
        try:
            self._cmd.sendto(P.make_ack(frame, payload), addr)
        except OSError:
            self.counters["send_errors"] += 1

    def _on_cmd(self, frame: P.ControlFrame, addr) -> None:
        now = time.monotonic()
        cid = frame.cmd_id
        if cid == P.CMD_ID_HANDSHAKE:
            try:
                ip, data_port, _cmd_port, _imu = P.parse_handshake(frame.payload)
            except P.PacketError as exc:
                self.counters[exc.reason] += 1
                self._reply(frame, addr, b"\1")
                return
            self.host = (ip, data_port)
            self._last_heartbeat = now
            self.counters["handshakes"] += 1
            self._reply(frame, addr)
        elif self.host is None or addr[0] != self.host[0]:
            self.counters["not_connected"] += 1
            self._reply(frame, addr, b"\1")
        elif cid == P.CMD_ID_HEARTBEAT:
            self._last_heartbeat = now
            self.counters["heartbeats"] += 1
            self._reply(frame, addr, P.heartbeat_ack_payload(state=1))
        elif cid == P.CMD_ID_SAMPLING:
            start = frame.payload[:1] == b"\1"
            if start and not self.sampling:
                self._next_slot = int(np.ceil((self.stream_time_ns(now) - self.t_start_ns) / self.slot_ns))
            self.sampling = start
            self.counters["sampling_start" if start else "sampling_stop"] += 1
            self._reply(frame, addr)
        elif cid == P.CMD_ID_DISCONNECT:
            self._reply(frame, addr)
            self.host, self.sampling = None, False
        else:
            self.counters["unsupported_cmd"] += 1
            self._reply(frame, addr, b"\1")

    # ------------------------------------------------------------------ data

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
            xyz_s, refl_s, t0, self.point_rate_hz, self.packet_type, timestamp_type=self.timestamp_type
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
        per = 2 if self.packet_type == 4 else 1
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
    ap.add_argument("--packet-type", type=int, default=2, choices=P.POINT_DATA_TYPES)
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
