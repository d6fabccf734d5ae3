"""The daemon's figures and what went wrong, in words: the counters of the loop, the lidar, the head
and the recording in one dict (the log's ``stop`` event, the CLI's last lines).  One role of
:class:`foveatrack.daemon.runtime.Daemon`."""

from __future__ import annotations

from dataclasses import asdict


def rate_known(d) -> bool:
    return getattr(d, "client", None) is not None and d.client.decoder.point_rate_hz > 0


#: how long a Livox may take to be heard after the daemon starts (it broadcasts once a second, and the
#: handshake follows): a stop within it, with nothing heard, is not a lidar fault
ANNOUNCE_WAIT_S = 3.0
#: lidar points lost on the way [%] from which the end of a run says so on stderr (the log has every figure)
LOST_PCT_SAID = 1.0


class RunStats:
    """The figures' part of the daemon (a mixin of ``Daemon``)."""

    def stats(self) -> dict:
        """All counters in one flat dict (loop, lidar, head, recording)."""
        d = dict(self.counters)
        rx = getattr(self, "rx", None)
        if rx is not None:
            d.update({f"lidar_{k}": v for k, v in rx.counters.items()})
            d["queue_dropped_batches"] = rx.dropped_batches
            d["queue_dropped_points"] = rx.dropped_points
            if rx.first_t_ns is not None and rate_known(self):
                span = (rx.last_t_ns - rx.first_t_ns + rx.span_done_ns) * 1e-9
                expected = span * self.client.decoder.point_rate_hz
                if expected > 0:
                    d["lidar_points_missing_pct"] = round(max(0.0, 100.0 * (1 - rx.points_in / expected)), 3)
                d["lidar_lost_pct"] = round(self.lost_pct() or 0.0, 3)
        if getattr(self, "head", None) is not None:
            d.update({f"head_{k}": v for k, v in asdict(self.head.stats).items()})
        d["slicer_late_points"] = self.slicer.late_points
        if self.recorder is not None:
            d["recording_dropped"] = self.recorder.dropped
            d["recording_jobs"] = self.recorder.written
        for name, xs in (("processing_ms", self.proc_ms), ("latency_ms", self.lat_ms)):
            if xs.count:
                # percentiles within half a bin (0.05 ms) of the exact ones: foveatrack.daemon.streaming_summary
                d[f"{name}_p50"] = round(xs.percentile(50), 3)
                d[f"{name}_p99"] = round(xs.percentile(99), 3)
                d[f"{name}_max"] = round(xs.max, 3)
        return d

    def problems(self) -> list[str]:
        """What went wrong in the run, in words for the final stderr lines (empty when nothing did).

        A run that received nothing from the lidar otherwise ended on "0 frames" with the reason
        only in the log's counters (e.g. a mistyped ``sensor_ip``: every datagram was dropped as
        ``lidar_foreign_source``)."""
        out = []
        rx = getattr(self, "rx", None)
        if self.stopped_before_data:
            out.append(f"stopped by a signal {self.signal_after_s:.1f} s after its start, before any lidar data "
                       f"arrived (a Livox announces itself once a second): no lidar fault to report")
        elif rx is not None and rx.last_packet_mono is None:
            out.append(self.no_lidar_data_text())
        failed = self.counters.get("commands_failed", 0)
        if failed:
            total = failed + self.counters.get("commands_written", 0)
            out.append(f"{failed} of {total} head commands were not written to [head] port {self.cfg.head.port!r} "
                       "(see head_* counters in the log)")
        lost = self.lost_pct()
        if lost is not None and lost >= LOST_PCT_SAID:
            # said in the log's counters alone, a lossy network went unnoticed (a user's audit, 30 %)
            out.append(f"{lost:.1f} % of the lidar's points were lost on the way (missing from its packets' "
                       f"sequence; lidar_lost_pct in the log): the network between the lidar and this host drops "
                       f"datagrams (a direct cable, or a larger receive buffer: net.core.rmem_max)")
        out.extend(text for _, text in self.output_faults())     # a recording, journal or log not written
        return out

    def no_lidar_data_text(self, so_far: str = "") -> str:
        """Why no lidar data arrived, in words (the end-of-run problem; while it runs, the watchdog's
        note with ``so_far``, e.g. " in 10 s so far"): the ports listened on, and the datagrams
        dropped from another address, or that nothing arrived at all."""
        rx = self.rx
        L = self.cfg.lidar
        hp = self.host_ports
        ports = f"data port {hp['data']}, command port {hp['cmd']}" + (
            f", broadcasts on port {hp['broadcast']}" if hp["broadcast"] is not None else "")
        msg = f"no lidar data arrived from [lidar] sensor_ip {L.sensor_ip}{so_far} ({ports})"
        foreign = sorted(self.client.foreign_addresses)
        if foreign:
            return msg + (f"; {rx.counters.get('foreign_source', 0)} datagrams from {', '.join(foreign)} were "
                          "dropped: is sensor_ip the lidar's address?")
        return msg + (f"; nothing arrived at all: is the lidar on and on this network, and host_ip {L.host_ip} "
                      "this host's address on it?")

    @property
    def no_lidar_data(self) -> bool:
        """True when the run never received a lidar packet (the CLI exits non-zero), unless it was
        stopped before the lidar had time to announce itself (:attr:`stopped_before_data`)."""
        rx = getattr(self, "rx", None)
        return rx is not None and rx.last_packet_mono is None and not self.stopped_before_data

    @property
    def stopped_before_data(self) -> bool:
        """Stopped by SIGINT/SIGTERM within :data:`ANNOUNCE_WAIT_S` of the start with no lidar packet yet:
        a user's Ctrl-C 0.8 s in was told the lidar was off the network (exit 3)."""
        rx = getattr(self, "rx", None)
        after = getattr(self, "signal_after_s", None)
        return rx is not None and rx.last_packet_mono is None and after is not None and after < ANNOUNCE_WAIT_S

    def drops(self) -> int:
        rx = self.rx
        c = rx.counters
        return (c.get("dropped_total", 0) + rx.dropped_batches + self.counters["frames_skipped"]
                + (self.recorder.dropped if self.recorder else 0))

    def lost_pct(self) -> float | None:
        """Lidar points lost on the way [%]: the slots missing inside the stream (by time, as a
        sequence number) against the slots the stream spanned."""
        rx = getattr(self, "rx", None)
        if rx is None or rx.first_t_ns is None or not rate_known(self):
            return None
        span_slots = (rx.last_t_ns - rx.first_t_ns + rx.span_done_ns) * 1e-9 * self.client.decoder.point_rate_hz
        lost = rx.counters.get("lost_slots", 0)
        return 100.0 * lost / span_slots if span_slots > 0 and lost else None
