"""A replay's figures: detection metrics, tracking metrics against the simulator's truth, and the
comparison of the replayed frames with the recorded ones."""

from __future__ import annotations

import numpy as np

from foveatrack.metrics import acquired_within_deg, tracking_metrics
from foveatrack.tracker import TrackerConfig


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
    target) and stops once it is held within :func:`foveatrack.metrics.acquired_within_deg` of ``cfg``:
    the configuration that moved the head the truth's error is of (the recorded one, in a replay)."""
    out = {"detection": bearing_metrics(frames)}
    if truth is not None:
        err = np.asarray(truth["true_error_deg"], float)
        with np.errstate(invalid="ignore"):
            in_fov = err < half_fov_deg if half_fov_deg is not None else truth["points_on_target"] > 0
        out["tracking"] = tracking_metrics(
            frames["t_end_s"], err, detected=frames["detected"], in_fov=in_fov,
            acquired_deg=acquired_within_deg(cfg), world_est=frames["world_xyz"], world_true=truth["target_xyz_m"])
    return out


def recorded_metrics(rec: dict, truth, cfg, frames) -> dict:
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
