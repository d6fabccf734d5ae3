"""Tracking metrics from per-frame truth and estimates, and the regression comparison.

Definitions (the ones ``foveatrack simulate --json`` and the regression baseline use)
--------------------------------------------------------------------------------------
* ``tracking_error_deg`` per frame: the angle between the optical axis and the true direction to the
  target (``arccos`` of the unit vectors' dot product, computed as ``atan2(|a x b|, a . b)`` so it is
  accurate near 0), in degrees.
* acquisition: the first frame from which the error stays below ``acquired_deg`` (default: the dead
  band + 1 deg) for ``hold_frames`` consecutive frames; ``acquisition_s`` = its time minus the time
  the target was first inside the FoV (or the start).  ``None`` if never acquired.  The two instants
  themselves (run time [s], for marking a plot) are ``in_fov_t_s`` and ``acquired_t_s`` (``None`` if
  never acquired).
* ``rms``, ``p95``, ``max`` of the error over frames *after acquisition* (NaN frames -- no truth --
  skipped).
* ``reconstruction_error_m`` (rms/p95/max) and ``reconstruction_error_rel`` (error / range) when world
  estimates are given.
* ``head_angle_error_deg`` (rms/p95/max over every frame, :func:`head_angle_error_deg`): the tracker's
  head attitude (dead reckoning or gyro) against the truth, in the simulator's summary.

Regression: :func:`compare_to_baseline` flags a metric that got *worse* than its baseline by more than
its tolerance (absolute ``abs`` plus relative ``rel``: ``new > base + abs + rel * |base|``; for metrics
where larger is better, listed in ``HIGHER_IS_BETTER``, the sign flips), and returns a printable table.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

HIGHER_IS_BETTER = frozenset({"frames_with_detection", "points_on_target_per_frame", "realtime_factor",
                              # the sky scenes' totals (sim.sky_summary.sky_totals)
                              "confirmed_within_2s", "scan_allows_within_2s", "continuity", "fovea_share"})


def angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle [deg] between rows of a and b (N, 3)."""
    a = np.asarray(a, float).reshape(-1, 3)
    b = np.asarray(b, float).reshape(-1, 3)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b)))


def head_angle_error_deg(true_pan_deg, true_tilt_deg, est_pan_deg, est_tilt_deg) -> np.ndarray:
    """Per sample, the angle [deg] of the rotation between the true and the estimated lidar attitude
    ``R = R_z(pan) R_y(-tilt)`` (:mod:`foveatrack.reconstruction`): the geodesic distance on SO(3),
    ``arccos((tr(R_t^T R_e) - 1) / 2)``, computed as ``2 asin(|R_t - R_e|_F / sqrt(8))`` to keep its
    accuracy near 0.  NaN where the estimate is NaN."""
    p, t = np.radians(np.asarray(true_pan_deg, float)), np.radians(np.asarray(true_tilt_deg, float))
    ep, et = np.radians(np.asarray(est_pan_deg, float)), np.radians(np.asarray(est_tilt_deg, float))

    def cols(p, t):   # the three columns of R_z(p) R_y(-t), flattened per sample
        cp, sp, ct, st = np.cos(p), np.sin(p), np.cos(t), np.sin(t)
        return np.stack([cp * ct, sp * ct, st, -sp, cp, 0 * p, -cp * st, -sp * st, ct], axis=-1)

    d = np.linalg.norm(cols(p, t) - cols(ep, et), axis=-1)
    return np.degrees(2.0 * np.arcsin(np.minimum(d / math.sqrt(8.0), 1.0)))


def _stats(x: np.ndarray) -> dict:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"rms": None, "p95": None, "max": None}
    return {"rms": float(np.sqrt(np.mean(x ** 2))), "p95": float(np.percentile(x, 95)), "max": float(x.max())}


def acquired_within_deg(cfg) -> float:
    """The error under which a run counts as acquired (held ``hold_frames`` frames): the larger dead
    band + 1 deg.  One rule for the simulator's summary and for replay, so both report the same
    acquisition time for a run."""
    return max(cfg.deadband_pan_deg, cfg.deadband_tilt_deg) + 1.0


