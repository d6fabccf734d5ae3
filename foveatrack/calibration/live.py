"""The speed-table calibration on live devices: a Livox over UDP, the head over a serial port
(paper Appendix D.4; ``foveatrack calibrate --config DAEMON.toml --corner X Y Z``).

The devices are the daemon's (:mod:`foveatrack.daemon`): the same config file names the lidar
(``[lidar]``), the head's port, baud, address, protocol and safety limits (``[head]``), so a bench
that runs the daemon calibrates with the same file.  The procedure is the simulator's:
:class:`~foveatrack.calibration.PriorAxisCalibrator` run by :func:`~foveatrack.calibration.drive.drive_calibration`, fed
``rate_hz`` frames cut from the live stream (:class:`~foveatrack.frames.FrameSlicer`), one Pelco-D
command written per frame (a keep-alive as well as the procedure's changes).

Safety: the plan is cut to the config's limits before anything moves (speed bytes above
``max_pan_byte``/``max_tilt_byte`` and turbo unless ``allow_turbo`` are dropped, and said so); the head
is stopped when the lidar falls silent for ``[daemon] watchdog_s`` (the run then ends with an error),
on Ctrl-C / SIGTERM, on any error and at the end.  A change of command that cannot be written ends
the run too (the head would go on with the previous one while a new leg is timed).

Timing: the Calibrator stamps each command with its frame's end (sensor time); the bytes reach the
head later by the time the frame took to complete and be processed, plus one Pelco-D frame on the
wire.  The plan's ``latency_s`` (subtracted from the measured delays, so the table's dead time is
the head's own) is the wire time plus ``processing_s``; the delays actually seen (host clock, from the
frame's last point to the bytes written) are returned, so a user can check that guess.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from foveatrack.calibration import CalibrationPlan, CalibrationReport, FeatureSpec, PriorAxisCalibrator
from foveatrack.calibration.drive import drive_calibration
from foveatrack.device_config import DaemonConfig
from foveatrack.errors import UserError
from foveatrack.frames import FrameSlicer, strip_no_return
from foveatrack.gate import CommandGate
from foveatrack.live_devices import LidarStream, counters_text, open_devices
from foveatrack.speed_table import TURBO, SpeedTable


@dataclass
class LiveCalibration:
    """A finished calibration on live devices."""

    table: SpeedTable
    report: CalibrationReport
    plan: CalibrationPlan                 # as run (cut to the config's limits)
    dropped_bytes: dict                   # {axis: [bytes]} the limits removed from the plan
    frames: int
    wall_s: float
    delay_ms: list = field(default_factory=list)   # per command: frame's last point -> bytes written
    counters: dict = field(default_factory=dict)   # lidar and head link counters


def plan_within_limits(plan: CalibrationPlan, config: DaemonConfig) -> tuple[CalibrationPlan, dict]:
    """The plan without the bytes the config's ``[head]`` limits forbid, and which were removed."""
    h = config.head
    pan = tuple(b for b in plan.pan_bytes if (b == TURBO and h.allow_turbo) or (b != TURBO and b <= h.max_pan_byte))
    tilt = tuple(b for b in plan.tilt_bytes if b <= h.max_tilt_byte)
    dropped = {"pan": [b for b in plan.pan_bytes if b not in pan], "tilt": [b for b in plan.tilt_bytes if b not in tilt]}
    if not pan or not tilt:
        raise UserError(f"{config.path} [head]: max_pan_byte {h.max_pan_byte}, max_tilt_byte {h.max_tilt_byte}, "
                        f"allow_turbo {h.allow_turbo} leave no {'pan' if not pan else 'tilt'} byte of the plan "
                        f"to measure (plan: pan {list(plan.pan_bytes)}, tilt {list(plan.tilt_bytes)})")
    return replace(plan, pan_bytes=pan, tilt_bytes=tilt), {k: v for k, v in dropped.items() if v}


