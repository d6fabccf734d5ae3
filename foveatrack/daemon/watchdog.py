"""The lidar's watchdog: STOP to the head when no lidar packet has arrived for ``watchdog_s`` (and
again every second while it is silent), and the lidar unit's own events in the log (one role of
:class:`foveatrack.daemon.runtime.Daemon`, run on the loop's 10 Hz tick)."""

from __future__ import annotations

from dataclasses import dataclass

from foveatrack.control import STOP

WATCHDOG_REPEAT_S = 1.0     # STOP again this often while the lidar stays silent
#: with no lidar data since the start, a note on stderr after this long [s], then every NO_DATA_REPEAT_S
NO_DATA_NOTE_S = 10.0
NO_DATA_REPEAT_S = 60.0


@dataclass
class WatchdogState:
    lidar_up: bool = False          # a packet has arrived since the start
    tripped: bool = False           # silent for watchdog_s after data had come
    last_stop: float = -1e9         # host time of the last STOP it sent [s]
    next_no_data_note: float | None = None   # host time of the next "no lidar data yet" note [s]
    silent_since: float | None = None        # host time of the last packet before the trip [s]


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
        if last_pkt is None:
            # nothing yet: said on stderr now and then, not only at the exit (a daemon under systemd,
            # its stderr in the journal, ran 10 minutes with a wrong broadcast port in silence)
            if w.next_no_data_note is None:
                w.next_no_data_note = self.started_mono + NO_DATA_NOTE_S
            if now >= w.next_no_data_note:
                w.next_no_data_note = now + NO_DATA_REPEAT_S
                self.status.note("foveatrack daemon: WARNING: " + self.no_lidar_data_text(
                    f" in {now - self.started_mono:.0f} s so far"))
        if silent and w.lidar_up and not w.tripped:
            w.tripped = True
            w.silent_since = last_pkt
            self.counters["watchdog_trips"] += 1
            self.log.event("watchdog_stop", silent_s=now - last_pkt)
            self.status.note(f"foveatrack daemon: WARNING: no lidar packet for {now - last_pkt:.1f} s: the head "
                             f"is stopped until the lidar comes back")
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
            self.status.note(f"foveatrack daemon: the lidar is back after {last_pkt - w.silent_since:.1f} s of silence")
