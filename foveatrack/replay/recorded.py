"""A recording read frame by frame (:class:`RecordedFrame` with its typed records) and the
per-frame arrays a replay builds (:class:`FrameArrays`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from foveatrack.gate import STALE_FRAME
from foveatrack.recording.format import COMMANDS, DAEMON_EVENTS, IMU, METRICS, POINTS
from foveatrack.recording.records import (CommandRecord, DetectionRecord, HeadEstimateRecord, RecordError, TracksRecord, TruthRecord,
                                          parse)


class FrameArrays:
    """Per-frame arrays built frame by frame."""

    KEYS = ("frame_index", "t_end_s", "n_points", "detected", "det_xyz", "det_n_points", "state", "error_pan_deg",
            "error_tilt_deg", "command", "head_pan_deg", "head_tilt_deg", "world_xyz")

    def __init__(self):
        self.d = {k: [] for k in self.KEYS}

    def add(self, fid, frame, out, cmd):
        d = self.d
        det = out.detection
        d["frame_index"].append(fid)
        d["t_end_s"].append(frame.t_end_s)
        d["n_points"].append(frame.n_points)
        d["detected"].append(det is not None)
        d["det_xyz"].append(np.full(3, np.nan) if det is None else np.asarray(det.xyz, float))
        d["det_n_points"].append(0 if det is None else int(det.n_points))
        d["state"].append(out.state.value)
        d["error_pan_deg"].append(np.nan if out.error_pan_deg is None else out.error_pan_deg)
        d["error_tilt_deg"].append(np.nan if out.error_tilt_deg is None else out.error_tilt_deg)
        d["command"].append((cmd.pan_dir, cmd.pan_byte, cmd.tilt_dir, cmd.tilt_byte))
        d["head_pan_deg"].append(out.head_pan_deg)
        d["head_tilt_deg"].append(out.head_tilt_deg)
        d["world_xyz"].append(np.full(3, np.nan) if out.world_xyz is None else np.asarray(out.world_xyz, float))

    # dtypes given so that a run with no frames (an empty or all-no-return .lvx) still yields arrays
    # that index and reduce like the others (a bare np.asarray([]) is float: not a mask)
    DTYPES = {"frame_index": np.int64, "n_points": np.int64, "detected": bool, "det_n_points": np.int64,
              "t_end_s": float, "error_pan_deg": float, "error_tilt_deg": float, "head_pan_deg": float,
              "head_tilt_deg": float, "det_xyz": float, "world_xyz": float, "command": np.int64}

    def arrays(self) -> dict[str, np.ndarray]:
        out = {k: np.asarray(v, dtype=self.DTYPES.get(k)) if v or k in self.DTYPES else np.asarray(v)
               for k, v in self.d.items()}
        for k in ("det_xyz", "world_xyz"):
            out[k] = out[k].reshape(-1, 3)
        out["command"] = out["command"].reshape(-1, 4)
        return out


# the recording's own per-frame values (replay_recording collects them); dtypes given so that a
# recording with no frames (the daemon's when the lidar never sent data) yields empty arrays that
# index and compare like those of any other
RECORDED_DTYPES = {"detected": bool, "det_xyz": float, "det_n_points": np.int64, "error_pan_deg": float,
                   "error_tilt_deg": float, "processing_ms": float, "latency_ms": float, "head_pan_deg": float,
                   "head_tilt_deg": float}
TRUTH_DTYPES = {"true_error_deg": float, "target_xyz_m": float, "points_on_target": np.int64, "pan_deg": float,
                "tilt_deg": float}


def recorded_arrays(lists: dict, dtypes: dict) -> dict[str, np.ndarray]:
    """Per-frame lists as arrays of ``dtypes`` (xyz columns reshaped to (n, 3)); ``command`` stays a
    list of (pan_dir, pan_byte, tilt_dir, tilt_byte) tuples or (None,) * 4 where none was recorded."""
    out = {k: (np.asarray(v, dtype=dtypes[k]) if k in dtypes else np.asarray(v)) for k, v in lists.items()}
    for k in ("det_xyz", "target_xyz_m"):
        if k in out:
            out[k] = out[k].reshape(-1, 3)
    if "command" in lists:
        out["command"] = np.asarray(lists["command"]) if lists["command"] else np.zeros((0, 4), object)
    return out


class TimeOrder:
    """Frames and commands a replay cannot take because they go back in time: intact chunks read out
    of order (e.g. a stretch of the file copied over an earlier one).  The tracker's dead reckoning
    takes commands in time order only, so such a frame (with its command) or command is skipped and
    counted; the replay's warning names them, and the comparison is partial."""

    def __init__(self):
        self.frames = 0
        self.commands = 0
        self.first_frame: int | None = None
        self._last_t_end_s = -np.inf

    def rebased(self) -> None:
        self._last_t_end_s = -np.inf      # a new sensor clock: its frames start over

    def frame_out_of_order(self, tracker, frame_index: int, t_end_s: float, send_t_s: float) -> bool:
        last_send = tracker.recon.last_send_t_s
        if t_end_s <= self._last_t_end_s or (last_send is not None and send_t_s < last_send) \
                or not np.isfinite(send_t_s):
            self.frames += 1
            if self.first_frame is None:
                self.first_frame = frame_index
            return True
        self._last_t_end_s = t_end_s
        return False

    def command_out_of_order(self, tracker, send_t_s) -> bool:
        last_send = tracker.recon.last_send_t_s
        if send_t_s is None or not np.isfinite(send_t_s) or (last_send is not None and send_t_s < last_send):
            self.commands += 1
            return True
        return False

    def describe(self) -> list[str]:
        if not (self.frames or self.commands):
            return []
        what = []
        if self.frames:
            what.append(f"{self.frames} frame{'' if self.frames == 1 else 's'} (the first: frame "
                        f"{self.first_frame})")
        if self.commands:
            what.append(f"{self.commands} command{'' if self.commands == 1 else 's'} outside any frame")
        return [f"{' and '.join(what)} skipped: out of time order (intact data read out of order, e.g. "
                f"a stretch of the file copied over an earlier one); the tracker takes them in time order only"]


