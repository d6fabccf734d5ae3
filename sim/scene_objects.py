"""What every moving object of a scene is read with: its id, its trajectory table, the cap on their
number.  Shared by the drones' reader (:mod:`sim.scene`) and the birds' and trees' (:mod:`sim.scene_sky`),
so neither imports the other for it."""

from __future__ import annotations

from typing import Mapping

from foveatrack.config_util import as_choice, as_float, as_vec, check_keys
from foveatrack.errors import UserError

TRAJECTORY_TYPES = ("straight", "circle", "figure8", "waypoints", "manual")
# A scene is read from a file someone may have made by mistake or on purpose: every object is ray-cast
# for every beam, so their count is capped (a swarm of birds fits).
MAX_TARGETS = 256


def object_id(v, w: str) -> str:
    """A scene object's id: a short name without spaces or slashes (a flock's birds are ``id/k``)."""
    if not isinstance(v, str) or not v or len(v) > 64 or any(c.isspace() or c == "/" for c in v):
        raise UserError(f"{w}: id must be a name of 1-64 characters without spaces or '/', got {v!r}")
    return v


def trajectory_from_table(traj, w: str, table: str, duration_s: float, seed: int):
    """The ``[<table>.trajectory]`` of a scene object (a drone, a flock's centre)."""
    from sim.world import trajectories as tr

    wt = f"{w}.trajectory"
    if not isinstance(traj, Mapping):
        raise UserError(f"{w}: missing [{table}.trajectory] table (type = {' | '.join(TRAJECTORY_TYPES)})")
    kind = as_choice(traj.get("type"), "type", wt, TRAJECTORY_TYPES)
    keys = {
        "straight": ["start_m", "velocity_m_s"],
        "circle": ["centre_m", "radius_m", "speed_m_s", "start_deg"],
        "figure8": ["centre_m", "size_m", "period_s"],
        "waypoints": ["points_m", "speed_m_s"],
        "manual": ["centre_m", "radius_m", "max_speed_m_s", "max_accel_m_s2", "tau_s"],
    }[kind]
    check_keys(traj, ["type"] + keys, wt)
    required = [k for k in keys if k not in ("start_deg", "tau_s")]
    missing = [k for k in required if k not in traj]
    if missing:
        raise UserError(f"{wt}: type {kind!r} needs {', '.join(missing)}")
    v3 = lambda k: as_vec(traj[k], k, wt, 3)  # noqa: E731
    pos = lambda k, **a: as_float(traj[k], k, wt, lo=0, lo_open=True, **a)  # noqa: E731
    if kind == "straight":
        trajectory = tr.Straight(v3("start_m"), v3("velocity_m_s"))
    elif kind == "circle":
        trajectory = tr.Circle(v3("centre_m"), pos("radius_m"), as_float(traj["speed_m_s"], "speed_m_s", wt),
                               as_float(traj.get("start_deg", 0.0), "start_deg", wt))
    elif kind == "figure8":
        trajectory = tr.FigureEight(v3("centre_m"), pos("size_m"), pos("period_s"))
    elif kind == "waypoints":
        pts = traj["points_m"]
        if not isinstance(pts, list) or len(pts) < 2:
            raise UserError(f"{wt}: points_m must be a list of at least 2 [x, y, z] points")
        pts3 = tuple(as_vec(p, f"points_m[{i}]", wt, 3) for i, p in enumerate(pts))
        for i in range(1, len(pts3)):
            if pts3[i] == pts3[i - 1]:
                raise UserError(f"{wt}: points_m[{i}] repeats points_m[{i - 1}]; consecutive waypoints must differ")
        trajectory = tr.Waypoints(pts3, pos("speed_m_s"))
    else:
        trajectory = tr.Manual(v3("centre_m"), pos("radius_m"), pos("max_speed_m_s", hi=20), pos("max_accel_m_s2"),
                               duration_s, seed, as_float(traj.get("tau_s", 1.5), "tau_s", wt, lo=0, lo_open=True))
    if trajectory.max_speed_m_s > 20.0 + 1e-9:
        raise UserError(f"{wt}: the target flies at up to {trajectory.max_speed_m_s:.1f} m/s; the model covers <= 20 m/s")
    return trajectory
