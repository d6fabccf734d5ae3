"""The pinned regression scenes and how one is run (shared by the tests and
scripts/update_regression_baseline.py, which regenerates tests/regression/baseline.json)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BASELINE = Path(__file__).with_name("baseline.json")

# scene file -> virtual duration [s] (None: the scene's own).  Every shipped scene with a target,
# the hard ones included; durations keep the whole suite well under 2 min on 2 shared cores.
CASES: dict[str, float | None] = {
    "fig12-tracking": None,
    "fig12-predictive": None,
    "fig14a-frozen-pass": None,
    "fast-crossing-close": None,
    "far-target-range-limit": None,
    "overhead-tilt-stop": None,
    "noisy-link": None,
}

# Metrics kept in the baseline (from sim.summary.summarize).  Wall time and real-time factor are
# machine properties, not tracking quality, and are left out.
DROP = ("wall_s", "realtime_factor", "scene", "seed", "effects")

# "Worse than the baseline by more than abs + rel * |baseline|" fails (foveatrack.metrics.compare_to_baseline).
# Runs are bit-for-bit deterministic for a seed on one machine; across machines, libm/BLAS/numba
# float differences can flip a point at a surface edge or a byte at a rounding boundary and the
# closed loop then diverges a little.  The tolerances are a few percent plus one frame's worth
# (0.1 s, ~0.05 deg, 2 cm) -- far below the changes a real regression makes (tens of percent).
TOLERANCES = {
    "*": {"abs": 0.0, "rel": 0.05},
    "tracking_error_deg.rms": {"abs": 0.05, "rel": 0.05},
    "tracking_error_deg.p95": {"abs": 0.05, "rel": 0.05},
    "tracking_error_deg.max": {"abs": 0.10, "rel": 0.05},
    "acquisition_s": {"abs": 0.2, "rel": 0.05},
    "reconstruction_error_m.rms": {"abs": 0.02, "rel": 0.05},
    "reconstruction_error_m.p95": {"abs": 0.02, "rel": 0.05},
    "reconstruction_error_m.max": {"abs": 0.05, "rel": 0.05},
    "reconstruction_error_rel.rms": {"abs": 0.001, "rel": 0.05},
    "reconstruction_error_rel.p95": {"abs": 0.001, "rel": 0.05},
    "reconstruction_error_rel.max": {"abs": 0.002, "rel": 0.05},
    "head_angle_error_deg.rms": {"abs": 0.05, "rel": 0.05},   # ~1e-15 with a true table: rounding
    "head_angle_error_deg.p95": {"abs": 0.05, "rel": 0.05},
    "head_angle_error_deg.max": {"abs": 0.10, "rel": 0.05},
    "frames_with_detection": {"abs": 2, "rel": 0.02},
    "points_on_target_per_frame": {"abs": 0.1, "rel": 0.05},
    "points_per_frame": {"abs": 1.0, "rel": 0.02},
    "frames": {"abs": 0, "rel": 0.0},
}


def run_case(name: str) -> dict:
    """Run one pinned scene; returns its summary metrics without the machine-dependent keys."""
    from sim.loop import ClosedLoop
    from sim.scene import load_scene
    from sim.summary import summarize

    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    if CASES[name] is not None:
        scene = replace(scene, duration_s=CASES[name])
    t = time.perf_counter()
    log = ClosedLoop(scene).run()
    m = summarize(scene, log, time.perf_counter() - t)
    for k in DROP:
        m.pop(k, None)
    m["duration_s"] = scene.duration_s
    return m


# ---- Monte Carlo mode: each pinned scene over several seeds, mean and spread per metric ----------
# The baseline (baseline_mc.json) records the seeds it used; the tests run the same ones.  8 in CI
# (about a minute on two cores); regenerate with more for a tighter baseline:
#     python scripts/update_regression_baseline.py --monte-carlo --seeds 32 [--scheduler tcp://...]
BASELINE_MC = Path(__file__).with_name("baseline_mc.json")
MC_SEEDS = 8


def _spreads(names, seeds, durations: dict, executor, progress: bool, tracker: dict | None = None,
             sky: dict | None = None) -> dict:
    """``{scene name: spread_over_runs(...)}`` of each scene over ``seeds`` at its duration in
    ``durations`` (None: its own), with ``tracker`` and ``[tracker.sky]`` overrides: what both Monte
    Carlo baselines run."""
    from foveatrack.metrics import spread_over_runs
    from sim.monte_carlo import SeedRun, run_seeds

    tasks = [SeedRun(str(ROOT / "scenes" / f"{n}.toml"), s, durations[n], tuple(sorted((tracker or {}).items())),
                     tuple(sorted((sky or {}).items())))
             for n in names for s in seeds]
    results = run_seeds(tasks, executor, progress)
    return {n: spread_over_runs([results[t] for t in tasks if Path(t.scene_path).stem == n]) for n in names}


def monte_carlo(names, seeds, executor=None, tracker: dict | None = None, progress: bool = False) -> dict:
    """``{scene name: spread_over_runs(...)}`` of the pinned scenes over ``seeds``."""
    return _spreads(names, seeds, CASES, executor, progress, tracker=tracker)


# ---- the sky scenes (issue 28's multi-object tracker) over seeds: their totals per run -----------
# sim.sky_summary.sky_totals of each run (drones confirmed within 2 s, never confirmed, id switches,
# false drone tracks, continuity, fovea share, the longest revisit gap, GOSPA), mean and spread over
# the baseline's seeds (baseline_sky_mc.json; regenerate with
#     python scripts/update_regression_baseline.py --sky [--seeds N]
# after a change meant to move them).  A run's counts move by whole drones, so the tolerances are a
# quarter of a drone per run on average (two drones in eight runs) plus a share.
SKY_CASES: dict[str, float | None] = {
    "two-drones-crossing": None,
    "drone-tree-line": None,
    "swarm-of-five": None,
    "drone-and-flock": None,
}
BASELINE_SKY_MC = Path(__file__).with_name("baseline_sky_mc.json")
SKY_PREFIX = "sky.totals."
SKY_TOLERANCES = {
    "*": {"abs": 0.0, "rel": 0.05},
    "drones": {"abs": 0.0, "rel": 0.0},
    "confirmed_within_2s": {"abs": 0.25, "rel": 0.1},
    "scan_allows_within_2s": {"abs": 0.25, "rel": 0.1},
    "never_confirmed": {"abs": 0.25, "rel": 0.1},
    "time_to_confirm_s": {"abs": 0.2, "rel": 0.1},
    "id_switches": {"abs": 0.5, "rel": 0.15},
    "false_drone_tracks": {"abs": 0.25, "rel": 0.15},
    "continuity": {"abs": 0.03, "rel": 0.05},
    "fovea_share": {"abs": 0.03, "rel": 0.05},
    "longest_revisit_gap_s": {"abs": 0.5, "rel": 0.1},
    # the least gap the head's path allowed: what the gaps are read against, not a figure of merit
    "head_allows_revisit_s": None,
    "gospa_mean_m": {"abs": 0.2, "rel": 0.05},
}


def sky_monte_carlo(names, seeds, executor=None, sky: dict | None = None, progress: bool = False) -> dict:
    """``{scene name: spread of its sky totals}`` (keys without ``sky.totals.``) over ``seeds``;
    ``sky``: ``[tracker.sky]`` keys to set for the runs."""
    spreads = _spreads(names, seeds, SKY_CASES, executor, progress, sky=sky)
    return {n: {k[len(SKY_PREFIX):]: v for k, v in spread.items() if k.startswith(SKY_PREFIX)}
            for n, spread in spreads.items()}


def assert_spread_no_worse(name: str, spread: dict, baseline: dict, tolerances: dict) -> None:
    """The Monte Carlo check of one scene (both baselines): print the table, fail on any worse metric."""
    from foveatrack.metrics import compare_spread_to_baseline

    table, failures = compare_spread_to_baseline(spread, baseline["scenes"][name], tolerances)
    print(f"\n{name} over seeds {baseline['seeds']}\n{table}")
    assert not failures, f"{name} got worse than its Monte Carlo baseline:\n" + "\n".join(failures)