class LvxTimeline:
    """An ``.lvx`` file's points cut into tracker frames, with the live driver's checks of sensor time
    (:class:`foveatrack.sensor_time.SensorTimeGuard`) on a clock the file gives: LVX frame ``k`` of
    ``frame_duration_ms`` is taken to arrive at ``k * frame_duration_ms``.  A package with a wild
    time (one stamped 18 minutes late once made the slicer restart there and drop every point after
    it as late: 9 frames of 31, silently) is dropped and counted; a real change of sensor clock
    starts a fresh stream (the slicer again from its first point); and no file yields more tracker
    frames than the time its LVX frames span, plus the tolerance, allows.

    :meth:`push` / :meth:`flush` return ``(frame, new_clock)`` pairs (``new_clock``: the first frame on
    a sensor clock other than the one before); :attr:`counts` and :meth:`describe` say what was dropped.
    """

    def __init__(self, rate_hz: float, frame_duration_ms: int):
        from foveatrack.frames import FrameSlicer
        from foveatrack.sensor_time import SensorTimeGuard

        self.guard = SensorTimeGuard()
        self.slicer = FrameSlicer(rate_hz)
        self.frame_s = max(int(frame_duration_ms), 1) * 1e-3
        self._k = 0
        self._epoch = 0
        self._new_clock = False

    def push(self, xyz, t_ns, reflectivity) -> list:
        host_s = self._k * self.frame_s
        self._k += 1
        t_ns = np.asarray(t_ns, np.int64)
        order = np.argsort(t_ns, kind="stable")     # devices' packets interleave within a frame
        return self._slice(self.guard.push(np.asarray(xyz)[order], t_ns[order], np.asarray(reflectivity)[order],
                                           host_s))

    def _slice(self, accepted) -> list:
        out = []
        for acc in accepted:
            if acc.epoch != self._epoch:            # a new sensor clock: the old stream ends here
                out += self._tag(self.slicer.flush())
                self.slicer.reset()
                self._epoch = acc.epoch
                self._new_clock = True
            out += self._tag(self.slicer.push(acc.xyz, acc.t_ns, acc.reflectivity))
        return out

    def flush(self) -> list:
        # the guard holds the newest points back to put an overtaken packet in order: hand them on first
        return self._slice(self.guard.flush()) + self._tag(self.slicer.flush())

    def _tag(self, frames) -> list:
        out = []
        for fr in frames:
            out.append((fr, self._new_clock))
            self._new_clock = False
        return out

    @property
    def counts(self) -> dict:
        g, s = self.guard.counters, self.slicer
        # after flush() what the guard still holds is a candidate clock that never continued: bad time
        return {"bad_time_points": int(g["bad_time_points"] + self.guard.held_points),
                "bad_time_packets_runs": int(g["bad_time_segments"] + (1 if self.guard.held_points else 0)),
                "clock_jumps": int(g["clock_jumps"]), "late_points": int(s.late_points),
                "slicer_restarts": int(s.restarts), "gap_dropped_points": int(s.gap_dropped_points)}

    def describe(self) -> list[str]:
        c = self.counts
        parts = []
        if c["bad_time_points"]:
            parts.append(f"{c['bad_time_points']} points dropped for a time that does not continue the stream "
                         f"({c['bad_time_packets_runs']} run(s) of packets, e.g. a damaged timestamp)")
        if c["late_points"]:
            parts.append(f"{c['late_points']} points dropped as late (older than a frame already cut)")
        if c["slicer_restarts"] or c["gap_dropped_points"]:
            parts.append(f"{c['slicer_restarts']} restart(s) of the frame slicer at a time gap, "
                         f"{c['gap_dropped_points']} points dropped with them")
        if c["clock_jumps"]:
            parts.append(f"{c['clock_jumps']} change(s) of the sensor clock (each starts a fresh tracker)")
        return ["; ".join(parts)] if parts else []


