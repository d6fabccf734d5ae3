"""Shared pieces of the accuracy-vs-time study: study sizes, scene variants, timed closed-loop runs.

Cost is measured as **CPU time of the worker process** (``time.process_time``), not wall time: the
study runs on shared machines and clusters, where wall time measures the neighbours as much as the
simulation.  Wall time is recorded next to it.  Every worker first warms numba's on-disk cache
(:func:`warm_up`), so no run pays for loading compiled kernels.

Nothing here reads the wall clock into a simulation: the clocks only *measure* runs.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"

_WARM = False


@dataclass(frozen=True)
class StudySize:
    """How big each axis is.  ``full`` is the committed report (< ~20 min with 2 workers);
    ``quick`` is the same study, smaller, for tests and a first look (< ~1 min)."""

    name: str
    seeds: int                      # paired seeds per closed-loop setting
    fidelity_duration_s: dict       # scene key -> virtual seconds per run (shortened scenes)
    scan_rays: int                  # rays per optics for the scan-model axis
    scan_repeats: int               # timing repeats (the minimum is reported)
    interp_steps: tuple             # exact-then-interpolate every m points
    windows_ms: tuple               # accumulation windows of the sensing axis
    sensing_duration_s: dict        # near / far
    sensing_seeds: int
    coverage_s: float               # accumulation time of the coverage curve
    coverage_rays: int              # reference rays of the reachable-cell grid
    dwells_s: tuple                 # calibration dwell per speed byte
    cal_plans: tuple                # names of calibration byte plans (calibration_time.PLANS)
    cal_seeds: int
    cal_check_s: float              # fig12 run with the calibrated table [virtual s]
    rate_duration_s: dict           # point-rate axis, per scene key
    levers_duration_s: float        # levers axis (fig12-tracking), virtual seconds per run


FULL = StudySize(
    name="full", seeds=8, fidelity_duration_s={"fig12": 15.0, "far": 20.0},
    scan_rays=400_000, scan_repeats=5, interp_steps=(2, 4, 8, 16),
    windows_ms=(25, 50, 100, 200, 400), sensing_duration_s={"near": 15.0, "mid": 15.0, "far": 15.0}, sensing_seeds=8,
    coverage_s=1.0, coverage_rays=1_000_000,
    dwells_s=(1.0, 2.0, 4.0, 8.0), cal_plans=("sparse", "dense"), cal_seeds=4, cal_check_s=30.0,
    rate_duration_s={"fig12": 15.0, "far": 20.0}, levers_duration_s=15.0,
)

QUICK = StudySize(
    name="quick", seeds=2, fidelity_duration_s={"fig12": 2.0, "far": 1.0},
    scan_rays=20_000, scan_repeats=2, interp_steps=(4,),
    windows_ms=(50, 200), sensing_duration_s={"near": 2.0, "mid": 2.0, "far": 2.0}, sensing_seeds=1,
    coverage_s=0.3, coverage_rays=100_000,
    dwells_s=(1.0,), cal_plans=("tiny",), cal_seeds=1, cal_check_s=3.0,
    rate_duration_s={"fig12": 2.0, "far": 1.0}, levers_duration_s=2.0,
)

SIZES = {"full": FULL, "quick": QUICK}

# The study's scenes: shipped files, keyed by the role they play.
SCENE_FILES = {
    "fig12": "fig12-tracking.toml",        # near target, tracked (paper Fig. 12 / 14b)
    "far": "far-target-range-limit.toml",  # 150 m, near the range limit
}


def load_study_scene(key: str):
    from sim.scene import load_scene

    return load_scene(SCENES_DIR / SCENE_FILES[key])


def seeds_for(scene_seed: int, n: int) -> list[int]:
    """``n`` paired seeds: the scene's own first, then fixed offsets (same for every setting)."""
    return [scene_seed + 1000 * i for i in range(n)]


def with_footprint(scene, subrays: int):
    """The scene with the beam-footprint effect off (``subrays = 0``) or on with ``subrays`` sub-rays."""
    effects = set(scene.effects)
    params = dict(scene.effect_params)
    if subrays <= 0:
        effects.discard("beam_footprint")
        params.pop("footprint_subrays", None)
    else:
        effects.add("beam_footprint")
        params["footprint_subrays"] = int(subrays)
    return replace(scene, effects=frozenset(effects), effect_params=params)


def with_window(scene, window_ms: float):
    """The scene with the tracker accumulating ``window_ms`` per frame (``rate_hz = 1000 / window``)."""
    return replace(scene, tracker=replace(scene.tracker, rate_hz=1000.0 / window_ms))


def warm_up() -> None:
    """Load every numba kernel the study uses once in this process (from the on-disk cache)."""
    global _WARM
    if _WARM:
        return
    from sim.loop import ClosedLoop
    from sim.scan.model import ScanModel
    from sim.scan.presets import HORIZON, MID40

    for optics in (MID40, HORIZON):
        for model in ("exact", "paraxial"):
            ScanModel(optics, model).scan(0, 1000)
    scene = with_footprint(replace(load_study_scene("fig12"), duration_s=0.2), 3)
    for grid, motion in ((None, "per_point"), (0.001, "per_point"), (0.0, "per_frame")):
        ClosedLoop(scene, head_grid_s=grid, target_motion=motion).run()
    _WARM = True


