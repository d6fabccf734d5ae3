"""Time of the tracker per frame (``Tracker.process``) on fig12 and the hall, two ways.

* in the loop: a closed-loop run of ``scenes/fig12-tracking.toml`` (and of its hall variant, the scene
  ``scripts/bench_closed_loop.py`` builds) on one thread, with ``process`` timed where the loop calls
  it (the tracker's code and data come cold from the rest of the frame's work, as in use);
* replayed: the tracker's calls in such a run are recorded once (every ``process(frame, send_t)``,
  every command the loop registers with ``command_sent``, the log's ``recon.angles_at``) and replayed
  in order on fresh trackers built like the loop's, through the one frame step with a pass-through
  gate (warm: the tracker's own work, and the step's few microseconds).  The replay
  checks that every output equals the run's (commands, states, detections, head estimates, world
  positions).

Each call is timed with ``time.perf_counter`` (``thread_time`` costs ~1 us a call here, a system
call); a process's figure is each frame's median over its runs (a call preempted on the shared
machine is an outlier there, so this comes close to the call's CPU time), averaged over the frames.

``--old DIR`` measures a second source tree (e.g. an old commit exported with ``git archive`` into DIR)
in turn with this one: each round runs one process per tree, alternating, so both see the same load;
the median over the rounds is printed per tree, with the load average and a Markdown table.
``--profile`` prints cProfile's view of a replay instead.

Usage: python scripts/bench_tracker.py [--rounds N] [--runs N] [--old DIR] [--only fig12|hall] [--profile]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
WAYS = ("in the loop", "replayed")


class _Recorder:
    """Stands in for the loop's controller: passes every call on to the tracker, timing ``process``,
    and (``calls`` not None) notes every call."""

    def __init__(self, tracker, calls: list | None, spent: list):
        self.tracker = tracker
        self.calls = calls
        self.spent = spent
        self.inside = False

    def process(self, frame, send_t_s=None):
        self.inside = True
        c = time.perf_counter()
        out = self.tracker.process(frame, send_t_s)
        self.spent.append(time.perf_counter() - c)
        self.inside = False
        if self.calls is not None:
            self.calls.append(("process", frame, send_t_s, out))
        return out

    def command_sent(self, t_s, cmd):
        if self.calls is not None:
            self.calls.append(("sent", t_s, cmd))
        self.tracker.command_sent(t_s, cmd)


def run_loop(scene, record: bool = False) -> tuple[list | None, list, object, object]:
    """One closed-loop run of ``scene`` on one thread: the time of each ``process`` [s], and with
    ``record`` the tracker's calls from outside (process, command_sent, the log's angles_at), with the
    tracker's configuration and speed table."""
    from sim.loop import ClosedLoop

    calls: list | None = [] if record else None
    spent: list = []
    loop = ClosedLoop(scene)
    loop.controller = rec = _Recorder(loop.tracker, calls, spent)
    recon = loop.tracker.recon
    if record:
        angles_at = recon.angles_at

        def logged_angles_at(t_s):   # the log's estimate at mid-frame (not the tracker's own asks)
            if not rec.inside:
                calls.append(("angles", t_s))
            return angles_at(t_s)
        recon.angles_at = logged_angles_at
    loop.run()
    if record:
        del recon.angles_at
    return calls, spent, loop.tracker.config, loop.tracker.table


def _same(a, b) -> bool:
    import numpy as np
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and a.shape == b.shape and a.tobytes() == b.tobytes()
    return a == b


def replay(calls, config, table, warm: bool = True) -> list[float]:
    """Time of each ``process`` call [s] over one replay, checking each output against the run's.
    ``warm``: read each frame's points before the call, as the loop has just written them (a replay
    of 300 frames of ~70 kB each would otherwise find them in memory, not in the cache)."""
    from foveatrack.tracker import Tracker

    try:
        from foveatrack.frame_step import FrameStep, NoHead
    except ImportError:
        raise SystemExit("the replay runs the tracker through foveatrack.frame_step: --old needs a tree that "
                         "has it") from None
    from foveatrack.gate import CommandGate

    class Written(NoHead):     # replay writes nothing; the run's own command_sent calls are replayed
        def send(self, cmd, send_t_s, source) -> bool:
            return True

    tracker = Tracker(config, table)
    # the one frame step, with a pass-through gate: it adds no call to the tracker's
    step = FrameStep(tracker, CommandGate(None), Written())
    clock = time.perf_counter
    spent = []
    for call in calls:
        kind = call[0]
        if kind == "process":
            _, frame, send_t, want = call
            if warm:
                frame.xyz.sum()
                frame.t_ns.sum()
            c = clock()
            out = step(frame, send_t).output
            spent.append(clock() - c)
            if out.command != want.command or out.state != want.state or not all(
                    _same(getattr(out, k), getattr(want, k)) for k in
                    ("t_s", "error_pan_deg", "error_tilt_deg", "head_pan_deg", "head_tilt_deg",
                     "head_sigma_pan_deg", "head_sigma_tilt_deg", "world_xyz", "world_sigma_m")):
                raise SystemExit(f"replay differs from the run at t = {frame.t_end_s} s")
            if (out.detection is None) != (want.detection is None) or (
                    out.detection is not None and not (_same(out.detection.xyz, want.detection.xyz)
                                                       and out.detection.t_s == want.detection.t_s)):
                raise SystemExit(f"replay's detection differs from the run's at t = {frame.t_end_s} s")
        elif kind == "sent":
            step.own_command(call[1], call[2], "sent")
        else:
            tracker.recon.angles_at(call[1])
    return spent


