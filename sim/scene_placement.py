"""Where a scene's drones and birds fly against its ground and the head, checked on load.

The world's origin is the head's rotation centre, the lidar on it (docs/scenes.md), and a
``[[background]] type = "ground"`` is a plane ``height_m`` below it.  The simulator flies whatever
path a file gives: a drone given the wrong sign on z flies under the ground, hidden by it from the
head, and one placed at the head sits in the lidar's blind zone (no return is nearer than ``[lidar]
min_range_m``); either run tracks nothing and says nothing about why.  :func:`placement_problems` samples every ``[[target]]``'s and bird's path over
the run and names the first instant and position at fault:

* a warning where an object is below the ground, or in the blind zone, at some instant;
* an error where a ``[[target]]`` is so for the whole run: the head can never see it, and the run's
  figures (acquisition, tracking error) would be about nothing.  A bird only warns: it is clutter.
"""

from __future__ import annotations

import math

import numpy as np

from sim.world.kernels import PLANE, PRIM_COLUMNS
from sim.world.trajectories import numpy_paths

SAMPLE_S = 0.1              # the tracker's frame at 10 Hz: a drone at 20 m/s moves 2 m in it
MAX_SAMPLES = 100_001       # a two-day scene is sampled every ~1.7 s (its check stays a few ms)


def ground_z_m(background_prims: np.ndarray) -> float | None:
    """The height of the highest ground plane (a ``PLANE`` facing up: ``[[background]] type =
    "ground"``) in the world frame [m], None without one."""
    p = np.asarray(background_prims, float).reshape(-1, PRIM_COLUMNS)
    up = p[(p[:, 0] == PLANE) & (p[:, 9] > 0.0)]
    return float(up[:, 3].max()) if len(up) else None


def placement_problems(scene) -> tuple[list[str], list[str]]:
    """``(errors, warnings)`` of a :class:`sim.scene.Scene`'s drones and birds (module docstring).
    The paths are sampled in numpy (:func:`sim.world.trajectories.numpy_paths`): a load compiles no
    numba kernel."""
    with numpy_paths():
        return _placement_problems(scene)


def _placement_problems(scene) -> tuple[list[str], list[str]]:
    n = min(MAX_SAMPLES, max(2, int(math.ceil(scene.duration_s / SAMPLE_S)) + 1))
    t = np.linspace(0.0, scene.duration_s, n)
    ground = ground_z_m(scene.background_prims)
    blind_m = scene.lidar_range_m[0]
    errors, warnings = [], []
    for i, spec in enumerate(scene.targets):
        what = f"{scene.path} [[target]] #{i + 1} ({spec.id})"
        for whole_run, text in _faults(what, spec.trajectory.position(t), t, ground, blind_m):
            (errors if whole_run else warnings).append(text)
    flocks_seen = set()
    for o in scene.others:
        flock = o.id.split("/")[0]
        if o.cls != "bird" or flock in flocks_seen:
            continue
        what = f"{scene.path} [[bird]] {flock}" + (f" (its bird {o.id})" if o.id != flock else "")
        found = [text for _, text in _faults(what, o.trajectory.position(t), t, ground, blind_m)]
        if found:
            flocks_seen.add(flock)      # a flock's first bird at fault speaks for it
            warnings.extend(found)
    return errors, warnings


def _faults(what: str, pos: np.ndarray, t: np.ndarray, ground: float | None, blind_m: float):
    """``(whole_run, message)`` for each way ``pos`` (at times ``t``) is at fault."""
    checks = []
    if ground is not None:
        # below by a micrometre or more: a path that ends on the ground is not under it (its rounding:
        # 0.9 - 0.8 x 3.0 = -1.5000000000000004)
        checks.append((pos[:, 2] < ground - 1e-6, "below the ground", lambda p: (
            f"{ground - p[2]:.2f} m below the ground plane ({-ground:g} m below the head)"),
            "the ground hides it from the head (the simulator flies it through the ground)"))
    r = np.sqrt((pos * pos).sum(axis=1))
    checks.append((r < blind_m, "inside the lidar's blind zone", lambda p: (
        f"{math.sqrt(float(p @ p)):.2f} m from the head's rotation centre (min_range_m {blind_m:g} m)"),
        "no return comes from it there"))
    for bad, name, detail, effect in checks:
        if not bad.any():
            continue
        k = int(np.argmax(bad))
        p = pos[k]
        at = f"at t = {t[k]:g} s at [{', '.join(f'{round(float(v), 2):g}' for v in p)}] m, {detail(p)}"
        if bad.all():
            yield True, (f"{what} is {name} for the whole run ({t[-1]:g} s; {at}): {effect}, and the head can "
                         "never see it; move its trajectory (world frame: origin at the head, x forward, y left, "
                         "z up)")
        else:
            yield False, f"{what} is {name}, first {at}: {effect}"
