"""Replay: re-run detection and control offline over recorded point frames (deterministic).

One tracker object for every driver (DESIGN.md): :func:`replay_recording` pushes the recorded frames
of a simulator or daemon recording (:mod:`foveatrack.recording`) through a fresh
:class:`foveatrack.tracker.Tracker` with the recorded configuration -- or another one -- and the
recorded send times, so with the recorded configuration the detections and commands come out
identical (to the bit) to the recorded ones.  :func:`replay_lvx` runs the tracker over a Livox Viewer
``.lvx`` file (lidar only: the head is taken as frozen, so the commands are what the tracker *would*
have sent).

How a recording's tracker is rebuilt (``meta``):

* simulator (``sim.recorder.recording_meta``): ``[tracker]`` table + what
  :class:`sim.loop.ClosedLoop` sets from ``[gimbal]`` (start pose, the family's tilt stops,
  ``latency_s`` = a Pelco-D frame's time on the wire, ``send_delay_s``); frame ``k`` is ``[k, k+1) / rate_hz`` and its command
  was written at ``t_end + send_delay_s``.
* daemon (:mod:`foveatrack.daemon.runtime`): ``[tracker]`` table + ``tracker_overrides``; frames end
  at the recorded ``t_ns``; the send time is the command's ``send_t_s``; commands the safety gate
  limited, and the watchdog's and shutdown's STOPs, are registered where they happened; a command
  whose write failed (``written: false``) is replaced, at the same instant, by the last one that
  reached the head (the head never saw it, and kept moving as it was told before).

Replay is open loop: the points are what the lidar saw while the head moved as it did, so a
different configuration shows which detections and commands would have differed on the same data,
not where the head would have gone.

A damaged recording (:class:`foveatrack.recording.Damage`) is replayed from everything the reader
recovered; the report's first line after the title is a WARNING naming what was skipped.  Frames
lost in the middle take their commands with them, so the replay's dead reckoning after the gap
lacks those commands: the comparison then says it is *partial* (``comparison["partial"]``,
``gaps`` with the head-estimate offset after each, ``before_first_gap`` exact as before).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from foveatrack.control import STOP, HeadCommand
from foveatrack.errors import UserError
from foveatrack.frames import Frame, FrameSlicer
from foveatrack.gate import STALE_FRAME, CommandGate, Limits
from foveatrack.recording.format import METRICS, POINTS
from foveatrack.recording.records import CommandRecord, DetectionRecord, HeadEstimateRecord, TruthRecord, parse
from foveatrack.metrics import acquired_within_deg, tracking_metrics
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import TrackerConfig, Tracker


@dataclass
class ReplayResult:
    """Per-frame arrays of the replay (``frames``), of the recording (``recorded``), truth (or None),
    the comparison and the metrics."""

    source: str
    path: str
    config: str
    frames: dict[str, np.ndarray]
    recorded: dict[str, np.ndarray] | None
    truth: dict[str, np.ndarray] | None
    comparison: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    recorded_metrics: dict = field(default_factory=dict)
    # Dead-reckoned (pan_deg, tilt_deg) once the head has settled after the last command sent
    # (2 s later): where the run left the head, by the tracker's own reckoning.
    final_pose_deg: tuple[float, float] | None = None
    # The tracker configuration the replay ran with (its dead band and tilt stops go on the plots).
    tracker_cfg: TrackerConfig | None = None

    def summary(self) -> dict:
        return {"source": self.source, "path": self.path, "config": self.config, "frames": len(self.frames["t_end_s"]),
                "metrics": self.metrics, "comparison": self.comparison, "recorded_metrics": self.recorded_metrics,
                "final_pose_deg": None if self.final_pose_deg is None else list(self.final_pose_deg)}


def load_tracker_table(path: str | os.PathLike) -> dict:
    """The ``[tracker]`` table of a TOML file (a scene, a daemon config, or a bare tracker table)."""
    from foveatrack.config_util import read_toml

    data, _ = read_toml(path, "tracker config (--tracker-config)")
    return dict(data.get("tracker", data))


def _overrides(meta: dict) -> dict:
    src = meta.get("source")
    if "tracker_overrides" in meta:  # written by the daemon and by the simulator
        return {k: tuple(v) if isinstance(v, list) else v for k, v in meta["tracker_overrides"].items()}
    if src == "simulator":  # recordings made before the simulator wrote its overrides
        from gimbal.pelco import frame_time_s
        from gimbal.pts303h import HeadParams

        g = meta["gimbal"]
        params = HeadParams.for_family(g["family"])
        tilt0 = min(max(g["tilt0_deg"], params.tilt_min_deg), params.tilt_max_deg)
        return {"pan0_deg": g["pan0_deg"], "tilt0_deg": tilt0,
                "tilt_limits_deg": (params.tilt_min_deg, params.tilt_max_deg),
                "latency_s": frame_time_s("D", g["baud"]), "send_delay_s": g["send_delay_s"]}
    raise UserError(f"recording source {src!r} is not 'simulator' or 'daemon'")


class _RecordedHead:
    """The head's facts as a recording gives them (its ``tracker_overrides``), for
    :meth:`TrackerConfig.with_head`."""

    def __init__(self, values: dict):
        self._values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}

    def tracker_values(self) -> dict:
        return dict(self._values)


def tracker_config(meta: dict, table: dict | None = None, where: str = "recorded [tracker]") -> TrackerConfig:
    """The effective tracker configuration of a recording, or of another ``[tracker]`` ``table`` on the
    recording's head: the head's facts win by the rule every driver applies (:meth:`TrackerConfig.with_head`;
    a table that contradicts them is an error naming the key).  Without ``table`` the recorded table and
    the head values recorded with it rebuild what ran (in daemon recordings made before that rule, a
    [tracker] head key had won over [head], and the recording left that key out of its overrides)."""
    head = _RecordedHead(_overrides(meta))
    if table is None:
        return replace(TrackerConfig.from_mapping(dict(meta.get("tracker_table", {})), where=where),
                       **head.tracker_values())
    return TrackerConfig.from_mapping(dict(table), where=where).with_head(head, table, where)


class _Frames:
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


@dataclass
class _RecordedFrame:
    """One frame of a recording with the typed records that belong to it (None where absent) and the
    commands sent after it that belong to no frame (watchdog, shutdown)."""
    points: object
    detection: DetectionRecord | None = None
    head: HeadEstimateRecord | None = None
    command: CommandRecord | None = None       # the tracker's command for this frame, as sent
    truth: TruthRecord | None = None
    metrics: dict = field(default_factory=dict)
    after: list = field(default_factory=list)   # [CommandRecord] in the order sent

    @property
    def stale(self) -> bool:
        """The driver found the frame stale when processing it (the daemon: by its wall clock)."""
        return self.command is not None and STALE_FRAME in self.command.limited


def _frames_of(reader):
    """Yield a :class:`_RecordedFrame` per frame of the recording."""
    cur = None
    for m in reader.messages():
        if m.channel == POINTS:
            if cur is not None:
                yield cur
            cur = _RecordedFrame(m.record)
            continue
        if cur is None:
            continue
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
        elif m.channel == METRICS:
            cur.metrics.setdefault(rec["name"], rec["value"])
    if cur is not None:
        yield cur


def _reached_head(gate: CommandGate, tracker: Tracker, send_t: float, cmd: HeadCommand,
                  record: CommandRecord | None) -> HeadCommand:
    """What the head runs after a command sent at ``send_t``: the gate's rule for a write, with the
    outcome the recording gives (the daemon's ``written: false`` for a failed write)."""
    return gate.wrote(tracker, send_t, cmd, ok=record is None or record.reached_head)


def _recorded_limits(meta: dict) -> Limits | None:
    """The gate's limits as the daemon or the simulator recorded them (None where none were recorded:
    a scene without [gate], older recordings; their commands pass the gate unchanged)."""
    if not meta.get("limits"):
        return None
    L = dict(meta["limits"])
    L["tilt_limits_deg"] = tuple(L["tilt_limits_deg"])
    return Limits(**L)


def replay_recording(path: str | os.PathLike, tracker_table: dict | None = None,
                     config_name: str | None = None) -> ReplayResult:
    """Re-run the tracker over a foveatrack recording (simulator or daemon)."""
    from foveatrack.recording import RecordingReader

    reader = RecordingReader(path)
    meta = reader.meta
    source = meta.get("source", "?")
    where = f"{config_name} [tracker]" if config_name else "recorded [tracker]"
    cfg = tracker_config(meta, tracker_table, where)
    rec_cfg = tracker_config(meta)
    table = SpeedTable.from_dict(meta["speed_table"], where=f"{path}: recorded speed table")
    tracker = Tracker(cfg, table, t0_s=float(meta.get("tracker_t0_s", 0.0)))
    gate = CommandGate(_recorded_limits(meta))
    period = rec_cfg.period_s
    period_ns = int(round(1e9 / rec_cfg.rate_hz))
    send_delay_sim = rec_cfg.send_delay_s
    F = _Frames()
    R = {k: [] for k in ("detected", "det_xyz", "det_n_points", "command", "error_pan_deg", "error_tilt_deg",
                         "processing_ms", "latency_ms", "head_pan_deg", "head_tilt_deg")}
    T = {k: [] for k in ("true_error_deg", "target_xyz_m", "points_on_target", "pan_deg", "tilt_deg")}
    has_truth = False
    for rf in _frames_of(reader):
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
        frame = Frame(t0, t1, pts.xyz, pts.t_ns_points, pts.reflectivity)
        out = tracker.process(frame, send_t_s=send_t)
        # a frame the driver found stale (the daemon: by its wall clock) is stale here too
        cmd, _ = gate.decide(tracker, out, send_t, stale=rf.stale)
        _reached_head(gate, tracker, send_t, cmd, rf.command)
        F.add(k, frame, out, cmd)
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
        for c in rf.after:   # watchdog / shutdown STOPs, in the order they were sent
            tracker.command_sent(c.send_time_s, c.command)
            _reached_head(gate, tracker, c.send_time_s, c.command, c)
    t_settled = (tracker.recon.last_send_t_s or 0.0) + 2.0
    final_pose = tuple(float(a) for a in tracker.recon.angles_at(t_settled)[:2])
    frames = F.arrays()
    recorded = {k: np.asarray(v) for k, v in R.items()}
    recorded["det_xyz"] = recorded["det_xyz"].reshape(-1, 3)
    truth = None
    if has_truth:
        truth = {k: np.asarray(v) for k, v in T.items()}
        truth["target_xyz_m"] = truth["target_xyz_m"].reshape(-1, 3)
    res = ReplayResult(source, str(path), config_name or "recorded", frames, recorded, truth,
                       final_pose_deg=final_pose, tracker_cfg=cfg)
    res.comparison = compare(frames, recorded)
    if tracker_table is None and "tracker_effective" in meta:
        # the configuration replay rebuilt is the one that ran (JSON-normalised: tuples as lists)
        import json

        res.comparison["tracker_config_as_recorded"] = (
            json.loads(json.dumps(cfg.effective())) == meta["tracker_effective"])
    res.metrics = replay_metrics(frames, truth, cfg, meta.get("half_fov_deg"))
    res.recorded_metrics = _recorded_metrics(recorded, truth, rec_cfg, frames)
    if reader.problem:
        res.comparison["recording_problem"] = reader.problem
    res.comparison["recording_complete"] = bool(reader.complete)
    res.comparison["recording_damage"] = [d.describe() for d in reader.damage]
    res.comparison.update(_gaps(frames, recorded, reader))
    return res


def _gaps(frames: dict, recorded: dict, reader) -> dict:
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
    partial = bool(gaps) or lost_other or bool(reader.unattributed)
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
    tracker = None
    slicer = FrameSlicer(cfg.rate_hz)
    F = _Frames()
    fid = 0

    def run(frames):
        nonlocal tracker, fid
        for fr in frames:
            fr = strip_no_return(fr)
            if tracker is None:
                tracker = Tracker(cfg, SpeedTable.nominal(), t0_s=fr.t_start_s)
            send_t = fr.t_end_s + cfg.send_delay_s
            out = tracker.process(fr, send_t_s=send_t)
            tracker.command_sent(send_t, STOP)   # the head is frozen
            F.add(fid, fr, out, out.command)
            fid += 1

    # no-return points are kept for their times (frames keep coming over the sky), then stripped
    with LvxReader(path, point_rate_hz=point_rate_hz, keep_no_return=True) as r:
        for lf in r.frames():
            b = lf.points
            run(slicer.push(b.xyz, b.t_ns, b.reflectivity))
        run(slicer.flush())
        problem = r.problem
    frames = F.arrays()
    res = ReplayResult("lvx", str(path), config_name or "default", frames, None, None, tracker_cfg=cfg)
    res.metrics = replay_metrics(frames, None, cfg)
    if problem:
        res.comparison["recording_problem"] = problem
    return res


def replay(path: str | os.PathLike, tracker_config_path: str | None = None) -> ReplayResult:
    """Replay a recording (``.mcap``) or a Livox Viewer file (``.lvx``), by content."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{p}: no such recording")
    table = load_tracker_table(tracker_config_path) if tracker_config_path else None
    with open(p, "rb") as fh:
        head = fh.read(16)
    if head.startswith(b"livox_tech"):
        return replay_lvx(p, table, tracker_config_path)
    return replay_recording(p, table, tracker_config_path)


# ----------------------------------------------------------------------------------------- figures
def _stats(x) -> dict:
    """rms, p95 and max of the magnitude |x| (a percentile of a signed error mixes its two sides:
    p95 -0.82 beside rms 2.30 said nothing), and the signed mean (the bias); ``of`` says so."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"rms": None, "p95": None, "max": None, "mean_signed": None, "of": "|error|; mean_signed is signed"}
    a = np.abs(x)
    return {"rms": float(np.sqrt(np.mean(x ** 2))), "p95": float(np.percentile(a, 95)), "max": float(np.max(a)),
            "mean_signed": float(np.mean(x)), "of": "|error|; mean_signed is signed"}


def bearing_metrics(frames: dict) -> dict:
    """Detection-based figures (no truth needed): bearing error of the detections off the lidar axis."""
    det = np.asarray(frames["detected"], bool)
    ep, et = frames["error_pan_deg"], frames["error_tilt_deg"]
    states, counts = np.unique(frames["state"], return_counts=True) if len(det) else ([], [])
    return {"frames": int(len(det)), "frames_with_detection": int(det.sum()),
            "points_per_frame_mean": float(frames["n_points"].mean()) if len(det) else None,
            "detection_points_mean": float(frames["det_n_points"][det].mean()) if det.any() else None,
            "bearing_error_pan_deg": _stats(ep[det]), "bearing_error_tilt_deg": _stats(et[det]),
            "bearing_error_deg": _stats(np.hypot(ep[det], et[det])),
            "states": {str(s): int(c) for s, c in zip(states, counts)}}


def replay_metrics(frames: dict, truth: dict | None, cfg: TrackerConfig, half_fov_deg: float | None = None) -> dict:
    """Detection metrics, and with the simulator's truth the tracking metrics as ``simulate`` gives
    them: the acquisition clock starts when the true error is inside ``half_fov_deg`` (recorded by
    the simulator; recordings made before it was, start it at the first frame with points on the
    target) and stops once it is held within :func:`foveatrack.metrics.acquired_within_deg`."""
    out = {"detection": bearing_metrics(frames)}
    if truth is not None:
        err = np.asarray(truth["true_error_deg"], float)
        with np.errstate(invalid="ignore"):
            in_fov = err < half_fov_deg if half_fov_deg is not None else truth["points_on_target"] > 0
        out["tracking"] = tracking_metrics(
            frames["t_end_s"], err, detected=frames["detected"], in_fov=in_fov,
            acquired_deg=acquired_within_deg(cfg), world_est=frames["world_xyz"], world_true=truth["target_xyz_m"])
    return out


def _recorded_metrics(rec: dict, truth, cfg, frames) -> dict:
    out = {}
    for k in ("processing_ms", "latency_ms"):
        x = np.asarray(rec[k], float)
        x = x[np.isfinite(x)]
        if x.size:
            out[k] = {"p50": float(np.percentile(x, 50)), "p99": float(np.percentile(x, 99)), "max": float(x.max())}
    return out


def compare(frames: dict, rec: dict) -> dict:
    """Which frames' detections and commands differ between the replay and the recording."""
    a_det, b_det = frames["detected"], rec["detected"]
    xyz_a, xyz_b = frames["det_xyz"], rec["det_xyz"]
    both = a_det & b_det
    dx = np.abs(xyz_a[both] - xyz_b[both]).max(axis=1) if both.any() else np.zeros(0)
    differ = (a_det != b_det) | (frames["det_n_points"] != rec["det_n_points"])
    differ[np.flatnonzero(both)[dx > 0]] = True
    has_cmd = np.array([c[0] is not None for c in rec["command"]], bool) if len(rec["command"]) else np.zeros(0, bool)
    cmd_differ = np.zeros(len(a_det), bool)
    if has_cmd.any():
        rc = np.array([c if c[0] is not None else (0, 0, 0, 0) for c in rec["command"]], dtype=np.int64)
        cmd_differ = has_cmd & np.any(frames["command"] != rc, axis=1)
    idx = np.flatnonzero(differ)
    cidx = np.flatnonzero(cmd_differ)
    return {"detections_equal": bool(not differ.any()), "frames_detection_differs": int(differ.sum()),
            "first_frames_detection_differs": frames["frame_index"][idx[:10]].tolist(),
            "max_detection_xyz_diff_m": float(dx.max()) if dx.size else 0.0,
            "detected_recorded": int(b_det.sum()), "detected_replayed": int(a_det.sum()),
            "commands_compared": int(has_cmd.sum()), "commands_equal": bool(not cmd_differ.any()),
            "frames_command_differs": int(cmd_differ.sum()),
            "first_frames_command_differs": frames["frame_index"][cidx[:10]].tolist()}


def format_report(res: ReplayResult) -> str:
    """The printed summary (the figures ``--json`` gives in full)."""
    L = [f"replay of {res.path} ({res.source}, {len(res.frames['t_end_s'])} frames, tracker config: {res.config})"]
    m = res.metrics
    tr = m.get("tracking")
    c = res.comparison
    # with another configuration the replay is open loop (the points are those of the recorded head
    # motion): its errors are what that configuration would have seen there, said beside the numbers
    open_loop = ("detections_equal" in c and not (c["detections_equal"] and c["commands_equal"]))
    caveat = " (open loop: on the recorded head motion, not where this config would have steered)" if open_loop else ""
    if tr is not None:
        te = tr["tracking_error_deg"]
        fmt = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
        L.append(f"  tracking error after acquisition [deg]: rms {fmt(te['rms'])}, p95 {fmt(te['p95'])}, "
                 f"max {fmt(te['max'])}; acquisition {fmt(tr['acquisition_s'])} s; "
                 f"frames with detection {tr['frames_with_detection']}/{tr['frames']}{caveat}")
        if "reconstruction_error_m" in tr and tr["reconstruction_error_m"]["rms"] is not None:
            re_ = tr["reconstruction_error_m"]
            L.append(f"  reconstructed target position error [m]: rms {re_['rms']:.3f}, p95 {re_['p95']:.3f}, "
                     f"max {re_['max']:.3f}{caveat}")
    d = m["detection"]
    be = d["bearing_error_deg"]
    L.append(f"  detections: {d['frames_with_detection']}/{d['frames']} frames"
             + (f", bearing error off the lidar axis [deg]: rms {be['rms']:.3f}, p95 |.| {be['p95']:.3f}, "
                f"max |.| {be['max']:.3f}" if be["rms"] is not None else "")
             + f"; states {d['states']}")
    if c.get("recording_damage"):
        L.insert(1, "  WARNING: damaged recording, " + "; ".join(c["recording_damage"]))
    if c.get("partial"):
        b = c["before_first_gap"]
        gaps = []
        for g in c["gaps"]:
            n = g["frames_missing"]
            txt = (f"frames before {g['before_frame']}" if not n else f"frame {g['before_frame'] - 1}" if n == 1
                   else f"frames {g['before_frame'] - n}-{g['before_frame'] - 1}")
            if g["head_estimate_diff_deg"] is not None:
                txt += f" (head estimate after it {g['head_estimate_diff_deg']:.3f} deg off the recorded)"
            gaps.append(txt)
        upto = ("same as recorded" if b["detections_equal"] and b["commands_equal"] else
                f"{b['frames_detection_differs']} detections and {b['frames_command_differs']} commands differ")
        L.append(f"  comparison is partial: {'; '.join(gaps) or 'records other than frames'} missing; the commands "
                 f"sent in them are lost, so after the first gap the replay's dead reckoning lacks them. Before it "
                 f"({b['frames']} frames): {upto}; over all {d['frames']} replayed frames {c['frames_detection_differs']}"
                 f" detections and {c['frames_command_differs']} of {c['commands_compared']} commands differ")
    elif "detections_equal" in c:
        if c["detections_equal"] and c["commands_equal"]:
            L.append(f"  same as recorded: all {d['frames']} detections and {c['commands_compared']} commands identical")
        else:
            L.append(f"  differs from the recording: {c['frames_detection_differs']} frames' detections "
                     f"(recorded {c['detected_recorded']} detected, replayed {c['detected_replayed']}; first "
                     f"{c['first_frames_detection_differs']}), {c['frames_command_differs']} of "
                     f"{c['commands_compared']} commands (first {c['first_frames_command_differs']}); "
                     f"open loop: same points, the head moved as recorded")
    for k, v in res.recorded_metrics.items():
        L.append(f"  recorded {k}: p50 {v['p50']:.2f}, p99 {v['p99']:.2f}, max {v['max']:.2f}")
    if c.get("recording_problem") and not c.get("recording_damage"):
        L.append(f"  note: {c['recording_problem']}")
    return "\n".join(L)


def export_replay_trajectory(res: ReplayResult, out_path: str | os.PathLike) -> int:
    """Write the replay's per-frame arrays (and truth) to CSV or NPZ (by suffix); returns rows."""
    out_path = Path(out_path)
    suf = out_path.suffix.lower()
    if suf not in (".csv", ".npz"):
        raise UserError(f"export to {out_path}: the file name must end in .csv or .npz")
    f = res.frames
    cols = {"frame_index": f["frame_index"], "t_end_s": f["t_end_s"], "n_points": f["n_points"],
            "detected": f["detected"].astype(int), "state": f["state"],
            "det_x_m": f["det_xyz"][:, 0], "det_y_m": f["det_xyz"][:, 1], "det_z_m": f["det_xyz"][:, 2],
            "error_pan_deg": f["error_pan_deg"], "error_tilt_deg": f["error_tilt_deg"],
            "head_pan_deg": f["head_pan_deg"], "head_tilt_deg": f["head_tilt_deg"],
            "world_x_m": f["world_xyz"][:, 0], "world_y_m": f["world_xyz"][:, 1], "world_z_m": f["world_xyz"][:, 2],
            "pan_dir": f["command"][:, 0], "pan_byte": f["command"][:, 1], "tilt_dir": f["command"][:, 2],
            "tilt_byte": f["command"][:, 3]}
    if res.truth is not None:
        t = res.truth
        cols.update({"true_error_deg": t["true_error_deg"], "true_x_m": t["target_xyz_m"][:, 0],
                     "true_y_m": t["target_xyz_m"][:, 1], "true_z_m": t["target_xyz_m"][:, 2],
                     "points_on_target": t["points_on_target"], "true_pan_deg": t["pan_deg"],
                     "true_tilt_deg": t["tilt_deg"]})
    if suf == ".npz":
        np.savez_compressed(out_path, **cols)
    else:
        import csv

        with open(out_path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols.keys())
            for row in zip(*(np.asarray(c).tolist() for c in cols.values())):
                w.writerow(["" if isinstance(v, float) and math.isnan(v) else v for v in row])
    return len(f["t_end_s"])
