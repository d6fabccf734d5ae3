"""The channels and fields one tracker frame is recorded with — shared by the daemon and the simulator,
so that ``foveatrack replay`` reads both the same way.

Per frame (``t_ns`` = frame end): points (lidar frame), the detection (``detected``, ``xyz_m``,
``n_points``, ``t_s``, ``az_deg``, ``el_deg``, ``state``, ``error_pan_deg``, ``error_tilt_deg``) and
the head estimate (``pan_deg``, ``tilt_deg``, sigmas, ``world_xyz_m``, ``world_sigma_m``).  Commands,
truth and metrics are written by each driver, which knows what it sent and measured.
"""

from __future__ import annotations

import math


def ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def finite_or_none(v):
    """JSON has no NaN: a missing or non-finite float is recorded as null."""
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v


def write_tracker_frame(writer, frame_id: int, frame, out) -> int:
    """Record one frame and the tracker's output for it; returns the frame-end time [ns]."""
    t_end = ns(frame.t_end_s)
    writer.write_points(t_end, frame_id, frame.xyz, frame.t_ns, frame.reflectivity)
    d = out.detection
    writer.write_detection(
        t_end, frame_id, d is not None, None if d is None else [float(v) for v in d.xyz],
        0 if d is None else int(d.n_points),
        t_s=None if d is None else float(d.t_s), az_deg=None if d is None else float(d.az_deg),
        el_deg=None if d is None else float(d.el_deg), state=str(out.state.value),
        error_pan_deg=finite_or_none(out.error_pan_deg), error_tilt_deg=finite_or_none(out.error_tilt_deg))
    writer.write_head_estimate(
        t_end, out.head_pan_deg, out.head_tilt_deg, frame_id=frame_id, sigma_pan_deg=out.head_sigma_pan_deg,
        sigma_tilt_deg=out.head_sigma_tilt_deg,
        world_xyz_m=None if out.world_xyz is None else [float(v) for v in out.world_xyz],
        world_sigma_m=finite_or_none(out.world_sigma_m))
    return t_end
