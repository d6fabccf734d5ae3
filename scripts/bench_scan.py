"""Benchmark of the scan model: exact rays/s of the numba kernel and of its numpy twin, measured in
the same run on the same rays, and points/s of the full scan (directions + timestamps + channels).

Targets (issue 2): >= 20 M exact rays/s on one core and >= 15x the numpy twin.

Second section (issue 4): per-frame time of ``ScanModel.scan`` for one 100 ms closed-loop frame
(10 000 points, mid40 with the motor speed noise of scenes/fig12-tracking.toml), the fused kernel
(``scan``) against the composed path (``scan_composed``), interleaved in one run, best of N.

Usage: python scripts/bench_scan.py [--rays N] [--frame-reps N] [--frames-only]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from scan_twins import trace_exact_twin  # noqa: E402
from sim.scan import kernels as K  # noqa: E402
from sim.scan.model import ScanModel  # noqa: E402
from sim.scan.presets import PRESETS  # noqa: E402
from foveatrack.environment import describe  # noqa: E402


def best_rate(fn, count, repeats=5):
    best = 0.0
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = max(best, count / (time.perf_counter() - t))
    return best


def frame_section(reps: int) -> None:
    """Per-frame ms of ScanModel.scan, fused vs composed, on consecutive 100 ms frames of the fig12 scene."""
    from sim.scene import load_scene
    from sim.sensor import scene_scan_model

    scene = load_scene(str(Path(__file__).resolve().parents[1] / "scenes" / "fig12-tracking.toml"))
    fused, composed = scene_scan_model(scene), scene_scan_model(scene)
    n = int(round(0.1 * scene.optics.point_rate_hz))
    fused.scan(0, n)
    composed.scan_composed(0, n)
    best = {"composed": float("inf"), "fused": float("inf")}
    k = n
    for _ in range(reps):  # interleaved, so both see the same machine load
        for name, fn in (("composed", composed.scan_composed), ("fused", fused.scan)):
            t = time.perf_counter()
            fn(k, n)
            best[name] = min(best[name], time.perf_counter() - t)
        k += n
    print(f"\nScanModel.scan, one 100 ms frame ({n} points, {scene.optics.name}, speed noise {fused.speed_noise is not None}), "
          f"best of {reps}:")
    print(f"  composed (scan_composed): {best['composed'] * 1e3:7.3f} ms")
    print(f"  fused    (scan)         : {best['fused'] * 1e3:7.3f} ms   ({best['composed'] / best['fused']:.2f}x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=2_000_000)
    ap.add_argument("--frame-reps", type=int, default=300)
    ap.add_argument("--frames-only", action="store_true", help="only the per-frame section")
    args = ap.parse_args()
    print(describe(), flush=True)   # versions, CPU and numba target: a figure without them says little
    if args.frames_only:
        frame_section(args.frame_reps)
        return
    n = args.rays
    print(f"{'preset':10s} {'numba exact':>14s} {'numpy twin':>14s} {'ratio':>7s} {'full scan':>14s}")
    for name in ("prototype", "horizon"):
        model = ScanModel(PRESETS[name])
        revs = model.prism_revs(0, n)
        revs_pn = np.ascontiguousarray(revs.T)
        ch = model.channels(0, n)
        out = np.empty((n, 3))
        st = np.empty(n, dtype=np.uint8)
        args_k = (revs_pn, ch, model._incident, model._sin_wedge, model._cos_wedge, model._index, model._exit_tilted)
        K.trace_exact_kernel(*(a[..., :10] if i < 2 else a for i, a in enumerate(args_k)), out[:10], st[:10])
        kern = best_rate(lambda: K.trace_exact_kernel(*args_k, out, st), n)
        m = n // 4
        twin = best_rate(lambda: trace_exact_twin(revs[:m], ch[:m], *args_k[2:]), m, repeats=3)
        model.scan(0, 1000)
        full = best_rate(lambda: model.scan(0, n), n, repeats=3)
        print(f"{name:10s} {kern / 1e6:11.1f} M/s {twin / 1e6:11.2f} M/s {kern / twin:6.1f}x {full / 1e6:11.1f} M/s")
    print("(best of several runs, one thread; 'full scan' = exact phases + directions + timestamps + channels)")
    frame_section(args.frame_reps)


if __name__ == "__main__":
    main()
