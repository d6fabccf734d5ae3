"""What a speed-table calibration is asked to do and what it reports (paper Appendix D.4): the plan
(bytes, timing), the feature to track, the legs run and the report."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from foveatrack.errors import UserError
from foveatrack.speed_table import TURBO, axis_bytes

DEFAULT_BYTES = (0, 1, 2, 3, 4, 6, 8, 10, 12, 16, 20, 24, 28, 32, 40, 48, 56, 63)


@dataclass(frozen=True)
class FeatureSpec:
    """The known feature: an inside room corner (three planes).

    approx_xyz : (3,) [m]  where the corner is in the lidar frame at the start (within radius_m)
    radius_m : > 0 [m]     points this close to the predicted corner are used
    plane_tol_m : > 0 [m]  RANSAC inlier distance
    min_plane_points : int minimum inliers per plane
    ransac_iters : int     hypotheses per plane
    """

    approx_xyz: tuple[float, float, float]
    radius_m: float = 0.6
    plane_tol_m: float = 0.03
    min_plane_points: int = 25
    ransac_iters: int = 80


@dataclass(frozen=True)
class CalibrationPlan:
    """Which bytes and how long.  Bytes not listed are interpolated by the table (documented subset).

    dwell_s [s] max per leg; settle_s [s] discarded after each command (dead time + acceleration);
    rest_s [s] stopped between legs; max_excursion_deg keeps the corner inside the FoV;
    reference_s [s] static frames at the start; min_samples per leg fit; start_tilt_deg prior for
    the pan axis if the legs cannot tell it; latency_s subtracted from the measured delays (the link
    part, which the Reconstructor adds itself); return_tol_deg for the final return.
    min_steady_samples: an OUT leg stopped at the excursion limit with fewer frames after its ramp
    (``Calibrator._ramp_end_s``) is run again from the far side of the start (the BACK leg's
    coast): the byte's run-up then lies behind the start and the steady part spans the excursion.
    max_rest_s [s]: a rest lasts rest_s and, if the corner still moves then (a fast leg's
    deceleration outlasts rest_s), until it stops, at most this long.
    """

    pan_bytes: tuple[int, ...] = DEFAULT_BYTES + (TURBO,)
    tilt_bytes: tuple[int, ...] = DEFAULT_BYTES
    dwell_s: float = 6.0
    settle_s: float = 0.5
    rest_s: float = 0.5
    max_excursion_deg: float = 15.0
    reference_s: float = 1.0
    min_samples: int = 4
    start_tilt_deg: float = 0.0
    latency_s: float = 0.0
    return_tol_deg: float = 0.3
    min_steady_samples: int = 8
    max_rest_s: float = 1.5

    def __post_init__(self) -> None:
        for axis, bs in (("pan", self.pan_bytes), ("tilt", self.tilt_bytes)):
            bad = [b for b in bs if b not in axis_bytes(axis)]
            if bad:
                said = ", ".join("turbo" if b == 255 else str(b) for b in bad)
                raise UserError(f"calibration plan: {axis} bytes {said} not allowed (0..63"
                                + (", turbo" if axis == "pan" else "; the tilt has no turbo") + ")")
        if not (self.dwell_s > self.settle_s >= 0 and self.max_excursion_deg > 0):
            raise UserError("calibration plan: need dwell_s > settle_s >= 0 and max_excursion_deg > 0")


@dataclass
class LegRecord:
    axis: str
    byte: int
    direction: int
    t_cmd_s: float
    t_stop_s: float | None = None
    ref_q: np.ndarray | None = None          # corner position at rest before the leg (lidar)
    samples: list = field(default_factory=list)   # (t_s, q (3,))
    derot_deg_s: list = field(default_factory=list)   # per sample: the rate its frame was de-rotated with
    end: str = ""                            # why it stopped: excursion, dwell, lost, reference, time
    repeat: bool = False                     # the sweep's second run of the byte (from the far side)


@dataclass
class CalibrationReport:
    """What a calibration measured beside its table, and what its user must hear.

    ``warnings``: sentences about a table that was written but may be wrong, or about the set-up
    that made it (each says what was seen and what to do); every place that shows the report
    prints them (``foveatrack calibrate``, text and ``--json``).
    """

    unmeasured: dict            # axis -> {byte: reason}
    axis_lidar: dict            # axis -> unit vector (rotation axis in lidar coords)
    implied_start_tilt_deg: float | None
    asymmetry: dict             # axis -> {byte: (v_out, v_back)}
    dead_time_s: float
    accel_deg_s2: float | None
    frames: int
    frames_with_feature: int
    warnings: tuple[str, ...] = ()
