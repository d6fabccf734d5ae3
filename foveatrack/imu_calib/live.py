"""The lidar-IMU calibration of paper Section IV.A on a live rig: a Livox with an IMU (Horizon, Avia,
Tele-15: data type 6 at 200 Hz) on the pan/tilt head of the daemon's config
(``foveatrack calibrate-imu --config DAEMON.toml``).

The devices are the daemon's, opened by :mod:`foveatrack.live_devices` (the same messages for a
wrong port or address, the same clock guard on the point times).  The procedure is the simulator's:
this module only gathers its input -- one cloud per static pose, the IMU samples, the static windows
-- and hands it to :func:`foveatrack.imu_calib.procedure.calibrate`.

Poses: the head is stepped by Pelco-D speed commands through a cycle of pan/tilt offsets from its
start pose (``RigPlan``: pan, tilt and both together, each step ``step_deg``), timed from the
config's speed table; where each pose really is does not matter (the lidar's registration and the
IMU measure each motion), only that the rig is still during each window.  With ``by_hand`` the head
is not opened: the user moves the rig and presses Enter at each pose.

Timing: after the head's STOP (or the user's Enter) at host time ``h``, the pose's window is
``[s(h) + settle_s, s(h) + settle_s + dwell_s]`` on the lidar's clock (``s``: the host -> sensor time
of :class:`~foveatrack.live_devices.LidarStream`); its points are the pose's cloud, and the next move
starts once points and IMU samples past the window's end have arrived.  The IMU is read all the time,
so each move between windows is integrated whole; a gap in its samples is an error.

What two head axes can and cannot calibrate (docs/imu-calibration.md "The real rig"): the head turns
the rig about its pan axis (vertical) and its tilt axis (horizontal, fixed in the lidar frame); two
non-parallel rotation axes determine the rotation ``R_X`` and, through ``(R_A - I) t_X = R_X t_B - t_A``
over pairs with both axes, all three components of ``t_X``.  A plan about one axis only is refused
before anything moves (the translation along that axis would be unobservable; the hand-eye solver
refuses it too, :class:`~foveatrack.imu_calib.handeye.DegenerateMotion`).  ``t_X`` is measured only
through the IMU's own displacement on its arc about the head's centre (``|t_X| theta``: 1.2 cm for a
7 cm lever and 10 deg), double-integrated over each move, so its accuracy is the accelerometer's
over a move, divided by the step angle; and gravity turns only with tilt (pan is about gravity).

Safety: the plan is checked against ``[head] tilt_limits_deg`` (with ``tilt_margin_deg``) and the
speed bytes against ``max_pan_byte``/``max_tilt_byte`` before anything moves; every command also
passes the daemon's command gate (:class:`foveatrack.gate.CommandGate`, the ``[head]`` limits) with
the dead-reckoned tilt and its uncertainty (the table's sigma over each move); a move it changes ends
the run.  The head is
stopped when the lidar falls silent for ``[daemon] watchdog_s``, on Ctrl-C / SIGTERM (``stop``), on
any error and at the end (after driving back to the start pose when the run completes).  The lidar's
gyro witnesses every move (:class:`foveatrack.turn_witness.TurnWitness`): a head that turns far more
than commanded stops the run while it moves (before it can reach a stop the dead reckoning does not
see coming), and one that turned far less, once it has stopped; the error names the axis and both turns.
"""

from __future__ import annotations

import math
import queue
import sys
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from foveatrack.control import STOP, HeadCommand
from foveatrack.errors import UserError
from foveatrack.frame_step import FrameStep
from foveatrack.gate import CommandGate, Proposal
from foveatrack.imu_calib import handeye, procedure, registration
from foveatrack.imu_calib.imu_integration import GRAVITY_M_S2, ImuSamples
from foveatrack.imu_calib.se3 import so3_log
from foveatrack.live_devices import counters_text
from foveatrack.turn_witness import TurnMismatch, TurnWitness

#: A window is static when no 0.25 s block of its gyro readings has a mean farther than this from the
#: window's mean [deg/s] (BMI088 white noise: 0.2 deg/s per 200 Hz sample, 0.03 deg/s per block mean).
STATIC_BLOCK_S = 0.25
STATIC_TOL_DEG_S = 0.3
#: Largest gap in the IMU's sample times [s] accepted (200 Hz: 5 ms; a lost packet is 5 ms).
IMU_MAX_GAP_S = 0.05
KEEPALIVE_S = 0.1          # the current command is written again this often during a move


