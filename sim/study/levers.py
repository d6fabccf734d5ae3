"""Axis 6 -- the levers: what each big choice of the closed loop buys in accuracy and costs in time.

Each lever changed alone from ``fig12-tracking`` as shipped (the paper's Algorithm 2, the unit's
true speed table, no recording; the **reference**), with the same seeds:

* ``predictive controller``: the constant-velocity bearing filter with a feed-forward rate instead
  of Algorithm 2 (``[tracker] controller = "predictive"``);
* ``recording on``: the run written to a Foxglove MCAP on the loop's thread (what ``simulate --out``
  costs without the writer process);
* ``head ripple``: the head's speed ripple (``effects += ["head_ripple"]``);
* ``paraxial scan model``: the scan traced by the paraxial vector sum instead of exact refraction;
* ``IMU, commands`` / ``IMU, gyro``: a BMI088-like IMU on the head (:mod:`sim.attitude_study`), the
  head attitude dead-reckoned from the commands or integrated from the gyro;
* ``nominal speed table``: the tracker's dead reckoning from the head's linear nominal table (no
  calibration) instead of the unit's own curve.

End metrics per run: the tracking error rms after acquisition and over all frames, the acquisition
time and the world position error of the reconstructed target (what the speed table buys: the
pointing hardly moves, the world position does).  Each as mean, 95 % interval over seeds and the
paired change against the reference (:mod:`sim.study.stats`); cost as CPU seconds per virtual
second and its ratio to the reference's on the same seed.
"""

from __future__ import annotations

import copy
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path

from sim.study.common import SCENES_DIR, SCENE_FILES, run_loop, seeds_for, strip_private
from sim.study.stats import interval, paired_delta, paired_ratio

REFERENCE = "paper controller (as shipped)"
LEVERS = (REFERENCE, "predictive controller", "recording on", "head ripple", "paraxial scan model",
          "IMU, commands", "IMU, gyro", "nominal speed table")
METRICS = ("error_rms_acq_deg", "error_rms_all_deg", "acquisition_s", "recon_rms_m", "cpu_per_virtual_s")


def lever_scene(lever: str, duration_s: float, seed: int):
    """fig12-tracking with one lever changed (see the module docstring), at ``duration_s`` and ``seed``."""
    from sim.scene import scene_from_mapping

    path = SCENES_DIR / SCENE_FILES["fig12"]
    if lever.startswith("IMU, "):
        from sim.attitude_study import scene_variant

        attitude = "gyro" if lever.endswith("gyro") else "commands"
        base = scene_variant(path, attitude, duration_s=duration_s)
        data = None
    else:
        data = copy.deepcopy(tomllib.loads(path.read_text()))
    if data is not None:
        data["scene"]["duration_s"] = duration_s
        data["scene"]["seed"] = seed
        if lever == "predictive controller":
            data.setdefault("tracker", {})["controller"] = "predictive"
        elif lever == "head ripple":
            data["scene"]["effects"] = list(data["scene"].get("effects", [])) + ["head_ripple"]
        elif lever == "paraxial scan model":
            data["lidar"]["model"] = "paraxial"
        elif lever == "nominal speed table":
            data["gimbal"]["speed_table"] = "nominal"
        elif lever not in (REFERENCE, "recording on"):
            raise ValueError(f"unknown lever {lever!r}")
        return scene_from_mapping(data, f"{path} ({lever})")
    from dataclasses import replace

    return replace(base, seed=seed)


@dataclass(frozen=True)
class LeverTask:
    lever: str
    seed: int
    duration_s: float

    axis = "levers"

    @property
    def cost_hint(self) -> float:
        return self.duration_s * (0.04 if self.lever == "recording on" else 0.02)

    def run(self) -> dict:
        scene = lever_scene(self.lever, self.duration_s, self.seed)
        if self.lever == "recording on":
            with tempfile.TemporaryDirectory(prefix="foveatrack-study-") as d:
                m = run_loop(scene, record_to=Path(d) / "run.mcap")
        else:
            m = run_loop(scene)
        return strip_private(m)


def tasks(size) -> list[LeverTask]:
    seed0 = tomllib.loads((SCENES_DIR / SCENE_FILES["fig12"]).read_text())["scene"]["seed"]
    return [LeverTask(lever, seed, size.levers_duration_s) for seed in seeds_for(seed0, size.seeds)
            for lever in LEVERS]


def collect(results) -> dict:
    """Per lever: each metric's interval over seeds, its paired change against the reference, and the
    cost ratio to the reference on the same seed."""
    by = {lever: {t.seed: r for t, r in results if t.lever == lever} for lever in LEVERS}
    ref = by[REFERENCE]
    rows = []
    for lever in LEVERS:
        have = by[lever]
        if not have:
            continue
        row = {"lever": lever, "seeds": len(have), "ci": {}, "delta": {}}
        for k in METRICS:
            row["ci"][k] = interval([have[s].get(k) for s in sorted(have)])
            row["delta"][k] = paired_delta({s: r.get(k) for s, r in have.items()},
                                           {s: r.get(k) for s, r in ref.items()})
        row["cost_ratio"] = paired_ratio({s: r["cpu_per_virtual_s"] for s, r in have.items()},
                                         {s: r["cpu_per_virtual_s"] for s, r in ref.items()})
        row["ms_per_frame"] = interval([1000 * have[s]["cpu_s"] / max(have[s]["frames"], 1) for s in sorted(have)])
        rows.append(row)
    duration = next((t.duration_s for t, _ in results), None)
    return {"scene": "fig12-tracking", "duration_s": duration, "seeds": sorted(ref), "reference": REFERENCE,
            "rows": rows}


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = CPU relative to the reference, error = tracking error rms after acquisition), each
    with its interval; the world position error is kept beside it."""
    pts = []
    for r in axis_result["rows"]:
        c, e = r["cost_ratio"], r["ci"]["error_rms_acq_deg"]
        if c is None or e is None:
            continue
        pts.append({"group": axis_result["scene"], "label": r["lever"], "cost": c["mean"], "cost_lo": c["lo"],
                    "cost_hi": c["hi"], "error": e["mean"], "error_lo": e["lo"], "error_hi": e["hi"],
                    "recon_rms_m": r["ci"]["recon_rms_m"], "offered": True})
    return pts


__all__ = ["LEVERS", "REFERENCE", "LeverTask", "collect", "lever_scene", "pareto_points", "tasks"]
