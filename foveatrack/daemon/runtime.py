"""The real-time daemon: Livox lidar in, Pelco-D out, at the tracker's 10 Hz (paper Appendix D).

Threads and queues::

    receiver thread:  LivoxClient.poll -> (host time, points) -> bounded batch queue (drops counted)
    control loop:     batch queue -> FrameSlicer -> Tracker.process -> CommandGate -> HeadClient
                      (the main thread; a monotonic 10 Hz tick runs the watchdog and the status)
    recording thread: bounded job queue -> RecordingWriter (drops counted; never blocks the loop)
    operator socket:  read by the control loop between frames, without waiting ([tracker.sky] only:
                      ``foveatrack daemon pin ID``, :mod:`foveatrack.daemon.operator`)

Each frame is processed as soon as it is complete (the first point at or after its end has
arrived), so the loop is paced by the lidar's clock; the monotonic tick keeps the watchdog and the
status line going when the lidar is silent.  If more than ``max_frame_backlog`` frames are waiting
(the loop fell behind, or the lidar came back after a gap) the oldest are skipped and counted
(``frames_skipped``): commands for stale frames would be wrong.

Time.  Point times are the sensor's clock (``t_ns``; no sync: ns since power-on).  Host time of a
sensor time is ``t_sensor + offset`` with ``offset = min over packets (host receive time - time of
the packet's last point)``: the offset at the first packet, lowered whenever a packet arrives
sooner than it predicts.  So the mapping is exact up to the smallest transit delay seen (on loopback
well under 1 ms; on Ethernet ~0.1 ms) and drifts with the sensor's clock error (ppm: 0.1 ms per
100 s at 1 ppm); for long runs sync the lidar (PTP) or restart.  The tracker runs in sensor time:
``send_t_s`` handed to :meth:`Tracker.process` is the host's "now" mapped to sensor time plus the
expected compute time (the median of the last nine), and no earlier than the previous command has
left the serial line (one Pelco frame time later).

Figures recorded per frame (``/metrics``): ``processing_ms`` = from the arrival of the batch that
completed the frame to the command bytes written (slicing, detection, control, encoding, write);
``latency_ms`` = end to end, host time of the frame's last point -> command bytes written.

Safety: a command leaves only through :class:`foveatrack.gate.CommandGate` (speed bytes, turbo, tilt
stops against the reconstructed tilt, stale frames, failed writes; the simulator and replay run the
same gate); the watchdog sends STOP when no lidar packet has
arrived for ``watchdog_s`` (and repeats it every second while silent); SIGINT/SIGTERM stop the
head, close the recording and return 0.  The serial link reconnects by itself
(:class:`gimbal.client.HeadClient`).
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter, deque
from typing import TYPE_CHECKING

from foveatrack.daemon.frame_loop import FrameLoop, _HeadSink
from foveatrack.daemon.head_pose import ABS_SET_QUIET_S, HeadPose  # noqa: F401  (ABS_SET_QUIET_S: its old home)
from foveatrack.daemon.homing_plan import Bearings, HomingConfirm, HomingPlan, HomingSteps
from foveatrack.daemon.lifecycle import Lifecycle
from foveatrack.daemon.operator import Operator
from foveatrack.daemon.pose_guard import PoseGuard
from foveatrack.daemon.record_queue import DaemonRecording, _job_event, _job_frame  # noqa: F401
from foveatrack.daemon.run_stats import RunStats, rate_known  # noqa: F401
from foveatrack.daemon.streaming_summary import StreamingSummary
from foveatrack.daemon.status_display import PROGRESS_PERIOD_S, StatusDisplay
from foveatrack.daemon.support import JsonLog, RecordingThread, StatusLine
from foveatrack.daemon.watchdog import LidarWatch
from foveatrack.device_config import DaemonConfig
from foveatrack.frames import FrameSlicer
from foveatrack.frame_step import FrameStep
from foveatrack.gate import CommandGate
from foveatrack.gyro_attitude import ImuFeed
from foveatrack.startup_heap import freeze_startup_heap
from foveatrack.tracker import Tracker
from foveatrack.turn_witness import MoveWitness

if TYPE_CHECKING:       # imported where a config asks for it (the sky tracker's modules are not small)
    from foveatrack.sky.controller import SkyController


def daemon_controller(config: DaemonConfig, table) -> Tracker | SkyController:
    """The daemon's controller: the paper's tracker (Algorithms 1 and 2), or -- where the config's
    ``[tracker]`` has a ``[tracker.sky]`` table -- the multi-object tracker steering the head through
    it (:mod:`foveatrack.sky.controller`, as the simulator builds it for a scene with that table).

    The lidar's field (``field_half_angle_deg``, which tells a track out of view from one unseen in
    it): the table's; the daemon does not know the lidar's model when it starts (the handshake comes
    later, and its field is what the recording's metadata must hold from the start), so without the
    key every track counts as in view."""
    tracker = Tracker(config.tracker, table)
    sky = config.tracker_table.get("sky")
    if sky is None:
        return tracker
    from foveatrack.sky.controller import SkyController

    return SkyController.from_table(tracker, sky, f"{config.path} [tracker.sky]")


def compile_sky(config: DaemonConfig, table) -> None:
    """Compile (or load from numba's cache) the multi-object tracker's kernels before data flows, as
    :func:`foveatrack.detection.compile_all` does the paper tracker's, on a throwaway copy of the
    daemon's controller (:func:`foveatrack.sky.warm.compile_sky_kernels`).  Without it a fresh
    install's first frames past the tracker's warm-up waited seconds for the compiler."""
    if not config.sky:
        return
    from foveatrack.sky.warm import compile_sky_kernels

    compile_sky_kernels(lambda: daemon_controller(config, table), config.tracker.rate_hz)


class Daemon(Lifecycle, FrameLoop, HeadPose, LidarWatch, DaemonRecording, Operator, StatusDisplay, RunStats):
    """One run of the daemon (see module docstring).  ``run()`` returns the exit status (0).

    config : DaemonConfig; log_path : JSON-lines log (overrides ``[daemon] log``);
    status : show the status line (None = if stderr is a TTY); duration_s : stop after this long

    Its roles live in the modules of its bases: :mod:`~foveatrack.daemon.lifecycle` (open, signals,
    shutdown), :mod:`~foveatrack.daemon.frame_loop` (batches -> frames -> the step -> the head),
    :mod:`~foveatrack.daemon.head_pose` (link, pose, homing), :mod:`~foveatrack.daemon.watchdog`,
    :mod:`~foveatrack.daemon.record_queue` (metadata, writer queue, live view),
    :mod:`~foveatrack.daemon.operator` (the operator's pin, with ``[tracker.sky]``),
    :mod:`~foveatrack.daemon.status_display` and :mod:`~foveatrack.daemon.run_stats`.
    """

    def __new__(cls, *args, **kwargs):
        # the imports out of the collector's walks (foveatrack.startup_heap: a full collection is a
        # ~19 ms stall in a frame), before this daemon exists: a frozen daemon's cycles would never go
        freeze_startup_heap()
        return super().__new__(cls)

    def __init__(self, config: DaemonConfig, log_path: str | None = None, status: bool | None = None,
                 duration_s: float | None = None, install_signals: bool = True, live_port: int | None = None,
                 live_origins=()):
        self.cfg = config
        self.live_port = live_port      # serve the recording's channels on ws://127.0.0.1:PORT
        self.live_origins = tuple(live_origins)    # origins of web pages also let read it (--live-origin)
        self.heap_returns_freed: bool | None = None  # set by `foveatrack daemon` (foveatrack.daemon.heap)
        self.live = None
        self.control = None             # the operator's socket (foveatrack.daemon.operator), [tracker.sky] only
        self.log = JsonLog(log_path or config.loop.log)
        self.status = StatusLine(enabled=status)
        self.duration_s = duration_s
        self.install_signals = install_signals
        self.stop_ev = threading.Event()
        h = config.head
        self.limits = h.limits
        self.gate = CommandGate(self.limits)
        self.table = config.speed_table()
        self.sink = _HeadSink(self)
        # The one frame step: tracker -> gate -> serial port; a failed write leaves the head on its
        # last command and the gate tells the dead reckoning (seen without it: ~9 deg of pan while a
        # head was unplugged).  The tracker: the paper's, or with [tracker.sky] the multi-object one.
        self.step = FrameStep(daemon_controller(config, self.table), self.gate, self.sink)
        # attitude = "gyro": the lidar's IMU samples, held until the frame they precede
        self.imu_feed = ImuFeed() if config.tracker.attitude == "gyro" else None
        # ... and the same gyro witnesses every move of the head against its command (a slipping gear,
        # a wrong speed table, another head on the port stop the run: foveatrack.turn_witness)
        self.witness = MoveWitness(self.table) if self.imu_feed is not None else None
        self.slicer = FrameSlicer(config.tracker.rate_hz)
        self.counters: Counter = Counter(frames_stale=0)
        # per-frame times [ms], summarised in constant memory (a list grew ~2.3 MB an hour: issue 26)
        self.proc_ms = StreamingSummary()
        self.lat_ms = StreamingSummary()
        self.frame_id = 0
        self.last_out = None
        self._compute_s: deque = deque([0.002], maxlen=9)   # recent compute times [s]
        self._last_send_t = -math.inf
        self.recorder: RecordingThread | None = None
        self.recording_path = None
        self.epoch = 0                      # the sensor clock's epoch (foveatrack.sensor_time)
        self.pose_state: str | None = None  # None (known), "unknown", "homing" (after a head reconnect)
        self._home_policy = config.head.on_reconnect   # what an unknown pose gets (head_pose._pose_unknown)
        self._home_steps = HomingSteps()    # the writes of the homing under way
        self.last_frame_end_s: float | None = None
        self.pending: deque = deque()             # complete frames not yet processed, (frame, host arrival)
        self.frame_times: deque = deque(maxlen=50)   # host times of the last frames processed (status rate)
        self.pose_guard = PoseGuard(config)   # the head's pose against the background ([pose_check])
        self.bearings = Bearings()          # where the target was last seen: a homing goes there first
        self._homing: HomingPlan | None = None
        self._homing_confirm: HomingConfirm | None = None
        self._homing_t0: float | None = None

    @property
    def tracker(self) -> Tracker | SkyController:
        """The controller the step drives now (a fresh one after each rebase)."""
        return self.step.controller

    # -------------------------------------------------------------------------------- the loop
    def run(self) -> int:
        from foveatrack.detection import compile_all

        compile_all()   # before data flows: a first-call compile would stall the first frame
        compile_sky(self.cfg, self.table)     # and the multi-object tracker's, where it runs
        self.pose_guard.compile()
        self._open()
        with self._stop_signals():      # the handlers found come back on every way out
            try:
                self._start()
                period = 1.0 / self.cfg.tracker.rate_hz
                t_start = time.monotonic()
                next_tick = t_start + period
                self._next_status, self._next_progress = t_start, t_start + PROGRESS_PERIOD_S
                while not self.stop_ev.is_set():
                    if self.duration_s is not None and time.monotonic() - t_start >= self.duration_s:
                        break
                    if self.rx.error is not None:
                        raise self.rx.error
                    self._take_batches(max(0.0, next_tick - time.monotonic()))
                    self._process_pending()
                    self._serve_operator()      # between frames: a pin applies from the next one on
                    now = time.monotonic()
                    if now >= next_tick:
                        next_tick = self._tick(now, next_tick + period, period)
            finally:
                self._shutdown()
        return 0

    def _tick(self, now: float, next_tick: float, period: float) -> float:
        """The 10 Hz tick (also while the lidar is silent): watchdog, link events, homing, progress,
        status.  Returns the next tick's time (a late tick is counted and the clock starts again)."""
        if next_tick < now:
            self.counters["ticks_late"] += 1
            next_tick = now + period
        self._watch_lidar(now)
        self._watch_head_link(now)
        self._watch_outputs()
        if now >= self._next_progress:
            # how far the run got, in the log every second: a killed daemon's log still says so
            self._next_progress = now + PROGRESS_PERIOD_S
            self._log_progress()
        if now >= self._next_status:
            self._next_status = now + self.cfg.loop.status_period_s
            self._show_status(self.frame_times, self.watchdog.tripped, now)
        return next_tick
