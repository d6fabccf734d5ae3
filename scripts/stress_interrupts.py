"""Ctrl-C at random moments of a real ``foveatrack simulate --second-core --out DIR`` run, many times, and
what each run did: its exit code, whether it said ``foveatrack: interrupted``, printed a traceback,
left an incomplete recording, or hung (docs/interrupts.md).

    python scripts/stress_interrupts.py --runs 200 --busy-loops 2

Each run gets one SIGINT, ``uniform(--min-delay-s, --max-delay-s)`` after its start (the start, the imports, the
set-up, the first frames and the run itself all get their share).  ``--busy-loops N`` starts N
``yes > /dev/null`` loops for the length of the stress (killed at its end): on a loaded machine the
writer process falls behind and the loop's thread waits for it, where the interrupts land then.

A run that has not ended ``--timeout-s`` after its SIGINT counts as a hang: the stacks of all threads
of the run and of its writer process are dumped (``PYTHONFAULTHANDLER``; SIGABRT to each, which also
ends them) into ``--hang-dir``, and the counts go on.  Exit status 1 if any run hung.
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_daemon_soak import child_pids as children  # noqa: E402  (a run's writer process: /proc, every thread's)


def recording_state(path: Path) -> str:
    """'none' (no file yet), 'complete', or 'incomplete (N frames): why'."""
    if not path.exists():
        return "none"
    from foveatrack.recording import RecordingReader

    try:
        r = RecordingReader(path)
    except Exception as exc:  # noqa: BLE001 - a file the run left unreadable is what is counted here
        return f"incomplete: {type(exc).__name__}: {exc}"
    frames = sum(1 for _ in r.points())       # a full walk: only then is r.complete known
    return "complete" if r.complete else f"incomplete ({frames} frames): {r.problem}"


def one_run(root: Path, scene: Path, delay_s: float, timeout_s: float, hang_dir: Path, k: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="stress-interrupts-") as tmp:
        out = Path(tmp) / "run"
        env = dict(os.environ, PYTHONFAULTHANDLER="1")
        p = subprocess.Popen([sys.executable, "-m", "foveatrack", "simulate", str(scene), "--duration", "3000",
                              "--out", str(out), "--second-core", "--no-progress"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env, cwd=root)
        time.sleep(delay_s)
        p.send_signal(signal.SIGINT)
        hung = False
        try:
            # the end of stderr: the writer process (which shares it) has ended too
            _, err = p.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            hung = True
            for pid in (*children(p.pid), p.pid):      # the writer first: its stacks, then the run's
                try:
                    os.kill(pid, signal.SIGABRT)
                except ProcessLookupError:
                    pass
                time.sleep(0.5)
            try:
                _, err = p.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                for pid in (*children(p.pid), p.pid):
                    os.kill(pid, signal.SIGKILL)
                _, err = p.communicate()
            hang_dir.mkdir(parents=True, exist_ok=True)
            dump = hang_dir / f"hang-{k:03d}-after-{delay_s:.3f}s.txt"
            dump.write_text(err)
            print(f"  run {k}: HANG (SIGINT at {delay_s:.3f} s); stacks in {dump}", flush=True)
        return dict(delay_s=delay_s, rc=p.returncode, hung=hung, said_interrupted="foveatrack: interrupted" in err,
                    traceback="Traceback (most recent call last)" in err and not hung,
                    recording=recording_state(out / "run.mcap"), stderr=err)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--min-delay-s", type=float, default=0.0, help="SIGINT uniform in [this, --max-delay-s] s after the start")
    ap.add_argument("--max-delay-s", type=float, default=4.0)
    ap.add_argument("--timeout-s", type=float, default=60.0, help="a run not ended this long after its SIGINT hangs")
    ap.add_argument("--busy-loops", type=int, default=2, help="`yes > /dev/null` loops beside the runs")
    ap.add_argument("--seed", type=int, default=1, help="of the SIGINT times")
    ap.add_argument("--scene", type=Path, default=ROOT / "scenes" / "fig12-tracking.toml")
    ap.add_argument("--root", type=Path, default=ROOT,
                    help="the checkout whose foveatrack runs (the current directory comes first on the path)")
    ap.add_argument("--hang-dir", type=Path, default=Path(tempfile.gettempdir()) / "stress-interrupts-hangs")
    a = ap.parse_args(argv)
    rng = random.Random(a.seed)
    busy = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(a.busy_loops)]
    runs = []
    t0 = time.monotonic()
    try:
        print(f"{a.root}: {a.runs} runs of `foveatrack simulate {a.scene.name} --second-core --out DIR`, one SIGINT each "
              f"uniform in [{a.min_delay_s:g}, {a.max_delay_s:g}] s, beside {a.busy_loops} `yes > /dev/null` loops; "
              f"load {os.getloadavg()[0]:.2f}", flush=True)
        for k in range(a.runs):
            r = one_run(a.root, a.scene, rng.uniform(a.min_delay_s, a.max_delay_s), a.timeout_s, a.hang_dir, k)
            runs.append(r)
            if (k + 1) % 10 == 0:
                print(f"  {k + 1} runs, {sum(x['hung'] for x in runs)} hung, {time.monotonic() - t0:.0f} s, "
                      f"load {os.getloadavg()[0]:.2f}", flush=True)
    finally:
        for b in busy:
            b.kill()
            b.wait()
    codes = collections.Counter(r["rc"] for r in runs if not r["hung"])
    hangs = [r for r in runs if r["hung"]]

    def delays(rs):
        return f" (SIGINT {min(r['delay_s'] for r in rs):.2f}-{max(r['delay_s'] for r in rs):.2f} s)" if rs else ""

    print(f"runs: {len(runs)}")
    print(f"hangs (no end {a.timeout_s:g} s after the SIGINT): {len(hangs)}{delays(hangs)}")
    for rc, n in sorted(codes.items()):
        rs = [r for r in runs if r["rc"] == rc and not r["hung"]]
        print(f"exit {rc}: {n}{delays(rs)}; said 'foveatrack: interrupted': {sum(r['said_interrupted'] for r in rs)}, "
              f"printed a traceback: {sum(r['traceback'] for r in rs)}")
    rec = collections.Counter(r["recording"].split(" ")[0].rstrip(":") for r in runs if not r["hung"])
    print("recordings: " + ", ".join(f"{k} {v}" for k, v in sorted(rec.items())))
    for r in runs:
        if r["recording"].startswith("incomplete"):
            print(f"  SIGINT at {r['delay_s']:.3f} s: {r['recording']}")
    for r in runs:      # what went unexpectedly: the end of its stderr
        if not r["hung"] and (r["recording"].startswith("incomplete") or r["traceback"] and r["delay_s"] > 0.5):
            tail = "\n".join("    " + line for line in r["stderr"].strip().splitlines()[-12:])
            print(f"  SIGINT at {r['delay_s']:.3f} s, exit {r['rc']}, recording {r['recording']}:\n{tail}")
    print(f"{time.monotonic() - t0:.0f} s; load at the end {os.getloadavg()[0]:.2f}")
    return 1 if hangs else 0


if __name__ == "__main__":
    sys.exit(main())