def scenes(names) -> dict:
    sys.path.insert(0, str(ROOT / "scripts"))
    from bench_closed_loop import fig12_and_hall

    return {k: v for k, v in fig12_and_hall().items() if k in names}


def _per_frame(runs: list[list[float]]) -> float:
    """Each frame's median over the runs, averaged over the frames [ms]."""
    return statistics.fmean(statistics.median(frame) for frame in zip(*runs)) * 1e3


def measure(names, n_runs: int) -> dict:
    """Per scene and way: the time of ``process`` per frame [ms]."""
    res = {}
    for name, scene in scenes(names).items():
        calls, _, config, table = run_loop(scene, record=True)   # warm-up (numba's cache, first calls)
        res[f"{name}, {WAYS[0]}"] = _per_frame([run_loop(scene)[1] for _ in range(n_runs)])
        replay(calls, config, table)
        res[f"{name}, {WAYS[1]}"] = _per_frame([replay(calls, config, table) for _ in range(n_runs)])
    return res


def profile(names, sort: str = "tottime") -> None:
    import cProfile
    import pstats

    for name, scene in scenes(names).items():
        calls, _, config, table = run_loop(scene, record=True)
        replay(calls, config, table)
        print(f"{name}: {sum(c[0] == 'process' for c in calls)} frames")
        pr = cProfile.Profile()
        pr.enable()
        replay(calls, config, table)
        pr.disable()
        pstats.Stats(pr).sort_stats(sort).print_stats(40)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5, help="processes per tree (alternating with --old)")
    ap.add_argument("--runs", type=int, default=7, help="loop runs and replays per process")
    ap.add_argument("--only", choices=("fig12", "hall"))
    ap.add_argument("--old", type=Path, help="a second source tree measured in turn with this one")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    names = ("fig12", "hall") if args.only is None else (args.only,)
    if args.profile:
        profile(names)
        return
    if args.child:
        import foveatrack
        import sim
        res = measure(names, args.runs)
        json.dump({"source": [foveatrack.__file__, sim.__file__], **res}, sys.stdout)
        return
    trees = {"this tree": ROOT} if args.old is None else {"old": args.old.resolve(), "this tree": ROOT}
    results: dict = {t: [] for t in trees}
    load0 = os.getloadavg()
    for _ in range(args.rounds):
        for label, tree in trees.items():
            env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]))
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--runs", str(args.runs)]
            if args.only:
                cmd += ["--only", args.only]
            r = subprocess.run(cmd, env=env, cwd=tree, check=True, capture_output=True, text=True)
            res = json.loads(r.stdout)
            if not all(Path(f).is_relative_to(tree) for f in res.pop("source")):
                raise SystemExit(f"{label}: the child imported foveatrack or sim from outside {tree}")
            results[label].append(res)
    load1 = os.getloadavg()
    print(f"Tracker.process per frame [ms]: median over {args.rounds} processes per tree (alternating), each "
          f"the frames' mean of their median over {args.runs} runs; load average {load0[0]:.2f} before, "
          f"{load1[0]:.2f} after" + (f"; old = {args.old}" if args.old else ""))
    keys = list(results["this tree"][0])
    med = {label: {k: statistics.median(r[k] for r in runs) for k in keys} for label, runs in results.items()}
    for k in keys:
        for label, runs in results.items():
            vals = [r[k] for r in runs]
            print(f"  {k:24s} {label:10s} median {med[label][k]:.4f}  min {min(vals):.4f}  max {max(vals):.4f}")
    if args.old:
        print("\n| run | before [ms] | after [ms] | after / before |\n|---|---|---|---|")
        for k in keys:
            a, b = med["old"][k], med["this tree"][k]
            print(f"| {k} | {a:.4f} | {b:.4f} | {b / a:.2f} |")


if __name__ == "__main__":
    main()
