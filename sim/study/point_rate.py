"""Axis 5 -- point rate / channels: Mid-40 (100 k points/s, one channel) vs Horizon (240 k/s, six).

The same scenes (``fig12-tracking`` and ``far-target-range-limit``, shortened) with the lidar swapped
(``Scene.optics``); everything else as shipped.  Measured: tracking error (rms over all frames,
and after acquisition), points on the target per frame, detections; and compute per frame, split
into the tracker's own CPU time (``Tracker.process``: the part that runs on real hardware, which
grows with the points per frame) and the whole simulated frame (scan, head, ray casting, effects,
tracker).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from sim.study.common import load_study_scene, run_loop, seeds_for, strip_private
from sim.study.stats import interval

SCENE_KEYS = ("fig12", "far")
PRESETS = ("mid40", "horizon")


@dataclass(frozen=True)
class RateTask:
    scene_key: str
    preset: str
    seed: int
    scene: object

    axis = "rate"

    @property
    def cost_hint(self) -> float:
        return self.scene.duration_s * (0.1 if self.preset == "mid40" else 0.25)

    def run(self) -> dict:
        m = strip_private(run_loop(self.scene, time_tracker=True))
        frames = max(m["frames"], 1)
        m.update(sim_ms_per_frame=1000 * m["cpu_s"] / frames, tracker_ms_per_frame=1000 * m["tracker_cpu_s"] / frames)
        return m


def tasks(size) -> list[RateTask]:
    from sim.scan.presets import PRESETS as OPTICS

    out = []
    for key in SCENE_KEYS:
        base = replace(load_study_scene(key), duration_s=size.rate_duration_s[key])
        for seed in seeds_for(base.seed, size.seeds):
            for p in PRESETS:
                out.append(RateTask(key, p, seed, replace(base, seed=seed, optics=OPTICS[p])))
    return out


KEYS = ("error_rms_all_deg", "error_rms_acq_deg", "acquisition_s", "detect_frac", "points_on_target_per_frame",
        "points_per_frame", "sim_ms_per_frame", "tracker_ms_per_frame")


def collect(results) -> dict:
    out = {}
    for key in SCENE_KEYS:
        rows = []
        for p in PRESETS:
            runs = [r for t, r in results if t.scene_key == key and t.preset == p]
            if not runs:
                continue
            row = {"preset": p, "seeds": len(runs), "ci": {}}
            for k in KEYS:
                iv = interval([r.get(k) for r in runs])
                row[k] = None if iv is None else iv["mean"]
                row["ci"][k] = iv
            rows.append(row)
        scene = next((t.scene for t, _ in results if t.scene_key == key), None)
        if scene is not None:
            out[key] = {"scene": scene.name, "duration_s": scene.duration_s, "rows": rows}
    return out


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = tracker CPU ms per frame, error = tracking error rms over all frames), each with its
    interval over seeds, per scene."""
    pts = []
    for res in axis_result.values():
        for r in res["rows"]:
            c, e = r["ci"]["tracker_ms_per_frame"], r["ci"]["error_rms_all_deg"]
            if c is None or e is None:
                continue
            pts.append({"group": res["scene"], "label": r["preset"], "cost": c["mean"], "cost_lo": c["lo"],
                        "cost_hi": c["hi"], "error": e["mean"], "error_lo": e["lo"], "error_hi": e["hi"],
                        "sim_ms_per_frame": r["sim_ms_per_frame"], "offered": True})
    return pts
