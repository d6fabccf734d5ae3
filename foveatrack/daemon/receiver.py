"""The daemon's receiver thread: the lidar's packets in, (host time, points) batches out.

It owns the lidar's :class:`~foveatrack.live_devices.LidarStream` (the host - sensor clock offset, the
packet watchdog's clock), strips no-return points (keeping each batch's last for its time), takes the
IMU samples for a tracker that wants them, and hands everything to the control loop
(:mod:`foveatrack.daemon.runtime`) through a bounded queue, counting what it had to drop.
"""

from __future__ import annotations

import queue
import threading
from collections import deque

import numpy as np

from foveatrack.live_devices import LidarStream


class LidarReceiver(threading.Thread):
    """Owns the lidar's :class:`~foveatrack.live_devices.LidarStream`; hands (host time, xyz, t_ns,
    reflectivity) to the control loop."""

    def __init__(self, client, q: queue.Queue, stop: threading.Event):
        super().__init__(name="livox-receiver", daemon=True)
        self.client, self.q, self.stop_ev = client, q, stop
        self.stream = LidarStream(client)
        self.dropped_batches = 0
        self.dropped_points = 0
        self.points_in = 0
        self.first_t_ns: int | None = None
        self.last_t_ns: int | None = None
        self.span_done_ns = 0        # sensor time spanned by earlier clock epochs (a restarted lidar)
        self.error: BaseException | None = None
        self.counters: dict = {}
        # what the unit reports (LivoxClient.take_events), for the control loop's log and status line
        self.unit_events: queue.SimpleQueue = queue.SimpleQueue()
        self.unit_note = ""
        self.epoch = 0
        # The lidar's IMU samples (data type 6) for a tracker that takes its attitude from the gyro:
        # (t_ns, gyro_rad_s, clock epoch, acc_g) batches, taken by the control loop.
        self.want_imu = False
        self.imu: deque = deque(maxlen=4096)

    @property
    def offset_s(self) -> float | None:
        return self.stream.offset_s

    @property
    def last_packet_mono(self) -> float | None:
        return self.stream.last_packet_mono

    def run(self) -> None:
        try:
            self.client.start_sampling()
            while not self.stop_ev.is_set():
                now, batches = self.stream.poll(0.02)
                if self.want_imu:
                    imu = self.client.take_imu()
                    if len(imu.t_ns):
                        self.imu.append((imu.t_ns, imu.gyro_rad_s, self.stream.epoch, imu.acc_g))
                self.counters = {**self.client.counters, **self.stream.counters}
                for jump in self.stream.take_jumps():   # the sensor clock restarted or jumped: re-anchored
                    self.unit_events.put(jump.as_event())
                for ev in self.client.take_events():
                    self.unit_events.put(ev)
                    st = self.client.unit_status()
                    bad = st["work_state_name"] not in (None, "normal")
                    self.unit_note = ", ".join(([f"lidar {st['work_state_name']}"] if bad else []) + st["problems"])
                for b in batches:
                    if not len(b):
                        continue
                    t_last = int(b.t_ns[-1])
                    if b.epoch != self.epoch:
                        if self.first_t_ns is not None:
                            self.span_done_ns += self.last_t_ns - self.first_t_ns
                        self.epoch, self.first_t_ns, self.last_t_ns = b.epoch, None, None
                    if self.first_t_ns is None:
                        self.first_t_ns = int(b.t_ns[0])
                    # a late packet is handed on after newer ones (sensor_time): the span ends at the newest
                    self.last_t_ns = t_last if self.last_t_ns is None else max(self.last_t_ns, t_last)
                    self.points_in += len(b)
                    xyz, t_ns, refl = b.xyz, b.t_ns, b.reflectivity
                    ret = np.any(xyz != 0.0, axis=1)
                    if not ret.all():
                        # no-return points carry no data, but the last one carries the time, so
                        # frames keep coming while the lidar sees only sky (stripped in the loop)
                        ret[-1] = True
                        xyz, t_ns, refl = xyz[ret], t_ns[ret], refl[ret]
                    try:
                        self.q.put_nowait((now, xyz, t_ns, refl, b.epoch))
                    except queue.Full:
                        self.dropped_batches += 1
                        self.dropped_points += len(t_ns)
        except BaseException as exc:  # noqa: BLE001 - reported by the control loop
            self.error = exc
