"""Axis 2 -- simulation fidelity: what the cheaper world models change in the tracking metrics.

Knobs of the closed loop (:class:`sim.loop.ClosedLoop`), each varied alone from the scene as shipped
(``baseline``: footprint as the scene lists it, target moving per point, head pose on a 1 ms grid),
plus the two corners of the box:

* beam footprint sub-rays: off, 3, 7, 15 (the beam's 0.28 x 0.03 deg divergence ellipse);
* target motion: ``per_point`` (each point sees the target at its own time) vs ``per_frame``
  (frozen at the frame's mid-time);
* head pose: exact at every point, asking the head model about each (``head_grid_s = 0``) or from
  its constant-acceleration pieces (``None``, the loop's default), vs interpolated from a 1, 10, 25 or
  50 ms grid (the loop shrinks the step so the grid ends exactly at the frame's end: it never asks the
  head about a time a later command could still change);
* ``all-exact`` (15 sub-rays, per point, exact head): the reference;
* ``all-cheap`` (no footprint, per frame, 25 ms grid).

Scenes: ``fig12-tracking`` and ``fast-crossing-close``, shortened (:data:`sim.study.common.FULL`).

Accuracy of a setting = how far its metrics land from the reference's *with the same seed*
(paired): ``|d error_rms_all|`` [deg] and ``|d points on target per frame|``, averaged over seeds.
Changing a knob changes how many random numbers the noise streams draw, so even a perfect
approximation moves the metrics by the run-to-run spread; that spread is measured as the
``noise floor``: the mean paired difference between the reference's runs with different seeds.
Cost = CPU seconds per virtual second.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

from sim.study.common import load_study_scene, run_loop, seeds_for, strip_private, with_footprint

# setting -> (footprint sub-rays or None = as the scene has it, target_motion, head_grid_s)
SETTINGS = {
    "baseline": (None, "per_point", 0.001),
    "footprint 3": (3, "per_point", 0.001),
    "footprint 7": (7, "per_point", 0.001),
    "footprint 15": (15, "per_point", 0.001),
    "per-frame target": (None, "per_frame", 0.001),
    "head exact": (None, "per_point", 0.0),
    "head exact pieces": (None, "per_point", None),   # the loop's default: exact, from the motion pieces
    "head 10 ms": (None, "per_point", 0.010),
    "head 25 ms": (None, "per_point", 0.025),
    "head 50 ms": (None, "per_point", 0.050),
    "all-exact": (15, "per_point", 0.0),
    "all-cheap": (0, "per_frame", 0.025),
}
REFERENCE = "all-exact"
SCENE_KEYS = ("fig12", "crossing")


@dataclass(frozen=True)
class FidelityTask:
    scene_key: str
    setting: str
    seed: int
    scene: object
    head_grid_s: float | None   # None: the exact pieces route (see sim.loop.ClosedLoop)
    target_motion: str

    axis = "fidelity"

    @property
    def cost_hint(self) -> float:
        c = self.scene.duration_s * (0.1 if self.scene_key == "fig12" else 0.05)
        return c * (8 if self.head_grid_s == 0 else 1)

    def run(self) -> dict:
        m = run_loop(self.scene, self.head_grid_s, self.target_motion)
        return strip_private(m)


def describe(scene) -> str:
    sub = scene.effect_params.get("footprint_subrays") if scene.has("beam_footprint") else None
    return "off" if sub is None else f"{sub} sub-rays"


def tasks(size) -> list[FidelityTask]:
    out = []
    for key in SCENE_KEYS:
        base = replace(load_study_scene(key), duration_s=size.fidelity_duration_s[key])
        for seed in seeds_for(base.seed, size.seeds):
            sc = replace(base, seed=seed)
            for name, (sub, motion, grid) in SETTINGS.items():
                s = sc if sub is None else with_footprint(sc, sub)
                out.append(FidelityTask(key, name, seed, s, grid, motion))
    return out


METRICS = ("error_rms_all_deg", "points_on_target_per_frame", "detect_frac")


def collect(results) -> dict:
    """Per scene: each setting's mean metrics and cost, and its paired deviation from the reference."""
    out = {}
    for key in SCENE_KEYS:
        runs = {(t.setting, t.seed): (t, r) for t, r in results if t.scene_key == key}
        if not runs:
            continue
        seeds = sorted({s for _, s in runs})
        rows = []
        for name, (sub, motion, grid) in SETTINGS.items():
            have = [runs[(name, s)] for s in seeds if (name, s) in runs]
            if not have:
                continue
            row = {"setting": name, "footprint": describe(have[0][0].scene), "target_motion": motion,
                   "head_grid_ms": None if grid is None else grid * 1000, "seeds": len(have)}
            for k in METRICS + ("cpu_per_virtual_s", "cpu_s", "wall_s", "error_rms_acq_deg"):
                vals = [r[k] for _, r in have if r.get(k) is not None]
                row[k] = float(np.mean(vals)) if vals else None
            for k in METRICS:
                diffs = [abs(runs[(name, s)][1][k] - runs[(REFERENCE, s)][1][k]) for s in seeds
                         if (name, s) in runs and (REFERENCE, s) in runs]
                row[f"d_{k}"] = float(np.mean(diffs)) if diffs else None
            rows.append(row)
        floor = {}
        ref = [runs[(REFERENCE, s)][1] for s in seeds if (REFERENCE, s) in runs]
        for k in METRICS:
            pairs = [abs(a[k] - b[k]) for a, b in combinations(ref, 2)]
            floor[k] = float(np.mean(pairs)) if pairs else None
        scene = next(t.scene for t, _ in runs.values())
        out[key] = {"scene": scene.name, "duration_s": scene.duration_s, "seeds": seeds, "rows": rows,
                    "noise_floor": floor, "reference": REFERENCE}
    return out


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = CPU s per virtual s, error = |d tracking error rms| from the reference) per scene."""
    pts = []
    for key, res in axis_result.items():
        for r in res["rows"]:
            pts.append({"group": res["scene"], "label": r["setting"], "cost": r["cpu_per_virtual_s"],
                        "error": r["d_error_rms_all_deg"], "offered": True})
    return pts