@dataclass(frozen=True)
class TrackerRebased:
    """The daemon started a fresh tracker at this pose and sensor time (its ``tracker_rebased``
    event: a new lidar clock, or the head homed); replay does the same at the same place."""
    t0_s: float
    pan_deg: float
    tilt_deg: float
    reason: str


@dataclass(frozen=True)
class PoseCorrected:
    """The daemon's pose check moved the dead reckoning by this much from sensor time ``t_s`` (its
    ``pose_corrected`` event, :mod:`foveatrack.daemon.pose_guard`); replay does the same at the same place."""
    t_s: float
    dpan_deg: float
    dtilt_deg: float


@dataclass(frozen=True)
class TrackPinned:
    """The daemon's operator pinned a track of the multi-object tracker (None: unpinned; its
    ``track_pinned`` event, written between the frames it fell between); replay does the same there."""
    track_id: int | None


@dataclass
class RecordedFrame:
    """One frame of a recording with the typed records that belong to it (None where absent) and the
    commands sent after it that belong to no frame (watchdog, shutdown)."""
    points: object
    detection: DetectionRecord | None = None
    head: HeadEstimateRecord | None = None
    command: CommandRecord | None = None       # the tracker's command for this frame, as sent
    truth: TruthRecord | None = None
    tracks: TracksRecord | None = None         # the multi-object tracker's tracks after it ([tracker.sky])
    metrics: dict = field(default_factory=dict)
    after: list = field(default_factory=list)   # [CommandRecord | TrackerRebased | PoseCorrected | TrackPinned]
    imu: list = field(default_factory=list)     # [ImuSamples] fed to the tracker before this frame
    # the first frame only: what happened before it, as ``after`` (the daemon's homing at start,
    # ``[head] on_start = "home"``, rebased its tracker before any frame)
    before: list = field(default_factory=list)

    @property
    def stale(self) -> bool:
        """The driver found the frame stale when processing it (the daemon: by its wall clock)."""
        return self.command is not None and STALE_FRAME in self.command.limited


