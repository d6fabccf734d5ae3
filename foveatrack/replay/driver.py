"""Replay: re-run detection and control offline over recorded point frames (deterministic).

One tracker object for every driver (DESIGN.md): :func:`replay_recording` pushes the recorded frames
of a simulator or daemon recording (:mod:`foveatrack.recording`) through a fresh
:class:`foveatrack.tracker.Tracker` with the recorded configuration -- or another one -- and the
recorded send times, so with the recorded configuration the detections and commands come out
identical (to the bit) to the recorded ones.  :func:`replay_lvx` runs the tracker over a Livox Viewer
``.lvx`` file (lidar only: the head is taken as frozen, so the commands are what the tracker *would*
have sent, through the command gate a daemon runs).

How a recording's tracker is rebuilt (``meta``):

Both drivers record the configuration that ran, typed (:class:`foveatrack.recording.run_meta.RecordingMeta`:
every tracker setting with the head's facts applied, the speed table, the gate's limits); replay
rebuilds its tracker from that (recordings of the earlier form, with the raw ``[tracker]`` table, by
:func:`foveatrack.recording.run_meta.from_legacy_dict`).

* simulator (``sim.recorder.recording_meta``): frame ``k`` is ``[k, k+1) / rate_hz`` and its command
  was written at ``t_end + send_delay_s``.
* daemon (:mod:`foveatrack.daemon.runtime`): frames end
  at the recorded ``t_ns``; the send time is the command's ``send_t_s``; commands the safety gate
  limited, and the watchdog's and shutdown's STOPs, are registered where they happened; a command
  whose write failed (``written: false``) is replaced, at the same instant, by the last one that
  reached the head (the head never saw it, and kept moving as it was told before); where the daemon
  started a fresh tracker (``tracker_rebased``: a new lidar clock, the head homed), so does replay.

A tracker whose attitude comes from the gyro (``attitude = "gyro"``) gets the IMU samples the run's
tracker got (``/imu``), each frame's before that frame, as the driver fed them; a recording made
before the channel existed has none, and its replay dead-reckons the commands (the comparison's
``gyro_samples_recorded`` is then False and the report says so).

Replay is open loop: the points are what the lidar saw while the head moved as it did, so a
different configuration shows which detections and commands would have differed on the same data,
not where the head would have gone.  Its dead reckoning follows the head as it moved: where the
replayed tracker's command differs from the recorded one, the head is taken to have run the recorded
one (:class:`_RecordedOutcome`), so the points are placed in the world where they were seen.

A damaged recording (:class:`foveatrack.recording.Damage`) is replayed from everything the reader
recovered; the report's first line after the title is a WARNING naming what was skipped.  Frames
lost in the middle take their commands with them, so the replay's dead reckoning after the gap
lacks those commands: the comparison then says it is *partial* (``comparison["partial"]``,
``gaps`` with the head-estimate offset after each, ``before_first_gap`` exact as before).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from foveatrack.control import HeadCommand
from foveatrack.errors import UserError
from foveatrack.frame_step import FrameStep, NoHead
from foveatrack.frames import Frame
from foveatrack.gate import CommandGate, Limits
from foveatrack.recording.format import MCAP_MAGIC
from foveatrack.recording.records import CommandRecord
from foveatrack.recording.run_meta import RecordingMeta
from foveatrack.replay.config import load_tracker_table, tracker_config
from foveatrack.replay.metrics import recorded_metrics, compare, replay_metrics
from foveatrack.replay.recorded import (RECORDED_DTYPES, TRUTH_DTYPES, FrameArrays, LvxTimeline, TimeOrder,
                                        PoseCorrected, TrackerRebased, TrackPinned, recorded_arrays, recorded_frames)
from foveatrack.recording.records import TracksRecord, ns
from foveatrack.replay.result import ReplayResult
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import Tracker, TrackerConfig


def require_space(cfg: TrackerConfig, where: str) -> None:
    """A configuration given for replay must name its space of interest D: without one Algorithm 1
    takes every point, the ground too (an LVX replay "detected" it in 300 of 300 frames, bearing rms
    10.9 deg, reconstruction error 10 m, in silence)."""
    if cfg.space is None:
        raise UserError(f"{where}: no space of interest ([tracker.space]): replay would take every point "
                        "(the ground too) as the target; give one with --tracker-config FILE whose [tracker.space] "
                        "table sets it (a daemon config such as examples/daemon-virtual.toml, or a scene)")


class _RecordedOutcome:
    """Replay's command sink: nothing is written; whether the head got a command is what the recording
    says (the daemon's ``written: false`` for a failed write; a command without a record reached it).
    The driver names the record before each step (:attr:`record`).

    ``follow_recorded`` (a replay under another configuration): where the replayed command differs
    from the recorded one, the head ran the recorded one (:meth:`head_ran`): the points were seen
    from the head's recorded motion, and the dead reckoning that places them in the world follows it
    (before, it followed the replayed tracker's own commands: a what-if replay of a sky run with a
    1 s revisit time put the head 25 deg off by frame 400 and made 181 confirmed tracks of 5)."""

    def __init__(self, follow_recorded: bool = False):
        self.record: CommandRecord | None = None
        self.follow_recorded = follow_recorded

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        return self.record is None or self.record.reached_head

    def head_ran(self, cmd: HeadCommand) -> HeadCommand | None:
        r = self.record
        if not self.follow_recorded or r is None or not r.reached_head or None in r.speeds:
            return None
        recorded = r.command
        return None if recorded == cmd else recorded


class _TracksComparison:
    """The multi-object tracker's tracks, replayed against recorded, frame by frame: every field of
    every track (:class:`foveatrack.recording.records.TracksRecord`, as JSON: what the file holds)."""

    def __init__(self):
        self.replayed: list[TracksRecord] = []
        self.recorded = 0
        self.compared = 0
        self.identical = 0
        self.first_difference: int | None = None

    def add(self, frame_id: int, frame: Frame, out, recorded: TracksRecord | None) -> None:
        mine = TracksRecord.from_output(ns(frame.t_end_s), frame_id, out) if getattr(out, "sky", None) is not None else None
        if mine is not None:
            self.replayed.append(mine)
        if recorded is None:
            return
        self.recorded += 1
        if mine is None:
            return
        self.compared += 1
        if mine.to_json() == recorded.to_json():
            self.identical += 1
        elif self.first_difference is None:
            self.first_difference = frame_id

    def summary(self) -> dict:
        """``recorded`` frames with tracks, ``replayed``, ``compared`` (both), ``identical``,
        ``first_difference`` (frame id or None), ``identical_all`` (every recorded frame's tracks
        replayed equal, and none replayed beyond them)."""
        return {"recorded": self.recorded, "replayed": len(self.replayed), "compared": self.compared,
                "identical": self.identical, "first_difference": self.first_difference,
                "identical_all": self.recorded > 0 and self.identical == self.recorded == len(self.replayed)}


def _after_frame(step: FrameStep, sink: _RecordedOutcome, order: TimeOrder, after: list) -> None:
    """The watchdog / shutdown STOPs and the daemon's rebases after a frame, in the order they happened
    (a fresh tracker where the daemon rebased)."""
    for c in after:
        if isinstance(c, TrackerRebased):
            step.rebase(step.controller.rebased(c.t0_s, c.pan_deg, c.tilt_deg))
            order.rebased()
            continue
        if isinstance(c, PoseCorrected):
            step.controller.correct_pose(c.t_s, c.dpan_deg, c.dtilt_deg)
            continue
        if isinstance(c, TrackPinned):
            pin = getattr(step.controller, "pin", None)
            if pin is not None:          # a pin means nothing to the paper's tracker (another configuration)
                pin(c.track_id)
            continue
        if order.command_out_of_order(step.controller, c.send_time_s):
            continue
        sink.record = c
        step.own_command(c.send_time_s, c.command, c.source or "")


def replay_recording(path: str | os.PathLike, tracker_table: dict | None = None,
                     config_name: str | None = None, max_frames: int | None = None) -> ReplayResult:
    """Re-run the tracker over a foveatrack recording (simulator or daemon); ``max_frames``: the cap
    on frames read (default the reader's for the file's size, :func:`foveatrack.recording.reader.frame_cap`)."""
    from foveatrack.recording.segments import open_run

    reader = open_run(path, max_frames)      # a run split into segments: all of them, in order
    meta = RecordingMeta.from_dict(reader.meta, str(path))   # the configuration that ran, typed
    source = meta.source
    where = f"{config_name} [tracker]" if config_name else "recorded [tracker]"
    cfg = tracker_config(meta, tracker_table, where)
    if tracker_table is not None:     # the recorded configuration replays as it ran, space or none
        require_space(cfg, where)
    rec_cfg = meta.tracker
    sink = _RecordedOutcome(follow_recorded=tracker_table is not None)
    controller = Tracker(cfg, meta.speed_table, t0_s=meta.tracker_t0_s)
    # the multi-object tracker where the run had it (its recorded table), or where the table given has one
    sky_table = meta.sky if tracker_table is None else tracker_table.get("sky")
    if sky_table is not None:
        from foveatrack.sky.controller import SkyController, recorded_sky_table

        if tracker_table is None:       # the recorded table, with what the tracker gained since at its old values
            sky_table = recorded_sky_table(sky_table)
        # named as simulate and the daemon name it ("F [tracker.sky].attention", not "[tracker].sky")
        controller = SkyController.from_table(controller, sky_table, f"{where[:-len('[tracker]')]}[tracker.sky]",
                                              meta.half_fov_deg)
    tracks_cmp = _TracksComparison()
    step = FrameStep(controller, CommandGate(meta.limits), sink)
    period = rec_cfg.period_s
    period_ns = int(round(1e9 / rec_cfg.rate_hz))
    send_delay_sim = rec_cfg.send_delay_s
    F = FrameArrays()
    R = {k: [] for k in ("detected", "det_xyz", "det_n_points", "command", "error_pan_deg", "error_tilt_deg",
                         "processing_ms", "latency_ms", "head_pan_deg", "head_tilt_deg")}
    T = {k: [] for k in ("true_error_deg", "target_xyz_m", "points_on_target", "pan_deg", "tilt_deg")}
    has_truth = False
    imu_recorded = False
    order = TimeOrder()
    commands: dict = {}
    for rf in recorded_frames(reader, commands):
        _after_frame(step, sink, order, rf.before)     # the daemon's start (a homing) before its first frame
        pts = rf.points
        k = int(pts.frame_index)
        if source == "simulator":
            t0, t1 = k * period, (k + 1) * period
            if abs(int(round(t1 * 1e9)) - pts.t_ns) > 1:   # not the simulator's frame grid: trust t_ns
                t1 = pts.t_ns * 1e-9
                t0 = t1 - period
            send_t = t1 + send_delay_sim
        else:
            t1 = pts.t_ns * 1e-9
            t0 = (pts.t_ns - period_ns) * 1e-9
            c = rf.command
            send_t = float(c.send_t_s) if c is not None and c.send_t_s is not None else t1 + cfg.send_delay_s
        if order.frame_out_of_order(step.controller, k, t1, send_t):
            _after_frame(step, sink, order, rf.after)
            continue
        frame = Frame(t0, t1, pts.xyz, pts.t_ns_points, pts.reflectivity)
        # the IMU as the driver fed it: before the frame (a commands tracker ignores it); a frame the
        # driver found stale (the daemon: by its wall clock) is stale here too
        imu_recorded = imu_recorded or bool(rf.imu)
        sink.record = rf.command
        rec = step(frame, send_t, imu=[(b.t_s, b.gyro_rad_s) for b in rf.imu], stale=rf.stale)
        out = rec.output
        F.add(k, frame, out, rec.command)
        tracks_cmp.add(k, frame, out, rf.tracks)
        d = rf.detection
        R["detected"].append(d is not None and d.detected)
        R["det_xyz"].append(np.full(3, np.nan) if d is None or d.xyz_m is None else np.asarray(d.xyz_m, float))
        R["det_n_points"].append(0 if d is None else d.n_points)
        R["error_pan_deg"].append(np.nan if d is None or d.error_pan_deg is None else d.error_pan_deg)
        R["error_tilt_deg"].append(np.nan if d is None or d.error_tilt_deg is None else d.error_tilt_deg)
        R["command"].append((None,) * 4 if rf.command is None else rf.command.speeds)
        R["processing_ms"].append(rf.metrics.get("processing_ms", np.nan))
        R["latency_ms"].append(np.nan if rf.metrics.get("latency_ms") is None else rf.metrics["latency_ms"])
        h = rf.head
        R["head_pan_deg"].append(np.nan if h is None else h.est_pan_deg)
        R["head_tilt_deg"].append(np.nan if h is None else h.est_tilt_deg)
        t = rf.truth
        if t is not None:
            has_truth = True
            T["true_error_deg"].append(np.nan if t.true_error_deg is None else t.true_error_deg)
            T["target_xyz_m"].append(np.asarray(t.true_target_world_m, float))
            T["points_on_target"].append(t.points_on_target)
            T["pan_deg"].append(t.true_pan_deg)
            T["tilt_deg"].append(t.true_tilt_deg)
        else:
            T["true_error_deg"].append(np.nan)
            T["target_xyz_m"].append(np.full(3, np.nan))
            T["points_on_target"].append(0)
            T["pan_deg"].append(np.nan)
            T["tilt_deg"].append(np.nan)
        _after_frame(step, sink, order, rf.after)
    tracker = step.controller
    t_settled = (tracker.recon.last_send_t_s or 0.0) + 2.0
    final_pose = tuple(float(a) for a in tracker.recon.angles_at(t_settled)[:2])
    frames = F.arrays()
    recorded = recorded_arrays(R, RECORDED_DTYPES)
    truth = recorded_arrays(T, TRUTH_DTYPES) if has_truth else None
    res = ReplayResult(source, str(path), config_name or "recorded", frames, recorded, truth,
                       final_pose_deg=final_pose, tracker_cfg=cfg)
    res.comparison = compare(frames, recorded)
    res.tracks = tracks_cmp.replayed
    if tracks_cmp.replayed or tracks_cmp.recorded:
        res.comparison["tracks"] = tracks_cmp.summary()
    if cfg.attitude == "gyro":
        # Without IMU samples (a recording made before /imu existed, or of a run without an IMU) the
        # replayed tracker's head angles come from its commands alone, so they, the world estimates
        # and the commands may differ from the run for that reason.
        res.comparison["gyro_samples_recorded"] = imu_recorded
    as_recorded = meta.tracker_as_recorded()
    if tracker_table is None and as_recorded is not None:
        # the configuration replay rebuilt is the one the recording says ran
        res.comparison["tracker_config_as_recorded"] = as_recorded
    # the truth's error is the recorded head's (under another config too: open loop), so it counts as
    # acquired by the recorded run's dead band, not by this config's
    res.metrics = replay_metrics(frames, truth, rec_cfg, meta.half_fov_deg)
    res.recorded_metrics = recorded_metrics(recorded, truth, rec_cfg, frames)
    if reader.problem:
        res.comparison["recording_problem"] = reader.problem
    held = reader.held_text()
    if held:
        # a writer or a recover holds the file: what is said of its end (the report, as export says it)
        res.comparison["recording_held"] = held
    res.comparison["recording_complete"] = bool(reader.complete)
    if getattr(reader, "parts", None):
        res.comparison["recording_segments"] = len(reader.parts)
        if reader.notes:
            res.comparison["recording_segment_notes"] = reader.notes
    res.comparison["commands_in_recording"] = commands
    res.comparison["metadata_checksum"] = "verified" if reader.meta_checked else "absent (an older recording)"
    # a held file's cut-short end is not damage (recording_held says what it is); what was skipped
    # before it is
    res.comparison["recording_damage"] = [d.describe() for d in reader.damage_not_held()] + order.describe()
    if reader.capped is not None:
        res.comparison["recording_capped"] = reader.capped_text()
    res.comparison.update(_gaps(frames, recorded, reader, order.frames + order.commands))
    return res


def _gaps(frames: dict, recorded: dict, reader, skipped_out_of_order: int = 0) -> dict:
    """Where frames are missing (a skipped damaged stretch), and whether that makes the comparison partial.

    A gap is a jump in the recorded frame index (both drivers number frames 0, 1, 2, ...), or damage
    before the first frame read.  The commands sent in missing frames are lost with them, so after a
    gap the replay's dead reckoning lacks them and its head estimate, detections in the world frame
    and commands may differ from the recording for that reason alone: the comparison is then
    *partial*, exact only up to the first gap (``before_first_gap``).  A cut-short tail leaves no gap.
    """
    fi = np.asarray(frames["frame_index"], np.int64)
    gaps = []
    lead = [d for d in reader.damage if not d.cut_short and d.frames_before == 0]
    if fi.size and (fi[0] > 0 or (lead and lead[0].frames_lost)):
        gaps.append((0, None, int(fi[0]), int(fi[0]) if fi[0] > 0 else lead[0].frames_lost))
    for i in np.flatnonzero(np.diff(fi) != 1) + 1:
        gaps.append((int(i), int(fi[i - 1]), int(fi[i]), int(fi[i] - fi[i - 1] - 1)))
    # damage that lost records other than frames (e.g. a watchdog STOP) also leaves the reckoning short
    lost_other = any(not d.cut_short and (d.lost is None or sum(d.lost.values()) > 0) for d in reader.damage)
    partial = bool(gaps) or lost_other or bool(reader.unattributed) or bool(skipped_out_of_order)
    out: dict = {"partial": partial, "frames_missing": int(sum(g[3] for g in gaps if g[3])), "gaps": []}
    for i, after, before, n in gaps:
        dp = frames["head_pan_deg"][i] - recorded["head_pan_deg"][i]
        dt = frames["head_tilt_deg"][i] - recorded["head_tilt_deg"][i]
        diff = float(np.hypot((dp + 180.0) % 360.0 - 180.0, dt))
        out["gaps"].append({"after_frame": after, "before_frame": before, "frames_missing": n,
                            "head_estimate_diff_deg": diff if math.isfinite(diff) else None})
    if partial:
        k = gaps[0][0] if gaps else len(fi)
        c = compare({key: v[:k] for key, v in frames.items()}, {key: v[:k] for key, v in recorded.items()})
        out["before_first_gap"] = {"frames": int(k), "detections_equal": c["detections_equal"],
                                   "commands_equal": c["commands_equal"],
                                   "frames_detection_differs": c["frames_detection_differs"],
                                   "frames_command_differs": c["frames_command_differs"]}
    return out


def replay_lvx(path: str | os.PathLike, tracker_table: dict | None = None, config_name: str | None = None,
               point_rate_hz: float | None = None) -> ReplayResult:
    """Run the tracker over a Livox Viewer ``.lvx`` file (lidar only, head frozen: after every frame
    the reconstruction is told the head stopped, so the commands are what it would have sent)."""
    from foveatrack.frames import strip_no_return
    from foveatrack.livox.lvx import LvxReader

    cfg = TrackerConfig.from_mapping(tracker_table or {}, where=f"{config_name or 'default'} [tracker]")
    require_space(cfg, f"{path}: a Livox Viewer file carries no tracker configuration" if tracker_table is None
                  else f"{config_name or 'the given'} [tracker]")
    # The gate a daemon would run on this tracker's head (its stops, the tracker's own turbo rule); the
    # head is frozen, so no write reaches it (NoHead) and the dead reckoning is told it stayed stopped.
    step = FrameStep(None, CommandGate(Limits(allow_turbo=cfg.allow_turbo, tilt_limits_deg=cfg.tilt_limits_deg)),
                     NoHead())
    F = FrameArrays()
    fid = 0

    def run(frames):
        nonlocal fid
        for fr, new_clock in frames:
            fr = strip_no_return(fr)
            if step.controller is None or new_clock:
                step.rebase(Tracker(cfg, SpeedTable.nominal(), t0_s=fr.t_start_s))
            rec = step(fr, fr.t_end_s + cfg.send_delay_s)
            F.add(fid, fr, rec.output, rec.command)
            fid += 1

    # no-return points are kept for their times (frames keep coming over the sky), then stripped
    with LvxReader(path, point_rate_hz=point_rate_hz, keep_no_return=True) as r:
        timeline = LvxTimeline(cfg.rate_hz, r.frame_duration_ms)
        for lf in r.frames():
            b = lf.points
            run(timeline.push(b.xyz, b.t_ns, b.reflectivity))
        run(timeline.flush())
        problem = r.problem
    frames = F.arrays()
    res = ReplayResult("lvx", str(path), config_name or "default", frames, None, None, tracker_cfg=cfg)
    res.metrics = replay_metrics(frames, None, cfg)
    if problem:
        res.comparison["recording_problem"] = problem
    res.comparison["lvx_time"] = timeline.counts
    res.comparison["recording_damage"] = timeline.describe()
    return res


def replay(path: str | os.PathLike, tracker_config_path: str | None = None,
           max_frames: int | None = None) -> ReplayResult:
    """Replay a recording (``.mcap``) or a Livox Viewer file (``.lvx``), by content; ``max_frames``:
    the cap on a recording's frames (an ``.lvx`` is capped by the time its frames span)."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{p}: no such recording")
    table = load_tracker_table(tracker_config_path) if tracker_config_path else None
    from foveatrack.recording.reader import read_head

    head = read_head(p, 16)
    if head.startswith(b"livox_tech") or (p.suffix.lower() == ".lvx" and not head.startswith(MCAP_MAGIC)):
        from foveatrack.livox.lvx import LvxReader

        # the file's header first (a .lvx that is not one is named by the LVX field that is wrong, not
        # as lacking the MCAP magic; a damaged one before the missing tracker configuration)
        LvxReader(p).close()
        return replay_lvx(p, table, tracker_config_path)
    return replay_recording(p, table, tracker_config_path, max_frames)
