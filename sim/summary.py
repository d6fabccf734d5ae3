"""The metrics a closed-loop run prints (``foveatrack simulate --json``), from its per-frame log."""

from __future__ import annotations

import functools
import math

import numpy as np

from foveatrack.metrics import _stats, acquired_within_deg, head_angle_error_deg, tracking_metrics


def summarize(scene, log: dict, wall_s: float, loop=None, finish_s: float = 0.0) -> dict:
    """Tracking error after acquisition, acquisition time, detections, points on target, speed.

    "In the FoV" (the acquisition clock's start) is the first frame whose true off-axis angle is
    inside the scanner's half-FoV; acquisition uses the dead band + 1 deg (``foveatrack.metrics``).

    Speed: ``wall_s`` and ``realtime_factor`` (virtual / wall seconds) are the whole run's; with the
    run's ``loop`` (:class:`sim.loop.ClosedLoop`) also ``first_frame_s`` (the first frame loads the
    numba kernels from their cache, or compiles them on a fresh install), ``realtime_factor_after_first_frame``
    and ``time_per_frame_ms``: the mean wall time of each stage of a frame after the first (scan, ray casting and
    effects, tracker, ...), which is what the scene's fidelity costs; ``worked_ahead``: whether the scan
    and the effects' draws ran ahead on a second thread (:mod:`sim.ahead`; same results, other times).
    ``finish_s``: wall seconds after the loop that the run still needed (the recording's completion:
    a writer process finishing the frames it was handed), counted in ``realtime_factor_after_first_frame``
    and reported as ``finish_s``.

    A run of the multi-object tracker (``[tracker.sky]``) adds ``sky``: :func:`sim.sky_summary.sky_summary`.
    """
    half_fov = half_fov_deg(scene)
    err = log["true_error_deg"].astype(float)
    acquired = acquired_within_deg(scene.tracker)
    m = tracking_metrics(log["t_end_s"], err, detected=log["detected"], in_fov=err < half_fov,
                         acquired_deg=acquired, world_est=log["estimate_xyz"], world_true=log["target_xyz"])
    # the tracker's head attitude against the truth, every frame (None when no tracker runs)
    m["head_angle_error_deg"] = _stats(head_angle_error_deg(log["head_pan_deg"], log["head_tilt_deg"],
                                                            log["est_pan_deg"], log["est_tilt_deg"]))
    pts = log["points_on_target"]
    m["half_fov_deg"] = half_fov
    m["points_on_target_per_frame"] = float(np.mean(pts)) if len(pts) else 0.0
    m["points_per_frame"] = float(np.mean(log["points"])) if len(pts) else 0.0
    m["wall_s"] = round(wall_s, 3)
    m["realtime_factor"] = round(scene.duration_s / wall_s, 2) if wall_s > 0 else math.inf
    if loop is not None and loop.first_step_s is not None:
        n = loop.steps_timed   # the frames after the first (which loads or compiles the kernels)
        rest_s = sum(loop.stage_s.values()) + finish_s
        # to the microsecond: with the kernels loaded and the scan worked ahead, a first frame can take
        # under 0.5 ms, which the millisecond made 0 (a stress run of the suite failed on it)
        m["first_frame_s"] = round(loop.first_step_s, 6)
        m["finish_s"] = round(finish_s, 6)
        m["realtime_factor_after_first_frame"] = (round(n * scene.tracker.period_s / rest_s, 2)
                                                  if n > 0 and rest_s > 0 else None)
        m["time_per_frame_ms"] = ({k: round(v / n * 1e3, 4) for k, v in loop.stage_s.items()} if n > 0 else None)
        m["worked_ahead"] = loop.worked_ahead     # the scan and draws on a second thread (the times depend on it)
    if loop is not None and getattr(loop, "sky", None) is not None:
        # the multi-object tracker: per drone, false tracks, GOSPA (the single-target figures above are
        # of the scene's first target only, which the fovea serves only part of the time)
        from sim.sky_summary import sky_summary

        m["sky"] = sky_summary(loop, log)
    m["scene"] = scene.name
    m["seed"] = scene.seed
    m["effects"] = sorted(scene.effects)
    return m


def half_fov_deg(scene) -> float:
    """Half the scanner's smaller FoV [deg]: a target this far off the axis is "in the FoV" (the
    start of the acquisition clock; recorded in a recording's meta so that replay uses it too)."""
    return _half_fov_deg(scene.optics, scene.scan_model)


@functools.lru_cache(maxsize=16)
def _half_fov_deg(optics, scan_model: str) -> float:
    # A pure function of the optics (the noise-free pattern), ~25 ms: a recorded run asks twice
    # (recording meta, summary) and a study asks for every run of a scene.
    from sim.scan.fov import field_of_view_deg

    h, v = field_of_view_deg(optics, model=scan_model, samples=100_000)
    return 0.5 * min(h, v)
