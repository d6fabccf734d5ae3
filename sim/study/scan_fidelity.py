"""Axis 1 -- scan-model fidelity: angular error per ray against time per ray.

Candidates, all measured on the *same* rays (consecutive points of the real scan pattern, so the
prism angles and channels are the ones a frame uses):

* ``exact`` -- vector Snell refraction at every face (paper Appendix B; the reference, error 0);
* ``paraxial`` -- the first-order sum of the prisms' deviation vectors (paper Section III, eq. 1-3);
* ``exact/m`` -- exact at every m-th point of each channel, linear interpolation (renormalised)
  between.  A study-only candidate: the simulator does not offer it; it is measured here to show
  what a cheaper exact-based model could buy (a knob the lead could add to ``sim.scan``).

float32 kernels are **not offered** by the scan model (every kernel is float64), so there is no
float32 point on this curve.

Angular error of a ray: ``atan2(|a x b|, a . b)`` between its direction and the exact one.  Time
per ray: the minimum over ``repeats`` of the kernel call's wall time / rays (a micro-benchmark of a
few ms, where the minimum is the robust statistic; the closed-loop axes use CPU time instead).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from foveatrack.metrics import angle_between_deg


@dataclass(frozen=True)
class ScanTask:
    optics_name: str       # a preset: "mid40" | "horizon"
    rays: int
    repeats: int
    interp_steps: tuple
    k0: int = 1_234_567    # first point: an arbitrary place in the pattern, away from t = 0

    axis = "scan"

    @property
    def cost_hint(self) -> float:
        return self.rays * self.repeats * 3e-7

    def run(self) -> dict:
        return scan_errors(self.optics_name, self.rays, self.repeats, self.interp_steps, self.k0)


def _best_time(fn, repeats: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(max(1, repeats)):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def interpolated_exact(model, revs: np.ndarray, channel: np.ndarray, step: int, channels: int) -> np.ndarray:
    """Exact directions at every ``step``-th point of each channel, linear in between (renormalised)."""
    n = revs.shape[0]
    out = np.empty((n, 3))
    for c in range(channels):
        idx = np.arange(c, n, channels)
        if idx.size == 0:
            continue
        knots = np.unique(np.append(np.arange(0, idx.size, step), idx.size - 1))
        d, _ = model.directions_from_revs(revs[idx[knots]], channel[idx[knots]])
        pos = np.arange(idx.size)
        seg = np.clip(np.searchsorted(knots, pos, side="right") - 1, 0, max(knots.size - 2, 0))
        if knots.size == 1:
            out[idx] = d[0]
            continue
        k_lo, k_hi = knots[seg], knots[seg + 1]
        w = ((pos - k_lo) / (k_hi - k_lo))[:, None]
        v = (1 - w) * d[seg] + w * d[seg + 1]
        out[idx] = v / np.linalg.norm(v, axis=1, keepdims=True)
    return out


def _stats(err: np.ndarray) -> dict:
    return {"rms_deg": float(np.sqrt(np.mean(err ** 2))), "p95_deg": float(np.percentile(err, 95)),
            "max_deg": float(err.max()), "mean_deg": float(err.mean())}


def scan_errors(optics_name: str, rays: int, repeats: int, interp_steps=(), k0: int = 1_234_567) -> dict:
    """Each candidate's error statistics [deg] and time per ray [ns] on ``rays`` consecutive rays."""
    from sim.scan.kernels import RAY_OK
    from sim.scan.model import ScanModel
    from sim.scan.presets import PRESETS

    optics = PRESETS[optics_name]
    exact = ScanModel(optics, "exact")
    parax = ScanModel(optics, "paraxial")
    revs = np.ascontiguousarray(exact.prism_revs(k0, rays))
    channel = exact.channels(k0, rays)
    t_exact, (d_exact, st) = _best_time(lambda: exact.directions_from_revs(revs, channel), repeats)
    t_par, (d_par, _) = _best_time(lambda: parax.directions_from_revs(revs, channel), repeats)
    ok = st == RAY_OK
    rows = [{"model": "exact", "ns_per_ray": 1e9 * t_exact / rays, "rms_deg": 0.0, "p95_deg": 0.0,
             "max_deg": 0.0, "mean_deg": 0.0, "offered": True}]
    err_par = angle_between_deg(d_par[ok], d_exact[ok])
    rows.append({"model": "paraxial", "ns_per_ray": 1e9 * t_par / rays, **_stats(err_par), "offered": True})
    for m in interp_steps:
        t_i, d_i = _best_time(lambda: interpolated_exact(exact, revs, channel, m, optics.channels), repeats)
        rows.append({"model": f"exact/{m}", "ns_per_ray": 1e9 * t_i / rays,
                     **_stats(angle_between_deg(d_i[ok], d_exact[ok])), "offered": False})
    # paraxial error against the exact ray's off-axis angle (where in the FoV it goes wrong)
    off = np.degrees(np.arccos(np.clip(d_exact[ok, 0], -1, 1)))
    edges = np.linspace(0, off.max() + 1e-9, 21)
    which = np.digitize(off, edges) - 1
    prof = []
    for b in range(len(edges) - 1):
        sel = which == b
        if sel.any():
            prof.append({"off_axis_deg": float(0.5 * (edges[b] + edges[b + 1])),
                         "p95_deg": float(np.percentile(err_par[sel], 95)), "mean_deg": float(err_par[sel].mean())})
    return {"optics": optics_name, "rays": rays, "valid_rays": int(ok.sum()), "k0": k0, "rows": rows,
            "paraxial_vs_off_axis": prof, "float32": "not offered (all scan kernels are float64)"}


def tasks(size) -> list[ScanTask]:
    return [ScanTask(name, size.scan_rays, size.scan_repeats, tuple(size.interp_steps)) for name in ("mid40", "horizon")]


def collect(results: list[tuple[ScanTask, dict]]) -> dict:
    by = {task.optics_name: r for task, r in results}
    return {"optics": [by[k] for k in ("mid40", "horizon") if k in by]}


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = ns per ray, error = p95 angular error) of every candidate, per optics."""
    pts = []
    for o in axis_result["optics"]:
        for r in o["rows"]:
            pts.append({"group": o["optics"], "label": r["model"], "cost": r["ns_per_ray"], "error": r["p95_deg"],
                        "offered": r["offered"]})
    return pts
