"""The truth of every object of a multi-object scene, frame by frame: what the perception half is
scored against (the ``/truth_objects`` records of a recording, :class:`foveatrack.recording.records.
ObjectTruthRecord`; ``ClosedLoop.objects_log`` in process).

Objects: each ``[[target]]`` (class "drone", or "clutter" if the scene says so), each bird and tree
crown (:mod:`sim.world.sky`), and each stray near return of the frame (class "clutter", ids
``stray-N`` numbered through the run, size 0).  Position and velocity at frame mid [m, m/s, world].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ObjectTruth:
    id: str
    cls: str
    xyz_m: tuple
    velocity_m_s: tuple
    size_m: float
    rays_hit: int


def target_size_m(spec) -> float:
    """A drone's size for the truth: twice its bounding radius (a quadrotor's tip-to-tip span)."""
    return 2.0 * float(spec.body.bounding_radius_m)


def objects_truth(scene, t_mid_s: float, object_rays, strays_m: np.ndarray, stray_count: int) -> list[ObjectTruth]:
    """The truth of each object at ``t_mid_s``; ``object_rays``: rays that hit each object this frame
    (drones then others, :attr:`sim.sensor.SceneSensor.last_object_rays`), ``strays_m`` the frame's
    stray returns (world), numbered from ``stray_count``."""
    t = np.array([t_mid_s])
    out = []
    rays = np.zeros(len(scene.targets) + len(scene.others), dtype=np.int64) if object_rays is None else object_rays
    objs = [(s.id, s.cls, s.trajectory, target_size_m(s)) for s in scene.targets]
    objs += [(o.id, o.cls, o.trajectory, o.size_m) for o in scene.others]
    for (oid, cls, traj, size), n in zip(objs, rays):
        p = traj.position(t)[0]
        v = traj.velocity(t)[0]
        out.append(ObjectTruth(oid, cls, tuple(float(x) for x in p), tuple(float(x) for x in v), float(size), int(n)))
    for k, p in enumerate(strays_m):
        out.append(ObjectTruth(f"stray-{stray_count + k}", "clutter", tuple(float(x) for x in p), (0.0, 0.0, 0.0),
                               0.0, 1))
    return out


