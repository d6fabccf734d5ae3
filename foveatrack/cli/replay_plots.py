"""Plots of a replay: the paper's Fig. 14a/b/c equivalents and the head angles (matplotlib Agg, PNG;
CLI edge only).  Drawn by the same functions as ``foveatrack simulate --plot`` (``sim_plots``), so a
simulated run and its replay look alike.

* points_on_target.png (paper Fig. 14a) -- points per frame (a) along the target's path, (b) against its angle
  off the lidar axis.  With truth (a simulator recording): the true points on the target and the
  detection's points, both against the true position; otherwise the detection's points against the
  tracker's own world estimate and bearing.
* error.png (paper Fig. 14b) -- the true error off the axis (truth) and the detection's bearing off the
  axis against time, the dead band, the acquisition and tracking phases shaded (paper Fig. 12 colours)
* trajectory.png (paper Fig. 14c) -- the reconstructed target trajectory (the tracker's world estimates) against
  truth: top view, height against time, and the reconstruction error
* head.png -- the head (true; in a daemon recording the daemon's own estimate, the head
  reports no pose) and the replay's dead reckoning, their difference per axis, the tilt stops when
  the tilt comes near one, and the tracker's state frame by frame (not for a ``.lvx`` file)
* tracks.png -- a multi-object run's ([tracker.sky]) replayed tracks, with every object's truth and
  each drone's time in the fovea where the recording is a simulator's (:func:`sky_plot_data`); such a
  run gets it and head.png only, as ``simulate`` draws it: the one-target figures drew the fixated
  track's detections as one target's, jumping from drone to drone with the fovea

Time is the recording's own for a simulator recording (virtual time, as ``simulate`` plots it) and
seconds since the first frame otherwise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_all(res, out_dir: Path) -> list[Path]:
    f = res.frames
    out_dir = Path(out_dir)
    rp = Path(res.path)   # "overhead-tilt-stop/run.mcap": simulate names every recording run.mcap
    name = f"{rp.parent.name}/{rp.name}" if rp.parent.name else rp.name
    t_abs = np.asarray(f["t_end_s"], float)
    t0 = 0.0 if res.source == "simulator" or not len(t_abs) else float(t_abs[0])
    t = t_abs - t0
    sky = bool(res.tracks)      # a multi-object run: tracks.png and head.png, as simulate draws it
    files = [] if sky else _one_target_figures(res, out_dir, name, t, t0)
    if res.source != "lvx":
        files.append(_head_figure(res, out_dir, name, t))
    if sky:
        from foveatrack.cli import sim_plots

        files.append(sim_plots.plot_sky_tracks(sky_plot_data(res, t), f"{name}: tracks (replay)",
                                               out_dir / sim_plots.TRACKS_PNG))
    return files


def _one_target_figures(res, out_dir: Path, name: str, t, t0: float) -> list[Path]:
    """Fig. 14a, 14b and 14c of the replay (points on the target, error against time, the
    reconstructed trajectory)."""
    from foveatrack.cli import sim_plots

    f, truth, cfg = res.frames, res.truth, res.tracker_cfg
    det = np.asarray(f["detected"], bool)
    bearing = np.where(det, np.hypot(f["error_pan_deg"], f["error_tilt_deg"]), np.nan)
    det_points = np.where(det, f["det_n_points"], np.nan)
    if truth is not None:
        files = [sim_plots.plot_points_vs_position(
            truth["target_xyz_m"], truth["true_error_deg"], truth["points_on_target"],
            f"{name}: points on the UAV per frame (replay)", out_dir / sim_plots.POINTS_PNG,
            det_points=det_points)]
    else:
        files = [sim_plots.plot_points_vs_position(
            f["world_xyz"], bearing, None, f"{name}: points in the detection per frame (replay)",
            out_dir / sim_plots.POINTS_PNG, det_points=det_points, source="tracker's")]
    tr = res.metrics.get("tracking") or {}
    phases = {}
    if tr.get("in_fov_t_s") is not None:
        acq = tr.get("acquired_t_s")
        phases = dict(in_fov_t_s=tr["in_fov_t_s"] - t0, acquired_t_s=None if acq is None else acq - t0)
    db = None if cfg is None else max(cfg.deadband_pan_deg, cfg.deadband_tilt_deg)
    if res.source == "lvx":   # the head did not move: nothing was tracked, the dead band never acted
        db, err_title = None, f"{name}: detection's bearing off the lidar axis (replay, head frozen)"
    else:
        err_title = f"{name}: tracking error (replay; paper Fig. 14b)"
    files.append(sim_plots.plot_error_vs_time(
        t, None if truth is None else truth["true_error_deg"], err_title,
        out_dir / sim_plots.ERROR_PNG, detected=det if truth is not None else None,
        bearing_error_deg=bearing, deadband_deg=db, **phases,
        deadband_axes_deg=None if db is None else (cfg.deadband_pan_deg, cfg.deadband_tilt_deg)))

    # an .lvx holds no head motion: its points are turned by a head held still, whatever the head did
    lvx_note = "; head frozen: an .lvx holds no head motion" if res.source == "lvx" else ""
    files.append(sim_plots.plot_trajectory(
        t, f["world_xyz"], f"{name}: reconstructed trajectory (replay; paper Fig. 14c{lvx_note})",
        out_dir / sim_plots.TRAJECTORY_PNG, true_xyz=None if truth is None else truth["target_xyz_m"]))

    return files


def _head_figure(res, out_dir: Path, name: str, t) -> Path:
    """head.png of the replay."""
    from foveatrack.cli import sim_plots

    f, truth, cfg = res.frames, res.truth, res.tracker_cfg
    if truth is not None:
        pan, tilt, source = truth["pan_deg"], truth["tilt_deg"], "true"
        head_title = f"{name}: head angles (replay)"
    else:
        # a daemon recording holds the daemon's own dead reckoning, not the head's pose (the head
        # reports none): the residual says how far the replay is from it, not from the head
        pan, tilt, source = res.recorded["head_pan_deg"], res.recorded["head_tilt_deg"], "daemon's estimate"
        head_title = f"{name}: head angles (replay; the head's true pose is not measured)"
    return sim_plots.plot_head(
        t, pan, tilt, head_title, out_dir / sim_plots.HEAD_PNG, est_label="replay's dead reckoning",
        residual_label="replay - " + ("true" if truth is not None else "daemon") + " [deg]",
        est_pan_deg=f["head_pan_deg"], est_tilt_deg=f["head_tilt_deg"], state=f["state"], source=source,
        tilt_limits_deg=None if cfg is None else cfg.tilt_limits_deg,
        tilt_margin_deg=None if cfg is None else cfg.tilt_margin_deg)


def sky_plot_data(res, t: np.ndarray) -> dict:
    """What ``tracks.png`` draws (:func:`foveatrack.cli.sim_plots.plot_sky_tracks`, as ``simulate``
    draws it from :func:`sim.sky_summary.sky_plot_data`) from a replay of a multi-object run: the
    replayed confirmed tracks, and -- in a simulator's recording -- every object's truth
    (``/truth_objects``) and, per drone, the frames it was within the fovea's half-angle of the true
    axis (the half-angle of the recorded ``[tracker.sky]`` table).  A daemon's recording has no
    truth: the tracks alone."""
    from foveatrack.recording import RecordingReader
    from foveatrack.recording.records import ObjectTruthRecord
    from foveatrack.sky.attention import true_off_axis_deg
    from foveatrack.sky.track_paths import confirmed_paths

    T = len(t)
    tracks = confirmed_paths(([(v.id, v.confirmed, v.label, v.xyz_m, v.hit) for v in rec.tracks]
                              for rec in res.tracks), T)
    truth: dict[str, tuple[str, np.ndarray]] = {}
    in_fovea: dict[str, np.ndarray] = {}
    reader = RecordingReader(res.path) if res.source == "simulator" else None
    if reader is not None and res.truth is not None:
        for r in map(ObjectTruthRecord.from_json, reader.records("truth_objects")):
            k = r.frame_id
            if r.id.startswith("stray-") or not 0 <= k < T:
                continue
            cls = r.cls if r.cls in ("drone", "bird") else "clutter"
            truth.setdefault(r.id, (cls, np.full((T, 3), np.nan)))[1][k] = r.true_world_m
        half = float(((reader.meta.get("sky") or {}).get("attention") or {}).get("fovea_half_angle_deg", 3.0))
        pan, tilt = res.truth["pan_deg"], res.truth["tilt_deg"]
        for i, (c, xyz) in truth.items():
            if c == "drone":
                in_fovea[i] = true_off_axis_deg(xyz, pan, tilt) <= half     # NaN (absent): False
    return {"t_s": t, "truth": truth, "tracks": tracks, "in_fovea": in_fovea}