@dataclass
class Timer:
    """CPU and wall seconds of a block (``with Timer() as t: ...; t.cpu_s``)."""

    cpu_s: float = 0.0
    wall_s: float = 0.0

    def __enter__(self):
        self._c, self._w = time.process_time(), time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.cpu_s = time.process_time() - self._c
        self.wall_s = time.perf_counter() - self._w
        return False


def rms(x) -> float | None:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else None


def loop_metrics(scene, log: dict) -> dict:
    """Tracking metrics of one run: the project's summary plus ones defined on every frame.

    ``error_rms_all_deg``: rms of the true off-axis angle of the target over *all* frames (defined
    even when the target is never acquired); ``detect_frac``: frames with a
    detection / frames; the rest is :func:`sim.summary.summarize` (error after acquisition etc.).
    """
    from sim.summary import summarize

    s = summarize(scene, log, 1.0)
    err = log["true_error_deg"].astype(float)
    n = len(err)
    return {
        "frames": n,
        "error_rms_all_deg": rms(err),
        "error_rms_acq_deg": s["tracking_error_deg"]["rms"],
        "acquisition_s": s["acquisition_s"],
        "detect_frac": float(np.mean(log["detected"])) if n else 0.0,
        "points_on_target_per_frame": s["points_on_target_per_frame"],
        "points_per_frame": s["points_per_frame"],
        "recon_rms_m": s.get("reconstruction_error_m", {}).get("rms"),
    }


def run_loop(scene, head_grid_s: float | None = None, target_motion: str = "per_point", frame_hook=None,
             time_tracker: bool = False, record_to: Path | None = None) -> dict:
    """Run a scene's closed loop; metrics, CPU/wall time and, if asked, the tracker's own CPU time.

    ``tracker_cpu_s`` times ``Tracker.process`` alone (the part that runs on real hardware); the
    rest of ``cpu_s`` is the simulation of the world, the scanner, the link and the head.
    ``record_to``: also write the run's recording there on the loop's thread (as ``simulate --out
    --one-thread``), inside the timed block, closing the file included.
    """
    before = compiles_so_far()
    m = _run_loop_once(scene, head_grid_s, target_motion, frame_hook, time_tracker, record_to)
    if compiles_so_far() != before and frame_hook is None:     # (a hook's caller keeps what it saw: once)
        # numba compiled a kernel inside the timed run (one warm_up does not load: a fresh install's
        # first quick study priced 'all-cheap' at 16 +- 199 times all-exact, a user's audit): its CPU is
        # the compiler's; the same run again (the same seeds, the same figures) is what is timed
        m = _run_loop_once(scene, head_grid_s, target_motion, frame_hook, time_tracker, record_to)
    return m


_COMPILES = [0, False]      # numba compiles seen in this process; the listener registered


def compiles_so_far() -> int:
    """How many numba compiles this process has done since the first call (a listener on numba's
    compile events; loads from the on-disk cache are not compiles)."""
    if not _COMPILES[1]:
        from numba.core import event

        class _Count(event.Listener):
            def on_start(self, ev):
                pass

            def on_end(self, ev):
                _COMPILES[0] += 1

        event.register("numba:compile", _Count())
        _COMPILES[1] = True
    return _COMPILES[0]


def _run_loop_once(scene, head_grid_s, target_motion, frame_hook, time_tracker, record_to) -> dict:
    """One timed run of :func:`run_loop`."""
    from sim.loop import ClosedLoop

    loop = ClosedLoop(scene, frame_hook=frame_hook, head_grid_s=head_grid_s, target_motion=target_motion)
    writer = None
    if record_to is not None:
        from foveatrack.recording import RecordingWriter
        from sim.recorder import SimRecorder, recording_meta

        if frame_hook is not None:
            raise ValueError("run_loop: record_to and frame_hook together are not supported")
        writer = RecordingWriter(record_to, meta=recording_meta(scene, loop), overwrite=True,
                                 created_utc="virtual time (simulation)", log_time=scene.start_utc_ns)
        loop.frame_hook = SimRecorder(writer)
    tracker_cpu = [0.0]
    if time_tracker:
        inner = loop.tracker.process

        def timed(frame, send_t_s=None):
            c = time.process_time()
            out = inner(frame, send_t_s=send_t_s)
            tracker_cpu[0] += time.process_time() - c
            return out

        loop.tracker.process = timed
    with Timer() as t:
        try:
            log = loop.run()
        finally:
            if writer is not None:
                writer.close()
    m = loop_metrics(scene, log)
    m.update(cpu_s=t.cpu_s, wall_s=t.wall_s, virtual_s=scene.duration_s,
             cpu_per_virtual_s=t.cpu_s / scene.duration_s, rays=loop.rays_total)
    if time_tracker:
        m["tracker_cpu_s"] = tracker_cpu[0]
    m["_log"] = log
    m["_loop"] = loop
    return m


def strip_private(m: dict) -> dict:
    """Drop the in-process objects (``_log``, ``_loop``) before a result leaves the worker."""
    return {k: v for k, v in m.items() if not k.startswith("_")}


def finite_or_none(v):
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v
