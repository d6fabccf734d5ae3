"""The daemon's start and end: the devices, recording and receiver opened (links first), the start
logged, SIGINT/SIGTERM turned into a request to stop while it runs, and the shutdown that stops the
head and closes everything (one role of :class:`foveatrack.daemon.runtime.Daemon`).

The signal handlers go back to what they were on every way out, also when a shutdown step raises:
a handler left behind by an in-process run (a test, a caller of :class:`Daemon`) only sets the
event of a daemon long gone, so a later Ctrl-C in that process did nothing.
"""

from __future__ import annotations

import queue
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict

from foveatrack.control import STOP
from foveatrack.daemon.head_pose import LinkSeen
from foveatrack.daemon.receiver import LidarReceiver
from foveatrack.daemon.record_queue import _job_event
from foveatrack.daemon.watchdog import WatchdogState
from foveatrack.live_devices import open_devices
from foveatrack.recording.records import ns

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Lifecycle:
    """The start and end of the daemon (a mixin of ``Daemon``)."""

    def _open(self):
        # Links first, the recording last: a port that cannot be used fails the start before a
        # recording file exists (an empty one was left behind for every failed start).
        c = self.cfg
        self.head, self.client = open_devices(c)
        # the bound ports (config 0 = any), kept: the client's sockets are closed at shutdown
        self.host_ports = {"cmd": self.client.cmd_port, "data": self.client.data_port,
                           "broadcast": self.client.broadcast_port}
        self._open_control()      # the operator's socket ([tracker.sky]): a path in use fails the start here
        try:
            self._open_recording()
            if self.live_port is not None:
                try:
                    self._open_live()
                except Exception:
                    self._forget_unused_recording()
                    raise
        except BaseException:
            self._close_control()
            raise
        self.q: queue.Queue = queue.Queue(maxsize=c.loop.batch_queue)
        self.rx = LidarReceiver(self.client, self.q, self.stop_ev)
        self.rx.want_imu = self.imu_feed is not None
        # IMU packets are held only for a tracker that takes its attitude from them (issue 26: every
        # packet of a Horizon was kept otherwise, ~1 MB/min)
        self.client.decoder.keep_imu = self.rx.want_imu

    @contextmanager
    def _stop_signals(self):
        """While inside: SIGINT and SIGTERM set ``stop_ev`` (the loop stops the head and closes the
        recording its own way).  The handlers found are put back on every way out (only the main
        thread can set handlers; ``install_signals=False`` leaves them alone)."""
        old = {}
        try:
            if self.install_signals and threading.current_thread() is threading.main_thread():
                for sig in STOP_SIGNALS:
                    old[sig] = signal.signal(sig, lambda *_: self._stop_by_signal())
            yield
        finally:
            for sig, h in old.items():
                # None: a handler not set from Python, which cannot be put back; the default is
                signal.signal(sig, signal.SIG_DFL if h is None else h)

    def _stop_by_signal(self) -> None:
        """SIGINT/SIGTERM: stop, and remember how long after the start (a stop before the lidar had
        time to announce itself is no lidar fault: :attr:`RunStats.stopped_before_data`)."""
        if getattr(self, "signal_after_s", None) is None:
            started = getattr(self, "started_mono", None)
            self.signal_after_s = None if started is None else time.monotonic() - started
        self.stop_ev.set()

    def _start(self) -> None:
        """The start in the log, the head stopped, the receiver running; the loop's state fresh."""
        self.started_mono = time.monotonic()
        c = self.cfg
        self.log.event("start", config=c.path, recording=str(self.recording_path) if self.recording_path else None,
                       lidar=asdict(c.lidar), head_port=c.head.port, head_open=self.head.connected,
                       rate_hz=c.tracker.rate_hz, heap_returns_freed=self.heap_returns_freed,
                       host_ports=self.host_ports)
        for w in c.warnings():
            self.log.event("warning", message=w)
        self.head.stop()
        killed = []
        if self.recording_path is not None:   # a killed run's recording here: completed from its journal
            from foveatrack.daemon.recover import recover_directory

            killed = recover_directory(self.recording_path.parent, self.log.event, exclude=[self.recording_path])
        self.rx.start()
        self.watchdog = WatchdogState()
        self.link_seen = LinkSeen(head_up=self.head.connected)   # after the first STOP, which may reopen it
        h = c.head
        if h.on_start == "home":
            # the head reports no pose: drive it home (home_pan_deg / home_tilt_deg, by default pan0_deg /
            # tilt0_deg) by absolute moves before tracking, as a reconnected head is
            # (foveatrack.daemon.head_pose), wherever a previous run left it
            now = time.monotonic()
            self._pose_unknown(now, "start", policy="home")
            self._reconnected(now)
        elif killed and self.head.connected:
            from foveatrack.daemon.recover import head_after_a_kill

            self.status.note(f"foveatrack daemon: WARNING: the run before this one was killed (its recording was "
                             f"completed above): {head_after_a_kill(h.pan0_deg, h.tilt0_deg, 'this run')}")

    def _shutdown(self) -> None:
        self.stop_ev.set()
        t_s = self.sensor_now_s()
        if self.pose_state == "refused":     # another head behind the link: not even a STOP
            pass
        elif t_s is not None:
            t_s = self._send_time(t_s)
            self._send_own(STOP, "shutdown", t_s)
        else:
            self.head.stop()
        if self.rx.ident is not None:       # started (a start that failed before it did not)
            self.rx.join(2.0)
        self.client.close()
        self.head.close()
        self._close_control()
        stats = self.stats()
        if self.recorder is not None:
            self._record(_job_event, ns(t_s or 0.0), {"event": "stop", "stats": stats})
            self.recorder.close()
            stats["recording_dropped"] = self.recorder.dropped
            if self.recorder.error is not None:
                self.log.event("recording_error", error=repr(self.recorder.error))
        if self.live is not None:
            self.live.stop()
        self.status.done()
        self.log.event("stop", stats=stats, recording=str(self.recording_path) if self.recording_path else None)
        self.log.close()
        self.final_stats = stats