def recorded_frames(reader, commands: dict | None = None):
    """Yield a :class:`RecordedFrame` per frame of the recording.  A record whose fields are not of
    their type (a damaged or crafted file whose chunk CRC holds) is a UserError naming the file, the
    channel, the record's time and the field.  ``commands``: a dict counting the command records
    (``recorded``), those put back from the command journal (``from_journal``) and of those the ones
    the run's dead reckoning never saw (``journal_only``, not replayed)."""
    from foveatrack.errors import UserError

    cur = None
    early = RecordedFrame(None)      # what comes before the first frame (its ``before``)
    for m in reader.messages():
        if commands is not None and m.channel == COMMANDS and isinstance(m.record, dict):
            commands["recorded"] = commands.get("recorded", 0) + 1
            for k in ("from_journal", "journal_only"):
                commands[k] = commands.get(k, 0) + (m.record.get(k) is True)
        try:
            new = _take(early if cur is None and m.channel == DAEMON_EVENTS else cur, m)
        except RecordError as exc:
            raise UserError(f"{reader.path}: a {m.channel} record at time {m.t_ns} ns is damaged: {exc}") from None
        if new is not None:
            if cur is not None:
                yield cur
            else:
                new.before = early.after
            cur = new
    if cur is not None:
        yield cur


def _event_float(e: dict, key: str) -> float:
    v = e.get(key)
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        raise RecordError(f"field {key!r}: {v!r} is not a number")
    return float(v)


def _take(cur, m):
    """Add message ``m`` to the frame ``cur``; returns a new frame where ``m`` starts one, else None."""
    if m.channel == POINTS:
        return RecordedFrame(m.record)
    if cur is None:
        return None
    if m.channel == IMU:
        cur.imu.append(m.record)
        return None
    if m.channel == DAEMON_EVENTS:
        e = m.record
        if not isinstance(e, dict):
            raise RecordError(f"not a JSON object but {type(e).__name__}")
        if e.get("event") == "tracker_rebased":
            cur.after.append(TrackerRebased(_event_float(e, "t0_s"), _event_float(e, "pan_deg"),
                                            _event_float(e, "tilt_deg"), str(e.get("reason", "?"))))
        elif e.get("event") == "track_pinned":
            v = e.get("track_id")
            if v is not None and (not isinstance(v, int) or isinstance(v, bool)):
                raise RecordError(f"field 'track_id': {v!r} is not a whole number")
            cur.after.append(TrackPinned(v))
        elif e.get("event") == "pose_corrected":
            cur.after.append(PoseCorrected(_event_float(e, "t_s"), _event_float(e, "dpan_deg"),
                                           _event_float(e, "dtilt_deg")))
        return None
    if m.channel == COMMANDS and isinstance(m.record, dict) and m.record.get("journal_only") is True:
        return None      # put back from the command journal; the run's dead reckoning never saw it (recover)
    rec = parse(m.channel, m.record)
    if isinstance(rec, CommandRecord):
        if rec.frame_id is None:
            cur.after.append(rec)
        elif rec.from_tracker and cur.command is None:
            cur.command = rec
    elif isinstance(rec, DetectionRecord) and cur.detection is None:
        cur.detection = rec
    elif isinstance(rec, HeadEstimateRecord) and cur.head is None:
        cur.head = rec
    elif isinstance(rec, TruthRecord) and cur.truth is None:
        cur.truth = rec
    elif isinstance(rec, TracksRecord) and cur.tracks is None:
        cur.tracks = rec
    elif m.channel == METRICS:
        if not isinstance(rec, dict) or not isinstance(rec.get("name"), str) or not (
                rec.get("value") is None or isinstance(rec.get("value"), (int, float))):
            raise RecordError(f"not a metric (a name and a number): {str(rec)[:80]}")
        cur.metrics.setdefault(rec["name"], rec["value"])
    return None