def tracking_metrics(t_s, error_deg, *, detected=None, in_fov=None, acquired_deg: float = 3.0,
                     hold_frames: int = 5, world_est=None, world_true=None) -> dict:
    """Metrics of one run from per-frame arrays.

    t_s : (F,) frame times [s]; error_deg : (F,) true tracking error [deg] (NaN = no truth);
    detected : (F,) bool, a detection this frame; in_fov : (F,) bool, target inside the FoV (for
    acquisition time); world_est, world_true : (F, 3) world positions (NaN rows skipped).
    """
    t = np.asarray(t_s, float)
    e = np.asarray(error_deg, float)
    F = len(t)
    ok = np.isfinite(e) & (e < acquired_deg)
    if detected is not None and not np.any(detected):
        # nothing was ever detected: a target that flew out along the axis was within the threshold
        # and read as "acquired at 0.00 s, rms 0.84 deg" with the head never moved
        ok[:] = False
    acq_idx = None
    run = 0
    for i in range(F):
        run = run + 1 if ok[i] else 0
        if run >= hold_frames:
            acq_idx = i - hold_frames + 1
            break
    t_ref = t[0] if F else 0.0
    if in_fov is not None and np.any(in_fov):
        t_ref = t[int(np.argmax(np.asarray(in_fov, bool)))]
    out = {
        "frames": int(F),
        "frames_with_detection": int(np.sum(detected)) if detected is not None else None,
        "acquisition_s": None if acq_idx is None else float(t[acq_idx] - t_ref),
        "in_fov_t_s": float(t_ref),
        "acquired_t_s": None if acq_idx is None else float(t[acq_idx]),
        "tracking_error_deg": _stats(e[acq_idx:]) if acq_idx is not None else {"rms": None, "p95": None, "max": None},
    }
    if world_est is not None and world_true is not None:
        we = np.asarray(world_est, float).reshape(-1, 3)
        wt = np.asarray(world_true, float).reshape(-1, 3)
        d = np.linalg.norm(we - wt, axis=1)
        r = np.linalg.norm(wt, axis=1)
        out["reconstruction_error_m"] = _stats(d)
        with np.errstate(invalid="ignore", divide="ignore"):
            out["reconstruction_error_rel"] = _stats(d / r)
    return out


def flatten(metrics: Mapping, prefix: str = "", lists: bool = False) -> dict:
    """{"tracking_error_deg": {"rms": 1}} -> {"tracking_error_deg.rms": 1}.  ``lists``: a list of
    numbers (or None) becomes one key per element too, {"xyz_m": [1, 2]} -> {"xyz_m[0]": 1,
    "xyz_m[1]": 2} (a table's columns: the recording's CSV export)."""
    out = {}
    for k, v in metrics.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + ".", lists))
        elif lists and isinstance(v, list) and all(isinstance(e, (int, float)) or e is None for e in v):
            out.update((f"{key}[{i}]", e) for i, e in enumerate(v))
        else:
            out[key] = v
    return out


def compare_to_baseline(metrics: Mapping, baseline: Mapping, tolerances: Mapping) -> tuple[str, list[str]]:
    """Compare a run's metrics with the baseline.

    tolerances : {"tracking_error_deg.rms": {"abs": 0.1, "rel": 0.1}, ...}; a key ``"*"`` is the
    default for every numeric baseline metric without its own entry; metrics without a tolerance
    are printed but not checked.  Returns (table text, failures); a metric missing from the run, or
    None where the baseline had a number (e.g. never acquired), is a failure.
    """
    m, b = flatten(metrics), flatten(baseline)
    default = tolerances.get("*")
    rows, failures = [], []
    for key in sorted(b):
        base = b[key]
        if isinstance(base, bool) or not isinstance(base, (int, float)) or base is None:
            continue
        tol = tolerances.get(key, default)
        new = m.get(key)
        status = "-"
        if tol is not None:
            limit_abs = float(tol.get("abs", 0.0)) + float(tol.get("rel", 0.0)) * abs(base)
            if new is None or (isinstance(new, float) and math.isnan(new)):
                status = "FAIL"
                failures.append(f"{key}: baseline {base:.4g}, now missing")
            else:
                worse = (base - new) if key.split(".")[0] in HIGHER_IS_BETTER else (new - base)
                if worse > limit_abs + 1e-12 * max(1.0, abs(base)):   # float slack at the edge
                    status = "FAIL"
                    failures.append(f"{key}: {new:.4g} vs baseline {base:.4g} (allowed +{limit_abs:.3g})")
                else:
                    status = "ok"
            tol_txt = f"+{limit_abs:.3g}"
        else:
            tol_txt = "n/a"
        new_txt = "missing" if new is None else (f"{new:.4g}" if isinstance(new, (int, float)) else str(new))
        rows.append((key, f"{base:.4g}", new_txt, tol_txt, status))
    w = [max(len(r[i]) for r in rows + [("metric", "baseline", "now", "tolerance", "status")]) for i in range(5)]
    head = ("metric", "baseline", "now", "tolerance", "status")
    lines = ["  ".join(h.ljust(w[i]) for i, h in enumerate(head)), "  ".join("-" * x for x in w)]
    lines += ["  ".join(c.ljust(w[i]) for i, c in enumerate(r)) for r in rows]
    return "\n".join(lines), failures


