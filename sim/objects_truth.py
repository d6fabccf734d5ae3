"""The truth of every object of a multi-object scene, frame by frame: what the perception half is
scored against (the ``/truth_objects`` records of a recording, :class:`foveatrack.recording.records.
ObjectTruthRecord`; ``ClosedLoop.objects_log`` in process).

Objects: each ``[[target]]`` (class "drone", or "clutter" if the scene says so), each bird and tree
crown (:mod:`sim.world.sky`), and each stray near return of the frame (class "clutter", ids
``stray-N`` numbered through the run, size 0).  Position and velocity at frame mid [m, m/s, world].
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from itertools import chain
from typing import NamedTuple

import numpy as np


class ObjectTruth(NamedTuple):
    """One object at a frame's mid time (a named tuple: made ~25 times a frame, four times quicker than
    a frozen dataclass)."""
    id: str
    cls: str
    xyz_m: tuple
    velocity_m_s: tuple
    size_m: float
    rays_hit: int


# ObjectTruth(*fields) without the named tuple's Python-level __new__ (what it calls: tuple.__new__
# on the fields), so that a frame's ~25 are made by map and zip in C (~1 us an object before)
_truth_from_fields = partial(tuple.__new__, ObjectTruth)


def target_size_m(spec) -> float:
    """A drone's size for the truth: twice its bounding radius (a quadrotor's tip-to-tip span)."""
    return 2.0 * float(spec.body.bounding_radius_m)


class ObjectsTruth:
    """The truth of a scene's objects frame by frame; what does not change over a run (ids, classes,
    trajectories, sizes: a quadrotor's bounding radius walks its primitives) is gathered once."""

    def __init__(self, scene):
        from sim.world.sky import FlockPoses

        self.objects = [(s.id, s.cls, s.trajectory, target_size_m(s)) for s in scene.targets]
        self.objects += [(o.id, o.cls, o.trajectory, float(o.size_m)) for o in scene.others]
        self._ids, self._classes, _, self._sizes = zip(*self.objects) if self.objects else ((), (), (), ())
        # a flock's velocities in one evaluation (the same values as each bird's own)
        n_t = len(scene.targets)
        self._flocks = [(n_t + a, n_t + b, FlockPoses(scene.others[a:b])) for a, b in FlockPoses.groups(scene.others)]

    def at(self, t_mid_s: float, object_rays, strays_m: np.ndarray, stray_count: int,
           mid_xyz_m=None, mid_velocity=None) -> list[ObjectTruth]:
        """The truth of each object at ``t_mid_s``; ``object_rays``: rays that hit each object this
        frame (drones then others, :attr:`sim.sensor.SceneSensor.last_object_rays`), ``strays_m`` the
        frame's stray returns (world), numbered from ``stray_count``; ``mid_xyz_m``, ``mid_velocity``:
        each object's position and velocity at ``t_mid_s`` as [x, y, z] lists of floats where already
        computed (the sensor's cull has them, None for a velocity it did not ask: the same calls, the
        same bits)."""
        t = np.array([t_mid_s])
        n_obj = len(self.objects)
        rays = (np.zeros(n_obj, dtype=np.int64) if object_rays is None else object_rays).tolist()
        xyz = ([traj.position(t)[0].tolist() for _, _, traj, _ in self.objects] if mid_xyz_m is None
               else mid_xyz_m)
        vel: list = [None] * n_obj if mid_velocity is None else list(mid_velocity)
        for a, b, flock in self._flocks:
            if None in vel[a:b]:
                vel[a:b] = flock.velocities(np.arange(b - a), np.full(b - a, t_mid_s)).tolist()
        if None in vel:
            vel = [self.objects[k][2].velocity(t)[0].tolist() if v is None else v for k, v in enumerate(vel)]
        out = list(map(_truth_from_fields, zip(self._ids, self._classes, map(tuple, xyz), map(tuple, vel), self._sizes,
                                               rays)))
        for k, p in enumerate(strays_m):
            out.append(ObjectTruth(f"stray-{stray_count + k}", "clutter", tuple(float(x) for x in p), (0.0, 0.0, 0.0),
                                   0.0, 1))
        return out


def _rows(flat: tuple) -> list[tuple]:
    """``(x0, y0, z0, x1, ...)`` as ``[(x0, y0, z0), (x1, ...), ...]`` (the same floats)."""
    it = iter(flat)
    return list(zip(it, it, it))


class TruthLog(Sequence):
    """``ClosedLoop.objects_log``: per frame, the list of :class:`ObjectTruth` of
    :meth:`ObjectsTruth.at`, built when read from what the frame kept (:meth:`append`).

    A frame keeps its mid time, the rays per object and the stray returns (arrays), and the positions
    and velocities the sensor's cull evaluated as one flat tuple of floats each (x0, y0, z0, x1, ...;
    rows where a velocity is None): all of it the cyclic collector stops tracking at its first pass.
    Kept as ~25 named tuples a frame (a tuple subclass is tracked for good), the truth of the swarm
    with the flock was two thirds of the objects the collector walked over a run, and most of its
    ~0.1 ms a frame; as a tuple per object, ~55 of the ~125 containers a frame allocated (what
    triggers the collector's young passes).  Reading a frame calls
    :meth:`ObjectsTruth.at` on what it kept: the same objects, each read building them anew (a
    recording reads each frame's once, ``ClosedLoop.last_objects``; a study's summary, every frame
    once at the end).  Equal to any sequence of the same frames' lists."""

    def __init__(self, scene):
        self._scene = scene
        self._truth: ObjectsTruth | None = None
        self._frames: list[tuple] = []

    def append(self, t_mid_s: float, object_rays, strays_m: np.ndarray, stray_count: int, mid_xyz_m=None,
               mid_velocity=None) -> None:
        """Keep a frame's truth: :meth:`ObjectsTruth.at`'s arguments (its lists of floats as tuples)."""
        if self._truth is None:
            self._truth = ObjectsTruth(self._scene)
        xyz = None if mid_xyz_m is None else tuple(chain.from_iterable(mid_xyz_m))
        if mid_velocity is None:
            vel, flat = None, False
        elif None in mid_velocity:     # rows kept as rows: a missing velocity stays None
            vel, flat = tuple(None if v is None else tuple(v) for v in mid_velocity), False
        else:
            vel, flat = tuple(chain.from_iterable(mid_velocity)), True
        self._frames.append((float(t_mid_s), object_rays, strays_m, int(stray_count), xyz, vel, flat))

    def _frame(self, record: tuple) -> list[ObjectTruth]:
        t, rays, strays, count, xyz, vel, flat = record
        return self._truth.at(t, rays, strays, count, None if xyz is None else _rows(xyz),
                              _rows(vel) if flat else vel)

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self._frame(r) for r in self._frames[k]]
        return self._frame(self._frames[k])

    def __iter__(self):
        return map(self._frame, self._frames)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, (str, bytes)):
            return NotImplemented
        return len(other) == len(self) and all(a == b for a, b in zip(self, other))

    __hash__ = None

    def __repr__(self) -> str:
        return f"TruthLog({len(self)} frames)"
