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

Scenes: ``fig12-tracking`` and ``far-target-range-limit`` (a 0.8 m UAV at 140 m that the tracker
holds from the start), shortened (:data:`sim.study.common.FULL`).  ``fast-crossing-close`` is not
used: the tracker never acquires it, so every setting's error there is the crossing's geometry.

Accuracy of a setting = how far its metrics land from the reference's *with the same seed*
(paired): the signed difference per seed and its 95 % interval over seeds
(:func:`sim.study.stats.paired_delta`), for the tracking error over all frames and after
acquisition, the acquisition time and the points on target.  Changing a knob changes how many random
numbers the noise streams draw, so even a perfect approximation moves the metrics by the run-to-run
spread: a setting changes a metric only where the interval excludes zero.  The seed-to-seed
``noise floor`` (mean paired difference between the reference's runs with different seeds) is kept
beside it.  Cost = CPU seconds per virtual second, and its ratio to the reference's on the same
seed (both measured in the same study run).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

from sim.study.common import load_study_scene, run_loop, seeds_for, strip_private, with_footprint
from sim.study.stats import abs_bounds, interval, paired_delta, paired_ratio

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
SCENE_KEYS = ("fig12", "far")


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


METRICS = ("error_rms_all_deg", "error_rms_acq_deg", "acquisition_s", "points_on_target_per_frame", "detect_frac")


def collect(results) -> dict:
    """Per scene: each setting's metrics and cost (mean, and interval over seeds, per-seed values
    kept), and its paired deviation from the reference."""
    out = {}
    for key in SCENE_KEYS:
        runs = {(t.setting, t.seed): (t, r) for t, r in results if t.scene_key == key}
        if not runs:
            continue
        seeds = sorted({s for _, s in runs})
        by_seed = {name: {s: runs[(name, s)][1] for s in seeds if (name, s) in runs} for name in SETTINGS}
        ref = by_seed[REFERENCE]
        rows = []
        for name, (sub, motion, grid) in SETTINGS.items():
            have = by_seed[name]
            if not have:
                continue
            first_task = runs[(name, min(have))][0]
            row = {"setting": name, "footprint": describe(first_task.scene), "target_motion": motion,
                   "head_grid_ms": None if grid is None else grid * 1000, "seeds": len(have), "ci": {}, "delta": {}}
            for k in METRICS + ("cpu_per_virtual_s", "cpu_s", "wall_s"):
                iv = interval([have[s].get(k) for s in sorted(have)])
                row[k] = None if iv is None else iv["mean"]
                row["ci"][k] = iv
            for k in METRICS:
                row["delta"][k] = paired_delta({s: r.get(k) for s, r in have.items()},
                                               {s: r.get(k) for s, r in ref.items()})
                diffs = [abs(have[s][k] - ref[s][k]) for s in seeds if s in have and s in ref
                         and have[s].get(k) is not None and ref[s].get(k) is not None]
                row[f"d_{k}"] = float(np.mean(diffs)) if diffs else None
            row["cost_ratio"] = paired_ratio({s: r["cpu_per_virtual_s"] for s, r in have.items()},
                                             {s: r["cpu_per_virtual_s"] for s, r in ref.items()})
            rows.append(row)
        floor = {}
        ref_runs = [ref[s] for s in seeds if s in ref]
        for k in METRICS:
            pairs = [abs(a[k] - b[k]) for a, b in combinations(ref_runs, 2) if a.get(k) is not None and b.get(k) is not None]
            floor[k] = float(np.mean(pairs)) if pairs else None
        scene = next(t.scene for t, _ in runs.values())
        out[key] = {"scene": scene.name, "duration_s": scene.duration_s, "seeds": seeds, "rows": rows,
                    "noise_floor": floor, "reference": REFERENCE}
    return out


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = CPU relative to the reference on the same seed, error = |paired change of the tracking
    error rms over all frames|), each with its interval, per scene."""
    pts = []
    for key, res in axis_result.items():
        for r in res["rows"]:
            d, c = r["delta"].get("error_rms_all_deg"), r["cost_ratio"]
            if d is None or c is None:
                continue
            lo, hi = abs_bounds(d)
            pts.append({"group": res["scene"], "label": r["setting"], "cost": c["mean"], "cost_lo": c["lo"],
                        "cost_hi": c["hi"], "error": abs(d["mean"]), "error_lo": lo, "error_hi": hi,
                        "offered": True})
    return pts
