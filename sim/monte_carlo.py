"""One scene over many seeds: the tracking metrics' mean and spread (Monte Carlo regression).

A single seed can hide a regression (or invent one): a controller change that costs 10 % on average
may gain on the one pinned seed.  :func:`run_seeds` runs a scene once per seed through a
``concurrent.futures`` executor (local processes, or a Dask cluster: :func:`sim.sweep.make_executor`)
and :func:`foveatrack.metrics.spread_over_runs` turns the runs into mean and spread per metric.

Runs are deterministic per seed, so the same seeds give the same spread to the bit on one machine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

# Machine properties, not tracking quality: left out of the metrics.
MACHINE_KEYS = ("wall_s", "realtime_factor", "realtime_factor_after_first_frame", "first_frame_s", "finish_s",
                "time_per_frame_ms", "worked_ahead", "scene", "seed", "effects")


@dataclass(frozen=True)
class SeedRun:
    """One run: ``scene_path`` over ``duration_s`` (None: the scene's own) with ``seed``, and optional
    ``tracker`` overrides as ``(field, value)`` pairs of :class:`foveatrack.tracker.TrackerConfig`
    and ``sky`` overrides as ``(key, value)`` pairs of the scene's ``[tracker.sky]`` table (tuples,
    so that a run is hashable and keys its result)."""
    scene_path: str
    seed: int
    duration_s: float | None = None
    tracker: tuple = ()
    sky: tuple = ()


def run_one(task: SeedRun) -> dict:
    """The summary metrics of one seeded run, without the machine-dependent keys (picklable: runs in
    worker processes and on Dask workers)."""
    from sim.loop import ClosedLoop
    from sim.scene import load_scene, with_run_overrides
    from sim.summary import summarize

    scene = with_run_overrides(load_scene(Path(task.scene_path)), task.duration_s, task.seed)
    if task.tracker:
        scene = replace(scene, tracker=replace(scene.tracker, **dict(task.tracker)))
    if task.sky:
        table = dict(scene.tracker_table)
        table["sky"] = {**table.get("sky", {}), **dict(task.sky)}
        scene = replace(scene, tracker_table=table)
    t = time.perf_counter()
    loop = ClosedLoop(scene)
    log = loop.run()
    m = summarize(scene, log, time.perf_counter() - t, loop)     # with the loop: a sky run's figures too
    for k in MACHINE_KEYS:
        m.pop(k, None)
    return m


def seeds_for(count: int) -> list[int]:
    """The seeds of a Monte Carlo run of ``count`` runs: 1 .. count (fixed, so runs are comparable)."""
    return list(range(1, count + 1))


def run_seeds(tasks: list[SeedRun], executor=None, progress: bool = False) -> dict[SeedRun, dict]:
    """``{task: metrics}`` for every task, through ``executor`` (None: in this process, in order)."""
    if executor is None:
        return {t: run_one(t) for t in tasks}
    from sim.sweep import run_tasks

    return dict(run_tasks(run_one, tasks, executor, desc="seeded runs", progress=progress))
