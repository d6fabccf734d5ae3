"""Axis 8 -- the sky: what a closed-loop frame of the multi-object tracker costs against the number of
objects and of points, and what it tracks for it (issue 28).

Cases (:data:`CASES`), each over paired seeds (each seed its own world: the scene rebuilt from its
text, :func:`sim.scene.with_run_overrides`):

* objects: ``drone-and-flock`` (a Mid-40 at 100 k points/s, one drone) with its flock cut to 0, 5, 20
  and 80 birds; ``swarm-of-five``; the swarm with drone-and-flock's 20 birds added (issue 28's speed
  target: 150x real time);
* points: ``swarm-of-five`` scanned by a Horizon (240 k points/s) instead of its Mid-40.

Per run: the CPU time of the worker per frame (``time.process_time`` around the loop, after a
throwaway short run that loads the kernels), and of it the ray casting with the effects and the
tracker (the loop's own stage clocks, wall time); points and objects per frame; and what the
tracker made of it (:func:`sim.sky_summary.sky_summary`'s totals): drones confirmed within 2 s of
entering the field, id switches, false drone tracks and the mean GOSPA.  Recording off.
"""

from __future__ import annotations

import copy
import time
import tomllib
from dataclasses import dataclass

from sim.study.common import SCENES_DIR, seeds_for
from sim.study.stats import interval

#: (label, scene, birds (None: as shipped), another scene whose birds are added, lidar preset or None)
CASES = (
    ("drone-and-flock, 0 birds", "drone-and-flock", 0, None, None),
    ("drone-and-flock, 5 birds", "drone-and-flock", 5, None, None),
    ("drone-and-flock, 20 birds", "drone-and-flock", 20, None, None),
    ("drone-and-flock, 80 birds", "drone-and-flock", 80, None, None),
    ("swarm-of-five", "swarm-of-five", None, None, None),
    ("swarm-of-five + the 20-bird flock", "swarm-of-five", None, "drone-and-flock", None),
    ("swarm-of-five, Horizon (240 k points/s)", "swarm-of-five", None, None, "horizon"),
)
METRICS = ("ms_per_frame", "cast_ms_per_frame", "tracker_ms_per_frame", "points_per_frame", "objects",
           "confirmed_within_2s_share", "id_switches", "false_drone_tracks", "gospa_mean_m")


def sky_scene(name: str, duration_s: float, seed: int | None = None, birds: int | None = None,
              flock_of: str | None = None, preset: str | None = None):
    """A shipped sky scene, changed: its flock cut to ``birds`` (0: none), another scene's birds added
    (``flock_of``), another lidar (``preset``); at ``duration_s`` and ``seed`` (None: its own), both set
    in its table before it is built, so that what it draws when built (the flock's slots and wander,
    the crowns' sway over the run) follows them; the scene is built once."""
    from sim.scene import scene_from_mapping

    path = SCENES_DIR / f"{name}.toml"
    m = copy.deepcopy(tomllib.loads(path.read_text()))
    m["scene"]["duration_s"] = duration_s
    if seed is not None:
        m["scene"]["seed"] = seed
    if flock_of is not None:
        m["bird"] = tomllib.loads((SCENES_DIR / f"{flock_of}.toml").read_text())["bird"]
    if birds is not None:
        if birds == 0:
            m.pop("bird", None)
        else:
            m["bird"][0]["count"] = birds
    if preset is not None:
        m["lidar"] = {"preset": preset}
    return scene_from_mapping(m, str(path))


@dataclass(frozen=True)
class SkyObjectsTask:
    case: str
    seed: int
    duration_s: float

    axis = "objects"

    @property
    def cost_hint(self) -> float:
        return self.duration_s * 0.05

    @property
    def label(self) -> str:
        return self.case

    def run(self) -> dict:
        from sim.loop import ClosedLoop
        from sim.sky_summary import sky_summary

        _, name, birds, flock_of, preset = next(c for c in CASES if c[0] == self.case)
        # kernels loaded (the warm-up's end included), untimed
        ClosedLoop(sky_scene(name, 1.5, self.seed, birds, flock_of, preset)).run()
        scene = sky_scene(name, self.duration_s, self.seed, birds, flock_of, preset)
        loop = ClosedLoop(scene)
        c0 = time.process_time()
        log = loop.run()
        cpu = time.process_time() - c0
        frames = max(len(log["t_end_s"]), 1)
        timed = max(loop.steps_timed, 1)
        tot = sky_summary(loop, log)["totals"]
        return {"frames": frames, "cpu_s": cpu, "ms_per_frame": 1e3 * cpu / frames,
                "cast_ms_per_frame": 1e3 * loop.stage_s["ray casting + effects"] / timed,
                "tracker_ms_per_frame": 1e3 * loop.stage_s["tracker"] / timed,
                "points_per_frame": float(sum(log["points"])) / frames,
                "objects": len(scene.targets) + len(scene.others),
                "confirmed_within_2s_share": tot["confirmed_within_2s"] / max(tot["drones"], 1),
                "id_switches": tot["id_switches"], "false_drone_tracks": tot["false_drone_tracks"],
                "gospa_mean_m": tot["gospa_mean_m"], "period_s": scene.tracker.period_s}


def tasks(size) -> list[SkyObjectsTask]:
    """Every case on ``size.seeds`` paired seeds of ``size.levers_duration_s`` virtual seconds."""
    out = []
    for label, name, *_ in CASES:
        seed0 = tomllib.loads((SCENES_DIR / f"{name}.toml").read_text())["scene"]["seed"]
        out += [SkyObjectsTask(label, s, size.levers_duration_s) for s in seeds_for(seed0, size.seeds)]
    return out


def collect(results) -> dict:
    """Per case: each metric's interval over seeds, and the real-time factor of its mean CPU per frame."""
    rows = []
    for label, *_ in CASES:
        have = [(t, r) for t, r in results if t.case == label]
        if not have:
            continue
        row = {"case": label, "seeds": sorted(t.seed for t, _ in have), "ci": {}}
        for k in METRICS:
            row["ci"][k] = interval([r.get(k) for _, r in sorted(have, key=lambda x: x[0].seed)])
        ms = row["ci"]["ms_per_frame"]
        row["x_real_time"] = (1e3 * have[0][1]["period_s"] / ms["mean"]) if ms and ms["mean"] else None
        rows.append(row)
    duration = next((t.duration_s for t, _ in results), None)
    return {"duration_s": duration, "rows": rows}


__all__ = ["CASES", "METRICS", "SkyObjectsTask", "collect", "sky_scene", "tasks"]
