"""Benchmark of the scan model: exact rays/s of the numba kernel and of its numpy twin, measured in
the same run on the same rays, and points/s of the full scan (directions + timestamps + channels).

Targets (issue 2): >= 20 M exact rays/s on one core and >= 15x the numpy twin.

Usage: python scripts/bench_scan.py [--rays N]
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


def best_rate(fn, count, repeats=5):
    best = 0.0
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = max(best, count / (time.perf_counter() - t))
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=2_000_000)
    args = ap.parse_args()
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


if __name__ == "__main__":
    main()
