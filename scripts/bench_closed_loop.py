"""Real-time factor of the closed loop (issue 4 target: >= 200x for fig12-tracking on one core).

Runs a scene twice (the first run also warms numba's cache) and prints the wall time, the real-time
factor and where the time goes (cProfile, top functions).  Also runs the same scene with the head
pose evaluated exactly at every point (``head_grid_s = 0``) to show what that accuracy costs.

Usage: python scripts/bench_closed_loop.py [SCENE.toml] [--duration S]
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from sim.loop import ClosedLoop  # noqa: E402
from sim.scene import load_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed(scene, **kw):
    t = time.perf_counter()
    ClosedLoop(scene, **kw).run()
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default=str(ROOT / "scenes" / "fig12-tracking.toml"))
    ap.add_argument("--duration", type=float, default=30.0)
    args = ap.parse_args()
    scene = replace(load_scene(args.scene), duration_s=args.duration)
    timed(replace(scene, duration_s=1.0))
    wall = min(timed(scene) for _ in range(2))
    exact = timed(scene, head_grid_s=0.0)
    print(f"{scene.name}: {scene.duration_s:g} s of virtual time, {scene.optics.point_rate_hz} points/s, "
          f"effects {sorted(scene.effects)}")
    print(f"  head pose on a 1 ms grid (default): {wall:.2f} s wall -> {scene.duration_s / wall:.1f}x real time")
    print(f"  head pose exact at every point:     {exact:.2f} s wall -> {scene.duration_s / exact:.1f}x real time")
    prof = cProfile.Profile()
    prof.enable()
    ClosedLoop(scene).run()
    prof.disable()
    print("  where the time goes (tottime, top 10):")
    stats = pstats.Stats(prof)
    stats.sort_stats("tottime")
    for (file, line, fn), (cc, nc, tt, ct, callers) in sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:10]:
        print(f"    {tt:6.3f} s  {Path(file).name}:{line} {fn}")


if __name__ == "__main__":
    main()
