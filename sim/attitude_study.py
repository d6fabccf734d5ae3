"""Head attitude from the commands or from the gyro, on the same scene: the runs and their errors.

A variant of a scene file (:func:`scene_variant`): ``[imu]`` added if it has none (the BMI088 of
:mod:`sim.imu`, mounted as the lidar: the tracker's ``imu_rotation_deg`` is the scene's), ``[tracker]
attitude`` set, and optionally the tracker's speed table replaced by the unit's true curve scaled (a
mis-calibrated table: every speed ``table_scale`` times the truth, each axis's acceleration
``accel_scale`` times it; the dead time true).  The two variants of a scene differ only in the
tracker's attitude source: the gyro is simulated in both (its own random stream), so the head, the target and every effect draw alike until
the tracker's commands differ.

Errors (:func:`run_variant`):

* reconstruction: ``foveatrack simulate --json``'s ``reconstruction_error_m`` / ``_rel`` (the
  tracker's world estimate of each detection against the true target position);
* head angle: ``head_angle_error_deg`` of the same summary, the rotation angle between the true lidar
  attitude ``R(pan, tilt)`` and the estimated one at mid-frame, every frame
  (:func:`foveatrack.metrics.head_angle_error_deg`) [deg].
"""

from __future__ import annotations

import json
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from foveatrack import metrics
from sim.scene import Scene, scene_from_mapping


def _scaled_truth_table(data: dict, scale: float, accel_scale: float, where: str) -> str:
    """The unit's true speed table with every speed times ``scale`` and each axis's acceleration times
    ``accel_scale``, as a JSON file; its path."""
    from gimbal.pts303h import PTS303H, HeadParams
    from sim.loop import truth_speed_table

    g = data.get("gimbal", {})
    head = PTS303H(HeadParams.for_family(g.get("family", "pts-303")), unit_seed=g.get("unit_seed", 0))
    d = truth_speed_table(head).to_dict()
    for ax in d["axes"].values():
        for e in ax["entries"]:
            if e["speed"] is not None:
                e["speed"] *= scale
        if ax.get("accel_deg_s2"):
            ax["accel_deg_s2"] *= accel_scale
    d["source"] = f"the unit's truth, speeds x {scale:g}, accelerations x {accel_scale:g} ({where}: mis-calibrated)"
    # one file per unit and scales, reused (the loop reads it when it starts)
    out = _private_dir() / (
        f"{g.get('family', 'pts-303')}-unit{g.get('unit_seed', 0)}-speed{scale:g}-accel{accel_scale:g}.json")
    out.write_text(json.dumps(d))
    return str(out)


_TABLES_DIR: Path | None = None


def _private_dir() -> Path:
    """This process's own directory for the tables (mode 0700, a name no one can guess: a fixed, shared
    /tmp/foveatrack-tables let another user plant a symlink or a table there)."""
    global _TABLES_DIR
    if _TABLES_DIR is None or not _TABLES_DIR.is_dir():
        _TABLES_DIR = Path(tempfile.mkdtemp(prefix="foveatrack-tables-"))
    return _TABLES_DIR


def scene_variant(path, attitude: str, *, table_scale: float | None = None, accel_scale: float | None = None,
                  duration_s: float | None = None, imu: dict | None = None) -> Scene:
    """The scene at ``path`` with an IMU on the head and ``[tracker] attitude = attitude`` (see the
    module docstring); ``imu`` replaces the added ``[imu]`` table (a scene's own is kept)."""
    path = Path(path)
    data = tomllib.loads(path.read_text())
    if "imu" not in data or imu is not None:
        data["imu"] = dict(imu or {})
    tr = dict(data.get("tracker", {}))
    tr["attitude"] = attitude
    rot = data["imu"].get("rotation_deg")
    if rot is not None and "imu_rotation_deg" not in tr:
        tr["imu_rotation_deg"] = rot
    data["tracker"] = tr
    sc = dict(data.get("scene", {}))
    if duration_s is not None:
        sc["duration_s"] = duration_s
    data["scene"] = sc
    if table_scale is not None or accel_scale is not None:
        data.setdefault("gimbal", {})["speed_table"] = _scaled_truth_table(
            data, 1.0 if table_scale is None else table_scale, 1.0 if accel_scale is None else accel_scale, str(path))
    return scene_from_mapping(data, str(path))


def head_angle_error_deg(log: dict) -> np.ndarray:
    """Per frame, the angle [deg] between the true and the estimated lidar attitude (mid-frame)."""
    return metrics.head_angle_error_deg(log["head_pan_deg"], log["head_tilt_deg"], log["est_pan_deg"],
                                        log["est_tilt_deg"])


def run_variant(scene: Scene) -> dict:
    """Run a scene variant; its reconstruction and head-angle errors, and the gyro's own counters."""
    from sim.loop import ClosedLoop
    from sim.summary import summarize

    t = time.perf_counter()
    loop = ClosedLoop(scene)
    log = loop.run()
    m = summarize(scene, log, time.perf_counter() - t, loop)
    out = {"scene": scene.name, "attitude": scene.tracker.attitude,
           "reconstruction_error_m": m["reconstruction_error_m"],
           "reconstruction_error_rel": m["reconstruction_error_rel"],
           "head_angle_error_deg": m["head_angle_error_deg"],
           "tracking_error_deg": m["tracking_error_deg"], "frames_with_detection": m["frames_with_detection"],
           "frames": m["frames"], "wall_s": m["wall_s"]}
    src = loop.tracker.recon
    if hasattr(src, "bias"):
        out["gyro"] = {"bias_updates": src.bias.updates, "rests_refuted": src.rests_refuted,
                       "bias_error_deg_s": float(np.degrees(np.max(np.abs(src.bias.b - loop.gyro._bias)))),
                       "rest_fraction": src.rest_samples / max(src.samples, 1)}
    return out
