"""CPU of the closed loop's own thread per frame, stage by stage (no recording).

The critical path of a run: what the loop's thread spends on a frame (``time.thread_time``), for the
shipped ``fig12-tracking`` and its hall variant (the scene ``scripts/bench_closed_loop.py`` builds:
six walls instead of the ground), each on one thread and with the scan and the draws worked ahead
on a second (:mod:`sim.ahead`).  Each run is repeated; the best and the median are printed, with the
load average (the machine is shared: compare figures taken side by side, at the same load), and
the median per stage of :attr:`sim.loop.ClosedLoop.stage_s` (wall clocks, which with ``ahead``
include waits for the worker or the GIL).

Usage: python scripts/bench_loop_thread.py [--repeat N] [--duration S] [--only fig12|hall] [--mode one|ahead]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_closed_loop import fig12_and_hall  # noqa: E402
from sim.loop import ClosedLoop  # noqa: E402





def measure(scene, ahead: bool, repeat: int) -> tuple[list[float], list[dict[str, float]]]:
    """Loop-thread CPU per frame [ms] of each run, and each run's stage clocks [ms per frame]."""
    ClosedLoop(scene).run(ahead=ahead)             # warm-up: numba's cache, first calls
    cpu, stages = [], []
    for _ in range(repeat):
        loop = ClosedLoop(scene)
        c = time.thread_time()
        loop.run(ahead=ahead)
        cpu.append((time.thread_time() - c) / len(loop.log.t_end_s) * 1e3)
        stages.append({k: v / loop.steps_timed * 1e3 for k, v in loop.stage_s.items()})
    return cpu, stages


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--only", choices=("fig12", "hall"))
    ap.add_argument("--mode", choices=("one", "ahead"))
    args = ap.parse_args()
    for name, scene in fig12_and_hall(args.duration).items():
        if args.only not in (None, name):
            continue
        for mode in ("one", "ahead"):
            if args.mode not in (None, mode):
                continue
            load = os.getloadavg()[0]
            cpu, stages = measure(scene, mode == "ahead", args.repeat)
            print(f"{name} ({'scan + draws ahead' if mode == 'ahead' else 'one thread'}): loop thread's CPU "
                  f"best {min(cpu):.3f}, median {statistics.median(cpu):.3f} ms per frame over {len(cpu)} runs "
                  f"(load {load:.2f} before, {os.getloadavg()[0]:.2f} after)", flush=True)
            for k in stages[0]:
                print(f"    {statistics.median(s[k] for s in stages):6.3f} ms  {k}")


if __name__ == "__main__":
    main()
