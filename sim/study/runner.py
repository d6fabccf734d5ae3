"""Build every axis's tasks, run them through :mod:`sim.sweep`'s executor, assemble the results.

All tasks of all axes go into one pool (one progress bar), the expensive ones first so that two
workers finish together.  Tasks are picklable frozen dataclasses and :func:`execute` is a top-level
function, so the same study runs on local processes or a Dask cluster (``--scheduler``).
"""

from __future__ import annotations

import math

from sim.study import (calibration_time, effect_costs, levers, pareto, point_rate, scan_fidelity, sensing,
                       sim_fidelity, sky_objects)
from sim.study.common import SIZES, StudySize, warm_up
from sim.sweep import run_tasks

AXES = ("scan", "fidelity", "sensing", "calibration", "rate", "levers", "effects", "objects")

# Target accuracies of the closing Pareto table, per axis (in that axis's error unit).
TARGETS = {
    "scan": (1.0, 0.1, 0.01, 0.001),
    "fidelity": (0.5, 0.25, 0.1, 0.05),
    "sensing": (10.0, 5.0, 3.0, 2.0),
    "sensing_detect": (0.5, 0.8, 0.95),
    "calibration": (25.0, 10.0, 5.0, 2.0),
    "rate": (10.0, 5.0, 3.0, 2.0),
    "levers": (5.0, 3.0, 2.0, 1.0),
}


def execute(task) -> dict:
    """Run one task in a worker (after warming the numba cache of that process)."""
    warm_up()
    return task.run()


def build_tasks(size: StudySize) -> list:
    tasks = (scan_fidelity.tasks(size) + sim_fidelity.tasks(size) + sensing.tasks(size)
             + calibration_time.tasks(size) + point_rate.tasks(size) + levers.tasks(size) + effect_costs.tasks(size)
             + sky_objects.tasks(size))
    return sorted(tasks, key=lambda t: -t.cost_hint)


def assemble(size: StudySize, results: list[tuple[object, dict]]) -> dict:
    """The study's results (JSON-ready apart from non-finite floats) from ``(task, result)`` pairs."""
    # every axis's tasks, and the sensing axis's coverage tasks (collected with it)
    by = {a: [(t, r) for t, r in results if t.axis == a] for a in AXES + ("coverage",)}
    axes = {
        "scan": scan_fidelity.collect(by["scan"]),
        "fidelity": sim_fidelity.collect(by["fidelity"]),
        "sensing": sensing.collect(by["sensing"] + by["coverage"], size.windows_ms),
        "calibration": calibration_time.collect(by["calibration"]),
        "rate": point_rate.collect(by["rate"]),
        "levers": levers.collect(by["levers"]),
        "effects": effect_costs.collect(by["effects"]),
        "objects": sky_objects.collect(by["objects"]),
    }
    points = {
        "scan": scan_fidelity.pareto_points(axes["scan"]),
        "fidelity": sim_fidelity.pareto_points(axes["fidelity"]),
        "sensing": sensing.pareto_points(axes["sensing"]),
        "calibration": calibration_time.pareto_points(axes["calibration"]),
        "rate": point_rate.pareto_points(axes["rate"]),
        "levers": levers.pareto_points(axes["levers"]),
    }
    points["sensing_detect"] = [_miss_point(p) for p in points["sensing"]]
    front = {}
    for axis, pts in points.items():
        front[axis] = {}
        for group, gp in pareto.groups(pts).items():
            targets = TARGETS[axis]
            cheapest = []
            for target in targets:
                err = 1.0 - target if axis == "sensing_detect" else target
                c = pareto.cheapest_for(gp, err)
                ties = [] if c is None else [p["label"] for p in pareto.cost_ties(gp, c, err)]
                cheapest.append({"target": target, "label": c["label"] if c else None,
                                 "cost": c["cost"] if c else None, "error": c["error"] if c else None,
                                 "error_hi": c.get("error_hi", c["error"]) if c else None, "cost_ties": ties})
            front[axis][group] = {"front": pareto.pareto_front(gp), "cheapest": cheapest, "points": gp}
    cpu = sum(r.get("cpu_s", 0.0) + r.get("cal_cpu_s", 0.0) for _, r in results)
    return {"size": size.name, "tasks": len(results), "task_cpu_s": cpu, "axes": axes, "pareto": front}


def _miss_point(p: dict) -> dict:
    """A sensing point with error = 1 - detection probability (its interval turned round)."""
    ci = p.get("p_detect_ci")
    out = dict(p, error=None if p["p_detect"] is None else 1.0 - p["p_detect"], error_lo=None, error_hi=None)
    if ci is not None and p["p_detect"] is not None:
        out["error_lo"], out["error_hi"] = 1.0 - ci["hi"], 1.0 - ci["lo"]
    return out


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``; ``platform.processor()`` elsewhere): costs in seconds
    do not carry across machines, so the report names the one that measured them."""
    import platform

    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def run_one_axis(axis: str, size: str | StudySize, executor, effects: list[str] | None = None,
                 progress: bool = True) -> tuple[dict, float]:
    """One axis alone, ``"effects"`` (:mod:`sim.study.effect_costs`; ``effects``: a subset of the
    measured effects, default all) or ``"objects"`` (:mod:`sim.study.sky_objects`): its collected
    result and the CPU its runs measured."""
    size = SIZES[size] if isinstance(size, str) else size
    if axis == "effects":
        module, tasks = effect_costs, effect_costs.tasks(size, effects)
    elif axis == "objects":
        module, tasks = sky_objects, sky_objects.tasks(size)
    else:
        raise ValueError(f"no single-axis run for {axis!r}; axes run alone: effects, objects")
    results = run_tasks(execute, tasks, executor, desc=axis, progress=progress)
    return module.collect(results), sum(r.get("cpu_s", 0.0) for _, r in results)


def run_study(size: str | StudySize, executor, progress: bool = True) -> dict:
    """Run the whole study on ``executor`` (see :func:`sim.sweep.make_executor`)."""
    size = SIZES[size] if isinstance(size, str) else size
    results = run_tasks(execute, build_tasks(size), executor, desc="accuracy-vs-time", progress=progress)
    return assemble(size, results)


def json_ready(obj):
    """Non-finite floats -> None, tuples -> lists (strict JSON)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    return obj
