"""Cost of a closed-loop frame against the number of objects in the sky (issue 28, the world half).

Runs ``drone-and-flock`` (a Mid-40 at 100 k points/s, a quadrotor, the ground) on one numba thread with
the flock cut to 0, 5, 20 and 80 birds, the swarm, tree-line and crossing scenes as shipped, and the
swarm with drone-and-flock's 20 birds added (issue 28's speed target: 150x real time), each after a
warm-up frame, and prints per run: the objects, the wall time per frame after the first (best of the
repetitions), the real-time factor, the ray-casting stage's and the tracker's shares of it (where the
objects cost) and the other stages' (the head, the scan, the beams, the link, the log), the median
CPU time of this process per frame (less moved by other processes on a loaded machine than the wall
time), and the machine's load average (a shared machine's timings move with it).  No recording
is written.

Usage: python scripts/bench_sky_objects.py [--duration S] [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from sim.loop import ClosedLoop  # noqa: E402
from sim.study.sky_objects import sky_scene  # noqa: E402


def _scene(name: str, duration_s: float, birds: int | None = None, flock_of: str | None = None):
    # the study's builder (section 8 of docs/accuracy-vs-time.md runs the same cases over seeds)
    return sky_scene(name, duration_s, None, birds, flock_of)


# the stages whose cost does not depend on the objects in the sky (sim.loop.STAGES): what is left of
# 150x's 0.67 ms a frame for the ray casting and the tracker
FIXED_STAGES = ("head model: commands arrive", "scan", "beams into the world (head pose)",
                "link (Pelco-D, UART)", "log and recording")


def _frame_ms(scene, repeat: int) -> tuple[float, float, float, float, float]:
    best, cast, track, fixed, cpu = float("inf"), 0.0, 0.0, 0.0, float("inf")
    for _ in range(repeat):
        marks = []
        loop = ClosedLoop(scene, frame_hook=lambda *_: marks.append(time.process_time()))
        loop.run()
        n = max(loop.steps_timed, 1)
        total = sum(loop.stage_s.values()) / n
        if total < best:
            best, cast, track = total, loop.stage_s["ray casting + effects"] / n, loop.stage_s["tracker"] / n
            fixed = sum(loop.stage_s[k] for k in FIXED_STAGES) / n
        cpu = min(cpu, float(np.median(np.diff(marks))))       # from the second frame on
    return best * 1e3, cast * 1e3, track * 1e3, fixed * 1e3, cpu * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    runs = [(f"drone-and-flock, {n} birds", _scene("drone-and-flock", a.duration, n)) for n in (0, 5, 20, 80)]
    runs += [(name, _scene(name, a.duration)) for name in ("swarm-of-five", "drone-tree-line", "two-drones-crossing")]
    # issue 28's speed target: "the swarm scene with the flock at least 150x real time without recording"
    runs += [("swarm-of-five + the 20-bird flock", _scene("swarm-of-five", a.duration, flock_of="drone-and-flock"))]
    ClosedLoop(_scene("drone-and-flock", 0.2, 5)).run()      # numba's cache / compilation, once
    print(f"{'scene':34s} {'objects':>7s} {'ms/frame':>9s} {'x real time':>11s} {'cast+effects ms':>15s} "
          f"{'tracker ms':>10s} {'other stages ms':>15s} {'CPU ms/frame':>12s}")
    for label, scene in runs:
        ms, cast, track, fixed, cpu = _frame_ms(scene, a.repeat)
        n_obj = len(scene.targets) + len(scene.others)
        period_ms = scene.tracker.period_s * 1e3
        print(f"{label:34s} {n_obj:7d} {ms:9.2f} {period_ms / ms:11.1f} {cast:15.2f} {track:10.2f} {fixed:15.2f} "
              f"{cpu:12.2f}")
    print("load average (1, 5, 15 min): " + ", ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
