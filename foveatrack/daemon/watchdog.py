"""The lidar's watchdog: STOP to the head when no lidar packet has arrived for ``watchdog_s`` (and
again every second while it is silent), and the lidar unit's own events in the log (one role of
:class:`foveatrack.daemon.runtime.Daemon`, run on the loop's 10 Hz tick)."""

from __future__ import annotations

from dataclasses import dataclass

from foveatrack.control import STOP

WATCHDOG_REPEAT_S = 1.0     # STOP again this often while the lidar stays silent


@dataclass
class WatchdogState:
    lidar_up: bool = False          # a packet has arrived since the start
    tripped: bool = False           # silent for watchdog_s after data had come
    last_stop: float = -1e9         # host time of the last STOP it sent [s]


class LidarWatch:
    """The watchdog's part of the daemon (a mixin of ``Daemon``; its state: ``watchdog``)."""

    def _watch_lidar(self, now: float) -> None:
        while not self.rx.unit_events.empty():   # the unit's state, status, refusals, link losses
            ev = dict(self.rx.unit_events.get_nowait())
            self.log.event("lidar_" + ev.pop("event"), **ev)
        w = self.watchdog
        last_pkt = self.rx.last_packet_mono
        silent = last_pkt is None or now - last_pkt > self.cfg.loop.watchdog_s
        if last_pkt is not None and not w.lidar_up:
            w.lidar_up = True
            self.log.event("lidar_data", offset_s=self.rx.offset_s, device=self.client.device_broadcast_code)
        if silent and w.lidar_up and not w.tripped:
            w.tripped = True
            self.counters["watchdog_trips"] += 1
            self.log.event("watchdog_stop", silent_s=now - last_pkt)
        if (silent and (w.tripped or last_pkt is None) and now - w.last_stop >= WATCHDOG_REPEAT_S
                and self.pose_state is None):
            w.last_stop = now
            t_s = self.sensor_now_s(now)
            if t_s is not None and w.tripped:
                self._send_own(STOP, "watchdog", self._send_time(t_s))
            else:
                self.head.stop()
        if not silent and w.tripped:
            w.tripped = False
            self.log.event("lidar_resumed")
