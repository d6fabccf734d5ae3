"""The first run's numba compile, kernel by kernel: ``foveatrack warmup`` on an empty cache.

    python scripts/bench_first_compile.py [--top 25] [--kernel cast_static | --groups]

Runs :func:`foveatrack.cli.warmup_cmd.warm_up` in this one process (``split=False``) with
``NUMBA_CACHE_DIR`` pointed at a new temporary directory (the cache next to the sources is neither
read nor touched), and prints the wall time, the process's CPU time, and the CPU seconds of each
kernel's own compile, per signature (exclusive: a kernel's figure does not include the helpers it
calls that numba compiles as functions of their own; a kernel listed twice was compiled for two
argument types).  ``--group 1`` / ``--group 2`` does what one compile process of a first run does
(:mod:`foveatrack.cli.kernel_compile`) instead: how well the two processes share the work.  CPU seconds are the
figure to compare on a shared machine: the wall time grows with the load, the CPU time barely.
``--kernel cast_static`` times that one kernel's compile alone (the world's background cast, the
largest before it was split into non-inlined block helpers).  Say the load (``uptime``) with a figure.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict

if __name__ == "__main__" and "NUMBA_CACHE_DIR" not in os.environ:
    # numba reads the variable at import: set it, then run this script again in a fresh interpreter
    with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
        os.environ["NUMBA_CACHE_DIR"] = cache
        import subprocess

        sys.exit(subprocess.call([sys.executable] + sys.argv))


def _listen() -> dict[str, float]:
    from numba.core import event

    own: dict[str, float] = defaultdict(float)
    stack: list[list[float]] = []

    class Compiles(event.Listener):
        def on_start(self, ev):
            stack.append([time.process_time(), 0.0])

        def on_end(self, ev):
            t0, inner = stack.pop()
            t = time.process_time() - t0
            f = ev.data["dispatcher"].py_func
            sig = ", ".join(str(a).split("(")[0] + ("[literal]" if "Literal" in str(a) else "")
                            + ("[strided]" if "'A'" in str(a) else "") for a in ev.data["args"])
            own[f"{f.__module__}.{f.__qualname__}({sig})"] += t - inner
            if stack:
                stack[-1][1] += t

    event.register("numba:compile", Compiles())
    return own


def _cast_static() -> None:
    import numpy as np

    from sim.world import kernels as K

    d = np.random.default_rng(0).normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    prims = np.zeros((6, 13))
    prims[:, 0] = K.RECT
    K.cast_static_kernel(d, prims, 0, np.full(1000, np.inf), np.full(1000, -1, np.int64))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--top", type=int, default=25, help="kernels listed (default 25)")
    ap.add_argument("--kernel", choices=["cast_static"], help="compile this kernel alone")
    ap.add_argument("--group", type=int, choices=[1, 2],
                    help="compile what this compile process of a first run compiles (foveatrack.cli.kernel_compile)")
    args = ap.parse_args()
    own = _listen()
    t0, c0 = time.perf_counter(), time.process_time()
    if args.kernel:
        _cast_static()
    elif args.group:
        from foveatrack.cli.demo_work import DEFAULT_SCENE, shipped_scene
        from foveatrack.cli.kernel_compile import compile_group

        compile_group(args.group - 1, shipped_scene(DEFAULT_SCENE))
    else:
        from foveatrack.cli.warmup_cmd import warm_up

        warm_up(progress=False, split=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    what = args.kernel or (f"compile group {args.group}" if args.group else "foveatrack warmup")
    print(f"{what}, empty cache: wall {wall:.1f} s, CPU {cpu:.1f} s, "
          f"of it numba compiles {sum(own.values()):.1f} s CPU; load {os.getloadavg()[0]:.1f}")
    for name, t in sorted(own.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"  {t:6.2f} s  {name}")


if __name__ == "__main__":
    main()