def spread_over_runs(runs: list[Mapping]) -> dict[str, dict]:
    """Mean and spread of each numeric metric over runs of one scene with different seeds.

    Returns ``{metric: {"mean", "std", "n", "missing"}}`` for every flattened numeric metric:
    ``std`` is the sample standard deviation (ddof 1; 0 for one run), ``missing`` counts the runs
    where the metric is None or NaN (e.g. a seed whose target was never acquired).
    """
    flat = [flatten(r) for r in runs]
    keys = sorted({k for f in flat for k, v in f.items()
                   if v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))})
    out = {}
    for key in keys:
        vals = [f.get(key) for f in flat]
        good = np.array([float(v) for v in vals if v is not None and not (isinstance(v, float) and math.isnan(v))])
        out[key] = {"mean": float(good.mean()) if good.size else None,
                    "std": float(good.std(ddof=1)) if good.size > 1 else 0.0,
                    "n": int(good.size), "missing": len(vals) - int(good.size)}
    return out


def compare_spread_to_baseline(spread: Mapping, baseline: Mapping, tolerances: Mapping,
                               spread_rel: float = 0.5) -> tuple[str, list[str]]:
    """Compare a Monte Carlo run's :func:`spread_over_runs` with the baseline's.

    A metric fails when its mean got worse by more than its tolerance (as in
    :func:`compare_to_baseline`: ``abs + rel * |baseline mean|``), when its spread grew beyond
    ``std_base * (1 + spread_rel)`` plus that same slack (eight seeds estimate a standard deviation to
    about 25 %, so 50 % growth is a change, not chance), or when more runs lack it than in the baseline.
    """
    default = tolerances.get("*")
    rows, failures = [], []
    for key in sorted(baseline):
        b, s = baseline[key], spread.get(key)
        tol = tolerances.get(key, default)
        if tol is None or b.get("mean") is None:
            continue
        if s is None or s["mean"] is None:
            failures.append(f"{key}: baseline mean {b['mean']:.4g}, now missing in every run")
            rows.append((key, f"{b['mean']:.4g} ± {b['std']:.3g}", "missing", "", "FAIL"))
            continue
        limit_mean = float(tol.get("abs", 0.0)) + float(tol.get("rel", 0.0)) * abs(b["mean"])
        limit_std = b["std"] * (1.0 + spread_rel) + limit_mean   # a spread of 0 may grow to the mean's slack
        worse = (b["mean"] - s["mean"]) if key.split(".")[0] in HIGHER_IS_BETTER else (s["mean"] - b["mean"])
        status = "ok"
        slack = 1e-12 * max(1.0, abs(b["mean"]))
        if worse > limit_mean + slack:
            status = "FAIL"
            failures.append(f"{key}: mean {s['mean']:.4g} vs baseline {b['mean']:.4g} (allowed +{limit_mean:.3g})")
        if s["std"] > limit_std + slack:
            status = "FAIL"
            failures.append(f"{key}: spread {s['std']:.3g} vs baseline {b['std']:.3g} (allowed {limit_std:.3g})")
        if s["missing"] > b["missing"]:
            status = "FAIL"
            failures.append(f"{key}: missing in {s['missing']} runs, baseline {b['missing']}")
        rows.append((key, f"{b['mean']:.4g} ± {b['std']:.3g}", f"{s['mean']:.4g} ± {s['std']:.3g}",
                     f"+{limit_mean:.3g} / {limit_std:.3g}", status))
    head = ("metric", "baseline mean ± sd", "now", "allowed (mean / sd)", "status")
    w = [max(len(r[i]) for r in rows + [head]) for i in range(5)]
    lines = ["  ".join(h.ljust(w[i]) for i, h in enumerate(head)), "  ".join("-" * x for x in w)]
    lines += ["  ".join(c.ljust(w[i]) for i, c in enumerate(r)) for r in rows]
    return "\n".join(lines), failures
