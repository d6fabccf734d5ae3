"""The first ``foveatrack demo`` on an empty numba cache, as a fresh clone runs it, for one or more checkouts.

    python scripts/bench_first_demo.py [CHECKOUT ...] [--rounds 1]

Each checkout (default: this one; e.g. a ``git worktree add --detach /tmp/old 801b9d8`` beside it, to
pair the old and the new) runs ``python -m foveatrack demo`` from its own folder with
``NUMBA_CACHE_DIR`` pointed at a new empty directory (numba then neither reads nor writes the cache
next to the sources: the compile work of a fresh clone), in turn, ``--rounds`` times.  Printed per
run: the wait until the run's progress bar appears (the compile and the first frame: what a new user
waits for), the whole demo's wall time, the CPU seconds of all its processes, and the load average
before and after.  Say the load with a figure: the wall times grow with it, the CPU seconds barely.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def first_demo(checkout: Path) -> dict:
    """One demo on an empty cache from ``checkout``; the figures as a dict."""
    with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache, \
            tempfile.TemporaryDirectory(prefix="demo-out-") as out:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONDONTWRITEBYTECODE="1")
        load0 = os.getloadavg()[0]
        cpu0, t0 = _children_cpu_s(), time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "foveatrack", "demo", "--out", out], cwd=checkout, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        bar_s = [None]
        text = []

        def watch_stderr():     # the time the progress bar first shows (it starts after the first frame)
            tail = ""
            for chunk in iter(lambda: proc.stderr.read(1), ""):
                text.append(chunk)
                tail = (tail + chunk)[-8:]
                if bar_s[0] is None and "%|" in tail:
                    bar_s[0] = time.perf_counter() - t0

        watcher = threading.Thread(target=watch_stderr, daemon=True)
        watcher.start()
        stdout = proc.stdout.read()
        proc.wait()
        watcher.join(5)
        wall = time.perf_counter() - t0
        cpu = _children_cpu_s() - cpu0
        said = [line for line in "".join(text).replace("\r", "\n").splitlines() if line.strip() and "%|" not in line]
        return dict(checkout=str(checkout), code=proc.returncode, bar_s=bar_s[0], wall_s=wall, cpu_s=cpu,
                    load=(load0, os.getloadavg()[0]), said=said,
                    result=next((line for line in stdout.splitlines() if "with a detection" in line), ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkouts", nargs="*", type=Path, help="checkouts to time, in turn (default: this one)")
    ap.add_argument("--rounds", type=int, default=1, help="runs per checkout (default 1)")
    args = ap.parse_args()
    checkouts = args.checkouts or [ROOT]
    print(f"first `foveatrack demo` on an empty numba cache, {os.cpu_count()} cores")
    for r in range(args.rounds):
        for checkout in checkouts:
            f = first_demo(checkout.resolve())
            bar = "-" if f["bar_s"] is None else f"{f['bar_s']:.1f} s"
            print(f"{f['checkout']} (round {r + 1}): progress bar after {bar}, demo {f['wall_s']:.1f} s wall, "
                  f"{f['cpu_s']:.1f} s CPU in all its processes; load {f['load'][0]:.1f} -> {f['load'][1]:.1f}"
                  + ("" if f["code"] == 0 else f"; EXIT {f['code']}"))
            for line in f["said"]:
                print(f"    stderr: {line.strip()}")
            print(f"    {f['result'].strip()}")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