@dataclass(frozen=True)
class RigPlan:
    """The static poses: offsets (pan, tilt) [deg] from the start pose, cycling through
    ``(0, 0), (s, 0), (s, s), (0, s), (-s, 0), (-s, s)`` for ``s = step_deg`` (tilt steps
    ``tilt_step_deg``, default the same): moves of pan alone, tilt alone and both together, in both
    senses, so the rotation axes spread (pan's axis and tilt's are at right angles).

    poses : int >= 3; dwell_s : accumulation per pose [s]; settle_s : wait after the STOP (or the
    Enter) before the window opens [s]; speed_deg_s : target speed of each axis while moving.
    """

    poses: int = 25
    step_deg: float = 10.0
    tilt_step_deg: float | None = None
    dwell_s: float = 10.0
    settle_s: float = 1.0
    speed_deg_s: float = 10.0

    def __post_init__(self) -> None:
        if self.poses < 3:
            raise UserError(f"--poses {self.poses}: the calibration needs at least 3 static poses (2 pairs)")
        for name in ("dwell_s", "speed_deg_s"):
            if not getattr(self, name) > 0:
                raise UserError(f"{name.replace('_', '-')} must be > 0, got {getattr(self, name)}")
        if not self.settle_s >= 0:
            raise UserError(f"settle-s must be >= 0, got {self.settle_s}")
        if not 0 <= self.step_deg <= 45 or not 0 <= self.tilt_step <= 45:
            raise UserError(f"--step-deg must be within 0-45 deg, got pan {self.step_deg}, tilt {self.tilt_step}")

    @property
    def tilt_step(self) -> float:
        return self.step_deg if self.tilt_step_deg is None else self.tilt_step_deg

    def offsets_deg(self) -> list[tuple[float, float]]:
        s, u = self.step_deg, self.tilt_step
        cycle = [(0.0, 0.0), (s, 0.0), (s, u), (0.0, u), (-s, 0.0), (-s, u)]
        return [cycle[i % len(cycle)] for i in range(self.poses)]

    def check_axes(self) -> None:
        """Refuse a plan that turns about one head axis only (see the module docstring)."""
        off = np.array(self.offsets_deg())
        moves = np.diff(off, axis=0)
        pans = np.any(moves[:, 0] != 0)
        tilts = np.any(moves[:, 1] != 0)
        if not (pans or tilts):
            raise handeye.DegenerateMotion("the pose plan does not turn the head (pan and tilt steps 0 deg)")
        if not (pans and tilts):
            axis = "pan" if pans else "tilt"
            raise handeye.DegenerateMotion(
                f"the pose plan turns the head about its {axis} axis only (pan step {self.step_deg:g} deg, tilt step "
                f"{self.tilt_step:g} deg): with one rotation axis the translation along it cannot be found; "
                "give both a pan and a tilt step")


@dataclass(frozen=True)
class AxisMove:
    direction: int     # -1, 0, +1 (HeadCommand convention: pan +1 = left, tilt +1 = up)
    byte: int
    duration_s: float
    speed_deg_s: float


def axis_move(table, axis: str, delta_deg: float, speed_deg_s: float, max_byte: int) -> AxisMove:
    """The speed byte and time that turn ``axis`` by ``delta_deg`` at about ``speed_deg_s``, from the
    config's speed table and not above ``max_byte``."""
    if delta_deg == 0:
        return AxisMove(0, 0, 0.0, 0.0)
    tab = table.axis(axis)
    byte = tab.byte_for_speed(speed_deg_s)
    if byte > max_byte:
        byte = max_byte
    v = tab.speed_deg_s(byte)
    if not v > 0:
        raise UserError(f"[head] max_{axis}_byte {max_byte}: the speed table gives {axis} byte {byte} no speed; "
                        "the head cannot be stepped through the poses")
    return AxisMove(1 if delta_deg > 0 else -1, byte, abs(delta_deg) / v, v)


