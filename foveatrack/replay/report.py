"""A replay for people: the text report and the trajectory export."""

from __future__ import annotations

import os
from pathlib import Path

from foveatrack.recording.export import out_kind, write_columns
from foveatrack.replay.result import ReplayResult


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
    if res.tracks:
        # the multi-object tracker's fovea serves every drone in turn: the figures against the scene's
        # first target say how often it was that one, not how well the tracker did
        caveat += " (the scene's first target only; the multi-object tracker's fovea serves every track in turn)"
    if tr is not None:
        te = tr["tracking_error_deg"]
        fmt = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
        L.append(f"  tracking error after acquisition [deg]: rms {fmt(te['rms'])}, p95 {fmt(te['p95'])}, "
                 f"max {fmt(te['max'])}; acquisition {fmt(tr['acquisition_s'])} s; "
                 f"frames with detection {tr['frames_with_detection']}/{tr['frames']}{caveat}")
        if "reconstruction_error_m" in tr and tr["reconstruction_error_m"]["rms"] is not None:
            # under another config the dead reckoning follows the recorded head too (driver's
            # _RecordedOutcome): a figure on the recorded motion, with the tracking error's caveat
            re_ = tr["reconstruction_error_m"]
            L.append(f"  reconstructed target position error [m]: rms {re_['rms']:.3f}, p95 {re_['p95']:.3f}, "
                     f"max {re_['max']:.3f}{caveat}")
    d = m["detection"]
    be = d["bearing_error_deg"]
    L.append(f"  detections: {d['frames_with_detection']}/{d['frames']} frames"
             + (f", bearing error off the lidar axis [deg]: rms {be['rms']:.3f}, p95 |.| {be['p95']:.3f}, "
                f"max |.| {be['max']:.3f}" if be["rms"] is not None else "")
             + f"; states {d['states']}")
    if not d["frames"]:
        L.append("  the recording holds no lidar frames (e.g. the lidar never sent data): nothing to replay")
    if c.get("recording_held"):      # its end is a writer's next data, or a recover's to complete: not damage
        L.insert(1, f"  note: {c['recording_held']}")
    if c.get("recording_damage"):    # (a held file's: what was skipped before its end)
        L.insert(1, "  WARNING: damaged recording, " + "; ".join(c["recording_damage"]))
    if c.get("recording_capped"):
        L.insert(1, f"  WARNING: {res.path} read in part: {c['recording_capped']}")
    if c.get("gyro_samples_recorded") is False:
        L.append("  attitude = \"gyro\", but the recording holds no IMU samples (made before they were recorded, or "
                 "the run had no IMU): the replay's head angles come from its commands alone, so they and what "
                 "depends on them may differ from the run")
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
    tr = c.get("tracks")
    if tr:
        ids = sorted({t.id for r in res.tracks for t in r.tracks if t.confirmed})
        kept = f"{len(ids)} confirmed track{'s' if len(ids) != 1 else ''} (ids {', '.join(map(str, ids)) or '-'})"
        if tr["identical_all"]:
            L.append(f"  tracks (multi-object tracker): {kept}; all {tr['recorded']} frames' tracks identical to the recorded")
        elif not tr["recorded"]:
            L.append(f"  tracks (multi-object tracker): {kept}; the recording has none to compare (another configuration's run)")
        elif not tr["replayed"]:
            L.append(f"  tracks: the recording holds the multi-object tracker's tracks ({tr['recorded']} frames); this "
                     "replay ran the paper's single-target tracker (its configuration has no [tracker.sky]), so there "
                     "are none to compare")
        else:
            L.append(f"  tracks (multi-object tracker): {kept}; {tr['identical']} of {tr['recorded']} recorded frames' "
                     f"tracks identical ({tr['compared']} compared, {tr['replayed']} replayed; first difference: "
                     f"frame {tr['first_difference']})")
    cmds = c.get("commands_in_recording") or {}
    if cmds.get("from_journal"):
        L.append(f"  commands: {cmds['recorded']} in the recording, {cmds['from_journal']} of them put back from the "
                 f"command journal by 'foveatrack recover' ({cmds.get('journal_only', 0)} the head got outside the "
                 f"dead reckoning: STOPs at start or while its pose was unknown, homing; not replayed)")
    for k, v in res.recorded_metrics.items():
        L.append(f"  recorded {k}: p50 {v['p50']:.2f}, p99 {v['p99']:.2f}, max {v['max']:.2f}")
    if (c.get("recording_problem") and not c.get("recording_damage") and not c.get("recording_capped")
            and not c.get("recording_held")):
        L.append(f"  note: {c['recording_problem']}")
    return "\n".join(L)


def export_replay_trajectory(res: ReplayResult, out_path: str | os.PathLike) -> int:
    """Write the replay's per-frame arrays (and truth) to CSV or NPZ (by suffix); returns rows."""
    out_path = Path(out_path)
    out_kind(out_path)          # before the work: a wrong name is an error that names the file
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
    write_columns(out_path, cols, nan_as_empty=True)
    return len(f["t_end_s"])
