"""A frame source through the open-loop tracker: per-frame arrays, the summary and the track's CSV."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field

import numpy as np

from foveatrack.openloop.reference import error_summary, match_reference
from foveatrack.openloop.tracker import OpenLoopConfig, OpenLoopTracker


@dataclass
class OpenLoopResult:
    """``frames``: per-frame arrays (``t_s`` frame stamp, ``arrival_s``, ``n_points``, ``detected``,
    ``xyz_m`` Algorithm 1's position (NaN where none), ``det_t_s``, ``det_n_points``, ``track_id``
    (-1 none), ``state``, and with a reference ``ref_t_s`` the time it was sampled at (see
    :func:`summarize`), ``ref_xyz_m`` and ``error_m``); ``confirmed``: every confirmed track (id,
    first seen, confirmed at, hits, mean range); ``summary``: the figures."""
    source: str
    path: str
    frames: dict
    confirmed: list
    summary: dict = field(default_factory=dict)


def track_source(source, cfg: OpenLoopConfig | None = None, reference=None, progress=None,
                 observer=None) -> OpenLoopResult:
    """Run :class:`OpenLoopTracker` over ``source`` (an iterable of ``(arrival_s, Frame)``);
    ``reference``: ``(t_s, xyz_m)`` (:func:`~foveatrack.openloop.reference.load_reference`) or None;
    ``progress``: called with each frame's index (a progress bar); ``observer(k, arrival_s, frame,
    out)`` after each frame (a recording: :class:`~foveatrack.openloop.recording.TrackRecorder`)."""
    cfg = cfg or OpenLoopConfig()
    tracker = OpenLoopTracker(cfg)
    cols = {k: [] for k in ("t_s", "arrival_s", "n_points", "n_foreground", "detected", "xyz_m", "det_t_s",
                            "det_n_points", "track_id", "state")}
    period = []
    point_times = False     # some frame's points carry times of their own (not all the stamp)
    for k, (arrival_s, frame) in enumerate(source):
        out = tracker.process(frame)
        det = out.detection
        cols["t_s"].append(frame.t_start_s)
        cols["arrival_s"].append(arrival_s)
        cols["n_points"].append(frame.n_points)
        cols["n_foreground"].append(out.n_foreground)
        cols["detected"].append(det is not None)
        cols["xyz_m"].append(np.full(3, np.nan) if det is None else np.asarray(det.xyz, float))
        cols["det_t_s"].append(np.nan if det is None else det.t_s)
        cols["det_n_points"].append(0 if det is None else det.n_points)
        cols["track_id"].append(-1 if out.track_id is None else out.track_id)
        cols["state"].append(out.state)
        period.append(frame.duration_s)
        if not point_times and frame.n_points > 1:
            point_times = bool(frame.t_ns.max() > frame.t_ns.min())
        if observer is not None:
            observer(k, arrival_s, frame, out)
        if progress is not None:
            progress(k)
    frames = {k: np.asarray(v, dtype={"detected": bool, "state": object}.get(k, None)) for k, v in cols.items()}
    if not cols["t_s"]:
        frames = {k: np.zeros((0, 3) if k == "xyz_m" else 0) for k in cols}
        frames["detected"] = np.zeros(0, bool)
    frames["xyz_m"] = frames["xyz_m"].reshape(-1, 3).astype(float)
    confirmed = [{"track_id": tr.track_id, "first_seen_s": tr.first_t_s, "confirmed_s": tr.confirmed_t_s,
                  "hits": tr.hits, "mean_range_m": tr.mean_range_m, "static": tr.static} for tr in tracker.confirmed]
    res = OpenLoopResult(getattr(source, "kind", "?"), str(getattr(source, "path", "?")), frames, confirmed)
    res.summary = summarize(frames, confirmed, cfg, reference, float(np.median(period)) if period else 0.1,
                            point_times)
    return res


def summarize(frames: dict, confirmed: list, cfg: OpenLoopConfig, reference, period_s: float,
              point_times: bool = False) -> dict:
    """The run's figures.  With a reference, each frame is compared with the reference sample nearest
    the time of what was measured: with ``point_times`` (the points carry their own times) a
    detection's time ``det_t_s``, the median time of its points -- a drone at 8 m/s moves 0.4 m in
    the 50 ms between a frame's stamp and the middle of its scan (a simulated Mid-40 run, drone
    circling 20 m out: median 0.464 m from the reference at the stamps, 0.190 m at the detections'
    times) -- else the frame's stamp (its points' one time).  ``summary["reference"]["matched_at"]``
    says which."""
    det = frames["detected"]
    t = frames["t_s"]
    s = {"frames": int(det.size), "frames_tracked": int(det.sum()),
         "first_frame_s": float(t[0]) if t.size else None,
         "confirmed_tracks": len(confirmed), "confirmed": confirmed,
         "confirmed_static": sum(bool(c["static"]) for c in confirmed),
         "d_given": cfg.space is not None}
    if det.any():
        s["first_tracked_s"] = float(t[np.argmax(det)])
    if reference is not None:
        ref_t, ref_xyz = reference
        at = np.where(det, frames["det_t_s"], t) if point_times else t
        frames["ref_t_s"] = at
        idx = match_reference(at, ref_t, 0.5 * period_s)
        ok = idx >= 0
        ref = np.full((t.size, 3), np.nan)
        ref[ok] = ref_xyz[idx[ok]]
        frames["ref_xyz_m"] = ref
        d = frames["xyz_m"] - ref
        err = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
        frames["error_m"] = err
        s["reference"] = {"matched_at": ("each detection's time (the median time of its points)" if point_times
                                         else "each frame's stamp (the points carry no time of their own)"),
                          "frames_with_reference": int(ok.sum()),
                          "frames_with_reference_tracked": int((ok & det).sum()),
                          "error": error_summary(err),
                          # what says why none matched: the two clocks' spans (relative vs unix seconds)
                          "t_range_s": _span(ref_t), "frames_t_range_s": _span(at), "tracked_t_range_s": _span(at[det]),
                          "max_dt_s": 0.5 * period_s}
    return s


def _span(t) -> list | None:
    """``[first, last]`` of the finite times [s], None if there are none."""
    t = np.asarray(t, float)
    t = t[np.isfinite(t)]
    return [float(t.min()), float(t.max())] if t.size else None


def write_track_csv(res: OpenLoopResult, path) -> int:
    """The track as CSV: one row per frame (empty x, y, z where nothing was detected)."""
    f = res.frames
    has_ref = "error_m" in f
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        head = ["t_s", "arrival_s", "state", "track_id", "n_points", "det_n_points", "det_t_s", "x_m", "y_m", "z_m"]
        if has_ref:
            head += ["ref_x_m", "ref_y_m", "ref_z_m", "error_m"]
        w.writerow(head)
        for i in range(f["t_s"].size):
            x = f["xyz_m"][i]
            row = [repr(float(f["t_s"][i])), repr(float(f["arrival_s"][i])), f["state"][i], int(f["track_id"][i]),
                   int(f["n_points"][i]), int(f["det_n_points"][i]),
                   "" if not f["detected"][i] else repr(float(f["det_t_s"][i]))]
            row += ["" if not f["detected"][i] else repr(float(v)) for v in x]
            if has_ref:
                r = f["ref_xyz_m"][i]
                row += ["" if not np.isfinite(v) else repr(float(v)) for v in r]
                row.append("" if not np.isfinite(f["error_m"][i]) else repr(float(f["error_m"][i])))
            w.writerow(row)
    return int(f["t_s"].size)