@dataclass
class LiveImuCalibration:
    result: procedure.CalibrationResult
    windows_s: list            # static windows, sensor time relative to the first window's start [s]
    points_per_pose: list
    static_spread_deg_s: list  # per pose: largest 0.25 s gyro block mean off the window mean [deg/s]
    imu_samples: int
    wall_s: float
    by_hand: bool
    translation_singular_values: np.ndarray   # of the stacked (R_A - I): how well t_X is pinned [rad]
    weakest_translation_direction: np.ndarray
    counters: dict = field(default_factory=dict)
    turned_deg: list = field(default_factory=list)    # per pair: the rotation the lidar registered [deg]
    planned_deg: list = field(default_factory=list)   # per pair: the plan's (dead-reckoned; head mode)

    def short_turns(self) -> list[int]:
        """Pairs that turned less than half as far as planned (the speed table is off: the IMU's
        error over a small turn tilts the rotation axis, so X suffers)."""
        return [i for i, (t, p) in enumerate(zip(self.turned_deg, self.planned_deg)) if t < 0.5 * p]


def translation_observability(A: list, free=None) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (descending) of the stacked ``R_Ai - I`` of the hand-eye translation step and
    the direction of the smallest: ``t_X`` along it is pinned by ``sigma_min`` (about the rotation
    angle [rad] about a perpendicular axis; 0 = unobservable).  ``free``: per pair the directions its
    registration did not measure (their rows do not count, :func:`.handeye.measured_part`)."""
    C = np.vstack([handeye.measured_part(None if free is None else free[i]) @ (a[:3, :3] - np.eye(3))
                   for i, a in enumerate(A)])
    _, s, vt = np.linalg.svd(C)
    return s, vt[-1]


class _Answers:
    """Lines typed by the user (by-hand mode), read by a thread so the lidar keeps being polled."""

    def __init__(self, stream):
        self.q: queue.Queue = queue.Queue()
        t = threading.Thread(target=self._read, args=(stream,), daemon=True)
        t.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.q.put(line)
        self.q.put(None)

    def get(self, timeout_s: float):
        """A line, None at end of input, or False when nothing came within ``timeout_s``."""
        try:
            return self.q.get(timeout=timeout_s)
        except queue.Empty:
            return False


class _Rig:
    """The live stream while the calibration runs: points into the current window, every IMU sample,
    and the run's checks (Ctrl-C, time budget, lidar silence, clock restarts) at every poll."""

    def __init__(self, config, client, stream, stop, max_s, first_data_s, stride: int):
        self.config, self.client, self.stream = config, client, stream
        self.stop, self.max_s, self.first_data_s = stop, max_s, first_data_s
        self.t_start = time.monotonic()
        self.stride = stride
        self.imu: list = []
        self.window: tuple[float, float] | None = None   # sensor time [s]
        self.xyz: list = []
        self.t: list = []
        self.seen = 0
        self.latest_point_s: float | None = None
        self.latest_imu_s: float | None = None
        self.pose = 0
        self.drives_head = True

    def _fail(self, what: str):
        raise UserError(f"{what}; {'the head was stopped and ' if self.drives_head else ''}no extrinsic was written")

    def poll(self, timeout_s: float) -> None:
        now = time.monotonic()
        L, s = self.config.lidar, self.stream
        if self.stop is not None and self.stop.is_set():
            self._fail(f"calibration interrupted at pose {self.pose + 1}")
        if self.max_s is not None and now - self.t_start > self.max_s:
            self._fail(f"the calibration did not finish within {self.max_s:g} s (at pose {self.pose + 1})")
        silent = s.silent_s(now)
        if silent is None and now - self.t_start > self.first_data_s:
            self._fail(f"no data from the lidar {L.sensor_ip} within {self.first_data_s:g} s (is it on, and is "
                       f"[lidar] host_ip {L.host_ip} this machine's address on its network?) (lidar counters: "
                       f"{counters_text(self.client.counters)})")
        if silent is not None and silent > self.config.loop.watchdog_s:
            self._fail(f"the lidar fell silent for {silent:.1f} s ([daemon] watchdog_s {self.config.loop.watchdog_s:g}) "
                       f"at pose {self.pose + 1} (link {self.client.state}, lidar counters: {counters_text(self.client.counters)})")
        _, batches = s.poll(timeout_s)
        for b in batches:
            if b.epoch != 0:
                # windows and IMU moves are timed on the sensor clock: a restarted clock breaks both
                self._fail(f"the lidar's clock restarted or jumped at pose {self.pose + 1} (lidar counters: "
                           f"{counters_text(s.counters)}): start the calibration again")
            if not len(b):
                continue
            t_s = b.t_ns * 1e-9
            self.latest_point_s = float(t_s[-1]) if self.latest_point_s is None else max(self.latest_point_s, float(t_s[-1]))
            if self.window is None:
                continue
            m = (t_s >= self.window[0]) & (t_s < self.window[1]) & np.any(b.xyz != 0.0, axis=1)
            idx = np.flatnonzero(m)
            # a fixed stride over the window's points in arrival order (the registration's cost cap)
            keep = idx[(self.seen + np.arange(len(idx))) % self.stride == 0]
            self.seen += len(idx)
            if len(keep):
                self.xyz.append(np.asarray(b.xyz[keep], float))
                self.t.append(t_s[keep])
        imu = self.client.take_imu()
        if len(imu):
            self.imu.append(imu)
            t_last = float(imu.t_ns.max()) * 1e-9
            self.latest_imu_s = t_last if self.latest_imu_s is None else max(self.latest_imu_s, t_last)

    def wait_host(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.poll(min(0.02, max(0.0, end - time.monotonic())))

    def wait_first_data(self) -> None:
        while self.stream.offset_s is None or self.latest_imu_s is None:
            self.poll(0.02)
            if (self.stream.offset_s is not None and self.latest_imu_s is None
                    and time.monotonic() - self.t_start > self.first_data_s):
                self._fail(f"the lidar {self.config.lidar.sensor_ip} sends points but no IMU samples (data type 6) "
                           f"within {self.first_data_s:g} s: a Horizon, Avia or Tele-15 streams its IMU at 200 Hz "
                           "(a Mid-40 / Mid-70 has none)")

    def take_window(self, t0_s: float, t1_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Points of ``[t0_s, t1_s)`` (sensor time), once points past it have come.  The IMU samples
        of the window may still be on their way: the next move starts at once (the IMU's error
        over a move grows with the time between windows, ~T^1.5), and :meth:`wait_imu` waits for
        them at the end."""
        self.window, self.xyz, self.t, self.seen = (t0_s, t1_s), [], [], 0
        while self.latest_point_s is None or self.latest_point_s < t1_s:
            self.poll(0.02)
        self.window = None
        if not self.xyz:
            return np.zeros((0, 3)), np.zeros(0)
        return np.vstack(self.xyz), np.concatenate(self.t)

    def wait_imu(self, t_s: float) -> None:
        while self.latest_imu_s is None or self.latest_imu_s < t_s:
            self.poll(0.02)

    def imu_between(self, t0_s: float, t1_s: float, since: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU samples of ``[t0_s, t1_s)`` (sensor time) among the batches from index ``since`` on:
        (t_s, gyro rad/s, acc g), in arrival order."""
        bs = self.imu[since:]
        if not bs:
            return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
        t = np.concatenate([b.t_ns for b in bs]) * 1e-9
        m = (t >= t0_s) & (t < t1_s)
        return t[m], np.vstack([b.gyro_rad_s for b in bs])[m], np.vstack([b.acc_g for b in bs])[m]

    def imu_samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every IMU sample so far, in time order, duplicates removed: (t_ns, gyro rad/s, acc g)."""
        t = np.concatenate([b.t_ns for b in self.imu])
        g = np.vstack([b.gyro_rad_s for b in self.imu])
        a = np.vstack([b.acc_g for b in self.imu])
        t, first = np.unique(t, return_index=True)
        return t, g[first], a[first]


def static_spread_deg_s(t_s: np.ndarray, gyro_rad_s: np.ndarray, t0: float, t1: float) -> float:
    """Largest distance [deg/s] of a :data:`STATIC_BLOCK_S` block mean of the gyro from the window's mean."""
    m = (t_s >= t0) & (t_s < t1)
    g = np.degrees(gyro_rad_s[m])
    if len(g) < 10:
        return float("nan")
    blk = max(1, int(round(STATIC_BLOCK_S / np.median(np.diff(t_s[m])))))
    nb = len(g) // blk
    if nb < 1:
        return 0.0
    means = g[: nb * blk].reshape(nb, blk, 3).mean(axis=1)
    return float(np.max(np.abs(means - g.mean(axis=0))))


class _SerialSink:
    """The head's serial link as a command sink (:class:`foveatrack.live_devices.HeadLink`)."""

    def __init__(self, head):
        self.head = head

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        return self.head.send(cmd)[1]


class _HeadDrive:
    """The head's side of the run: each move's commands through the daemon's command gate (with the
    dead-reckoned tilt and its uncertainty: the table's sigma over each move, summed in quadrature),
    keep-alives, and the gyro's witness of every turn (:class:`foveatrack.turn_witness.TurnWitness`:
    a head turning far more than commanded stops the run while it moves, one that turned far less
    once it has stopped)."""

    def __init__(self, config, head, rig: "_Rig", table, X0):
        self.config, self.head, self.rig, self.table = config, head, rig, table
        self.tilt_deg = config.head.tilt0_deg
        self.tilt_var = 0.0                     # [deg^2]
        # The one frame step (foveatrack.frame_step) with this object as its controller: each move's
        # command is proposed by time (no frames), through the daemon's gate, to the serial port; a
        # command the gate changes is replaced by STOP and ends the run (send).
        self.gate = CommandGate(config.head.limits)
        self.step = FrameStep(self, self.gate, _SerialSink(head), source="imu_calibration", stop_on_change=True)
        self._proposed: HeadCommand = STOP
        self.witness = TurnWitness(None if X0 is None else X0[:3, :3])
        self.fed = 0                            # IMU batches given to the witness

    def process(self, frame, send_t_s: float) -> Proposal:
        """The controller's side of the step: the move's command and the dead-reckoned tilt."""
        return Proposal(self._proposed, self.tilt_deg, math.sqrt(self.tilt_var))

    def command_sent(self, t_s: float, cmd: HeadCommand) -> None:
        """The gate changed a command or a write failed: :meth:`send` ends the run on either (a keep-alive
        lost changes nothing), so the moves' dead reckoning has nothing to take from it."""

    def send(self, cmd: HeadCommand, last: HeadCommand | None) -> None:
        self._proposed = cmd
        rec = self.step(None, time.monotonic())
        if rec.limited:
            self.rig._fail(f"the [head] limits of {self.config.path} stopped a planned move ({', '.join(rec.limited)}) at "
                           f"dead-reckoned tilt {self.tilt_deg:.1f} +- {math.sqrt(self.tilt_var):.1f} deg")
        if not rec.reached_head and cmd != last:
            self.rig._fail(f"the head's serial link ({self.config.named_head_port()}) failed when a move changed "
                           f"its command (pose {self.rig.pose + 1})")

    def _witness(self, pan: AxisMove, tilt: AxisMove, el_s: float) -> None:
        """The gyro's turn against the commanded one ``el_s`` seconds into the move (inf: the head has
        stopped, judged both ways)."""
        t, g, _ = self.rig.imu_between(-np.inf, np.inf, since=self.fed)
        self.fed = len(self.rig.imu)
        self.witness.add(t, g)
        commanded = {ax: m.direction * m.speed_deg_s * min(el_s, m.duration_s) for ax, m in (("pan", pan), ("tilt", tilt))}
        try:
            self.witness.check(commanded, stopped=el_s == math.inf)
        except TurnMismatch as exc:
            self.rig._fail(f"pose {self.rig.pose + 1}: {exc}")

    def move(self, pan: AxisMove, tilt: AxisMove, still: tuple[float, float]) -> None:
        """Run one move (both axes at once, each for its own time), then STOP; ``still``: the sensor-time
        window the head last stood still through (the witness's gyro bias and up direction)."""
        rig = self.rig
        rig.wait_imu(still[1])
        self.witness.begin(*rig.imu_between(*still))
        self.fed = len(rig.imu)
        self.witness.add(*rig.imu_between(still[1], np.inf)[:2])
        t0 = time.monotonic()
        dur = max(pan.duration_s, tilt.duration_s)
        tilt_start = self.tilt_deg
        last, last_t = None, 0.0
        while True:
            el = time.monotonic() - t0
            self._witness(pan, tilt, el)
            if el >= dur:
                break
            cmd = HeadCommand(pan.direction if el < pan.duration_s else 0, pan.byte if el < pan.duration_s else 0,
                              tilt.direction if el < tilt.duration_s else 0, tilt.byte if el < tilt.duration_s else 0)
            self.tilt_deg = tilt_start + tilt.direction * tilt.speed_deg_s * min(el, tilt.duration_s)
            if cmd != last or time.monotonic() - last_t >= KEEPALIVE_S:
                self.send(cmd, last)
                last, last_t = cmd, time.monotonic()
            rig.poll(min(0.01, max(0.0, dur - el)))
        self.send(STOP, last)
        self.tilt_deg = tilt_start + tilt.direction * tilt.speed_deg_s * tilt.duration_s
        if tilt.direction:
            self.tilt_var += (self.table.axis("tilt").sigma_deg_s(tilt.byte) * tilt.duration_s) ** 2

    def check_stopped(self, pan: AxisMove, tilt: AxisMove, t_still_s: float) -> None:
        """After a move, once the head has stood still until sensor time ``t_still_s``: the whole turn."""
        self.rig.wait_imu(t_still_s)
        self._witness(pan, tilt, math.inf)


def calibrate_rig(config, plan: RigPlan, *, by_hand: bool = False, answers=None, prompt_out=None,
                  X0: np.ndarray | None = None, bootstrap_samples: int = 200, seed: int = 0,
                  max_s: float | None = None, stop: threading.Event | None = None, progress=None,
                  first_data_s: float = 10.0, return_home: bool = True) -> LiveImuCalibration:
    """Run the poses of ``plan`` on the rig of ``config`` and solve the extrinsic (module docstring).

    by_hand : do not open the head; prompt (``prompt_out``, default stderr) and wait for a line on
        ``answers`` (default stdin) at each pose
    X0 : nominal ``T_lidar_imu`` seeding the registration (default identity: the IMU's axes the
        lidar's, as Livox mounts it)
    progress : ``progress(pose_index_done, poses)`` after each pose
    Raises UserError (the head stopped) on any failure, DegenerateMotion for a plan or motion that
    cannot determine the extrinsic.
    """
    from foveatrack.live_devices import LidarStream, open_devices, open_lidar

    plan.check_axes()
    h = config.head
    offsets = plan.offsets_deg()
    moves, table = [], None
    if not by_hand:
        table = config.speed_table()
        lo, hi = h.tilt_limits_deg
        tilts = [h.tilt0_deg + o[1] for o in offsets]
        if min(tilts) < lo + h.tilt_margin_deg or max(tilts) > hi - h.tilt_margin_deg:
            raise UserError(f"{config.path} [head]: the poses reach tilt {min(tilts):g} to {max(tilts):g} deg from "
                            f"tilt0_deg {h.tilt0_deg:g}, beyond tilt_limits_deg {list(h.tilt_limits_deg)} less "
                            f"tilt_margin_deg {h.tilt_margin_deg:g}; start the head lower/higher or give a smaller step")
        steps = [(b[0] - a[0], b[1] - a[1]) for a, b in zip(offsets, offsets[1:])]
        for dp, dt in steps + [(-offsets[-1][0], -offsets[-1][1])]:
            moves.append((axis_move(table, "pan", dp, plan.speed_deg_s, h.max_pan_byte),
                          axis_move(table, "tilt", dt, plan.speed_deg_s, h.max_tilt_byte)))
    L = config.lidar
    rate = L.point_rate_hz or 240_000.0
    stride = max(1, -(-int(rate * plan.dwell_s) // registration.MAX_PLANE_POINTS))
    if by_hand:
        head, client = None, open_lidar(config)
    else:
        head, client = open_devices(config)
    stream = LidarStream(client)
    rig = _Rig(config, client, stream, stop, max_s, first_data_s, stride)
    rig.drives_head = head is not None
    out = prompt_out or sys.stderr
    inbox = _Answers(answers if answers is not None else sys.stdin) if by_hand else None
    windows, clouds = [], []
    drive = None if by_hand else _HeadDrive(config, head, rig, table, X0)
    t_wall0 = time.monotonic()
    try:
        if head is not None:
            head.stop()
        client.start_sampling()
        rig.wait_first_data()
        for i in range(plan.poses):
            rig.pose = i
            if by_hand:
                what = ("hold the rig still where it is" if i == 0 else
                        "turn the rig about 10 deg (about a different axis than last time), hold it still")
                print(f"pose {i + 1}/{plan.poses}: {what} and press Enter", file=out, flush=True)
                while True:
                    line = inbox.get(0.0)
                    if line is None:
                        rig._fail(f"the input ended before pose {i + 1} of {plan.poses} (--by-hand waits for Enter "
                                  "at each pose)")
                    if line is not False:
                        break
                    rig.poll(0.02)
            elif i > 0:
                drive.move(*moves[i - 1], windows[-1])
            h_still = time.monotonic()
            s0 = stream.sensor_now_s(h_still) + plan.settle_s
            xyz, t_s = rig.take_window(s0, s0 + plan.dwell_s)
            if not by_hand and i > 0:
                drive.check_stopped(*moves[i - 1], s0)
            windows.append((s0, s0 + plan.dwell_s))
            clouds.append((xyz, t_s))
            if by_hand:
                print(f"pose {i + 1}/{plan.poses}: {len(xyz)} points kept; done", file=out, flush=True)
            if progress is not None:
                progress(i + 1, plan.poses)
        rig.wait_imu(windows[-1][1])
        if head is not None and return_home:
            drive.move(*moves[-1], windows[-1])
    finally:
        if head is not None:
            head.stop()
        counters = {"lidar": {**client.counters, **stream.counters}}
        if head is not None:
            counters["head"] = head.stats_dict()
        client.close()
        if head is not None:
            head.close()
    t_ns, gyro, acc = rig.imu_samples()
    t_ref = windows[0][0]
    t_imu = t_ns * 1e-9 - t_ref
    win = [(a - t_ref, b - t_ref) for a, b in windows]
    span = (t_imu >= win[0][0] - 0.05) & (t_imu <= win[-1][1] + 0.05)
    gaps = np.diff(t_imu[span])
    if not len(gaps) or gaps.max() > IMU_MAX_GAP_S:
        worst = float(gaps.max()) if len(gaps) else float("nan")
        raise UserError(f"the IMU samples have a gap of {worst * 1e3:.0f} ms between the first and last pose (more "
                        f"than {IMU_MAX_GAP_S * 1e3:.0f} ms: lost packets); a move cannot be integrated across it, so "
                        "no extrinsic was written: run again (lidar counters: " + counters_text(counters["lidar"]) + ")")
    spreads = [static_spread_deg_s(t_imu, gyro, a, b) for a, b in win]
    for i, sp in enumerate(spreads):
        if not sp <= STATIC_TOL_DEG_S:
            raise UserError(f"pose {i + 1}: the rig was not still during its window (gyro block means up to "
                            f"{sp:.2f} deg/s off their mean, > {STATIC_TOL_DEG_S:g}): give it longer to settle "
                            "(--settle-s) and hold it still; no extrinsic was written")
    pose_clouds = [procedure.PoseCloud(xyz, t - t_ref, a) for (xyz, t), (a, _) in zip(clouds, win)]
    imu = ImuSamples(t_imu, gyro, acc * GRAVITY_M_S2)
    res = procedure.calibrate(pose_clouds, imu, win, plan.dwell_s, X0=X0, bootstrap_samples=bootstrap_samples,
                              seed=seed)
    planned = [float(np.hypot(b[0] - a[0], b[1] - a[1])) for a, b in zip(offsets, offsets[1:])]
    turned = [float(np.degrees(np.linalg.norm(so3_log(a[:3, :3])))) for a in res.A]
    s, weak = translation_observability(res.A, [r.free_directions for r in res.registrations])
    return LiveImuCalibration(res, win, [len(c[0]) for c in clouds], spreads, len(t_ns), time.monotonic() - t_wall0,
                              by_hand, s, weak, counters, turned, [] if by_hand else planned)