def calibrate_live(config: DaemonConfig, plan: CalibrationPlan, feature: FeatureSpec, *, rate_hz: float = 20.0,
                   processing_s: float = 0.005, seed: int = 0, start_tilt_sigma_deg: float = 0.5,
                   max_s: float | None = None, stop: threading.Event | None = None, progress=None,
                   date: str | None = None, first_data_s: float = 10.0) -> LiveCalibration:
    """Calibrate the head named by ``config`` against its lidar (see the module docstring).

    plan : bytes and timing (``start_tilt_deg`` is taken from ``[head] tilt0_deg``, ``latency_s``
        from the wire time + ``processing_s``)
    feature : the room corner, where it is in the lidar frame at the start (within ``radius_m``)
    rate_hz : frame rate of the procedure (20 Hz: 50 ms frames keep a corner sharp at full pan speed)
    max_s : wall-time budget [s] (None: no limit); stop : set it to end the run early (the head
        is stopped; UserError "interrupted")
    progress : ``progress(frames, legs_done, legs_total)`` after each frame
    first_data_s : how long to wait for the lidar's first packet [s]

    Raises UserError when the lidar never sends or falls silent, the calibration fails, runs out of
    time or is interrupted; the head is stopped in every case.
    """
    h, L = config.head, config.lidar
    plan, dropped = plan_within_limits(plan, config)
    plan = replace(plan, start_tilt_deg=h.tilt0_deg, latency_s=h.frame_time_s + processing_s)
    cal = PriorAxisCalibrator(plan, feature, seed=seed, date=date, start_tilt_sigma_deg=start_tilt_sigma_deg,
                              head=f"Pelco-{h.protocol} head, address {h.address} on {h.port}")
    legs_total = len(plan.pan_bytes) * 2 + len(plan.tilt_bytes) * 2
    head, client = open_devices(config)     # as the daemon opens them, with the same messages
    stream = LidarStream(client)            # last packet (watchdog) and host - sensor clock offset
    t_start = time.monotonic()
    run = {"frames": 0, "written": None, "last_point_s": None}   # frames fed, the head's last command
    delay_ms: list[float] = []

    def frames():
        """The live frame source: frames cut from the stream, with the run's checks between polls."""
        slicer = FrameSlicer(rate_hz)
        while True:
            now = time.monotonic()
            if stop is not None and stop.is_set():
                raise UserError(f"calibration interrupted after {run['frames']} frames ({_legs(cal)} legs done); "
                                "the head was stopped and no table was written")
            if max_s is not None and now - t_start > max_s:
                raise UserError(f"the calibration did not finish within {max_s:g} s ({_legs(cal)} of "
                                f"{legs_total} legs done); the head was stopped and no table was written")
            # Watchdog: the procedure cannot see the head move without the lidar (and a head left
            # turning would run into its stops), so silence ends the run.
            silent_s = stream.silent_s(now)
            if silent_s is None and now - t_start > first_data_s:
                raise UserError(f"no data from the lidar {L.sensor_ip} within {first_data_s:g} s (is it on, "
                                f"and is [lidar] host_ip {L.host_ip} this machine's address on its network?); "
                                f"the head was stopped and no table was written (lidar counters: {counters_text(client.counters)})")
            if silent_s is not None and silent_s > config.loop.watchdog_s:
                raise UserError(f"the lidar fell silent for {silent_s:.1f} s ([daemon] watchdog_s "
                                f"{config.loop.watchdog_s:g}) after {run['frames']} frames; the head was stopped "
                                f"and no table was written (link {client.state}, unit {client.unit_status()}, "
                                f"lidar counters: {counters_text(client.counters)})")
            _, batches = stream.poll(0.02)
            for b in batches:
                if b.epoch != 0:
                    # the procedure times legs on the sensor clock: a restarted or jumped clock mid-run
                    # would mis-time the leg under way (the daemon re-anchors; a table must not)
                    raise UserError(f"the lidar's clock restarted or jumped after {run['frames']} frames "
                                    f"({_legs(cal)} legs done; lidar counters: {counters_text(stream.counters)}); the head "
                                    "was stopped and no table was written: start the calibration again")
                if len(b):
                    for frame in slicer.push(b.xyz, b.t_ns, b.reflectivity):
                        frame = strip_no_return(frame)
                        run["frames"] += 1
                        run["last_point_s"] = frame.t_ns[-1] * 1e-9 if frame.n_points else None
                        yield frame

    def send(t_s, cmd) -> bool:
        """The command sink: the head's serial link, one Pelco frame per frame (a keep-alive too)."""
        _, ok = head.send(cmd)
        if not ok and cmd != run["written"]:
            # A keep-alive that did not get through changes nothing; a change of command that did
            # not, leaves the head doing the last one while the procedure times a new leg: its
            # measurements would be wrong.
            raise UserError(f"the head's serial link ({config.named_head_port()}) failed when the calibration "
                            f"changed its command ({_legs(cal)} legs done); the head was stopped if it "
                            "could be reached and no table was written")
        run["written"] = cmd
        if run["last_point_s"] is not None and stream.offset_s is not None:
            delay_ms.append((time.monotonic() - (run["last_point_s"] + stream.offset_s)) * 1e3)
        if progress is not None:
            progress(run["frames"], _legs(cal), legs_total)
        return ok

    try:
        head.stop()
        client.start_sampling()
        # the procedure the simulator runs, on the live devices, through the daemon's command gate
        drive_calibration(cal, frames(), send, gate=CommandGate(h.limits))
        table = cal.result()
    finally:
        head.stop()
        # the clock guard's counts beside the client's: points dropped as wrong times show here
        counters = {"lidar": {**client.counters, **stream.counters}, "head": head.stats_dict()}
        client.close()
        head.close()
    return LiveCalibration(table, cal.report, plan, dropped, run["frames"], time.monotonic() - t_start, delay_ms,
                           counters)


def _legs(cal) -> int:
    return sum(1 for leg in cal.legs if leg.t_stop_s is not None)


def delay_summary_ms(delay_ms: list[float]) -> tuple[float, float] | None:
    """(median, 95th percentile) of the command delays [ms], or None without any."""
    if not delay_ms:
        return None
    d = np.asarray(delay_ms)
    return float(np.median(d)), float(np.percentile(d, 95))

