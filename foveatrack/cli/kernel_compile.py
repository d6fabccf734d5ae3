"""The numba kernels' first compile, split across two processes (a first run, ``foveatrack warmup``).

numba compiles a kernel on its first call, for the argument types of that call, and caches the
result next to the sources (``cache=True``: one index file per function, one data file per
signature).  A first run after an install used to compile them one after another inside its first
frame, on one core: ~80 s of CPU.

Here the kernels the closed loop and the demo need are cut into two groups by module
(:data:`GROUPS`), and each group is compiled by a process of its own, both at once.  Each process
runs the first two frames of the scene with the *other* group's kernels run as plain Python (their
``py_func``: the very code numba compiles, uncompiled), so it compiles exactly its own group, in the
argument types the run gives them, and the two never compile one function.  They must not: numba
rewrites a function's whole index when it adds a signature, so two processes adding different
signatures to one function at once can leave the index naming the other one's data file
(``tests/test_kernel_compile.py`` checks that a split compile leaves every entry naming its own
signature, and that the demo's first frame then compiles nothing).  The caller waits for both and
then loads everything from the cache.

``python -m foveatrack.cli.kernel_compile GROUP SCENE.toml`` is one such process (GROUP: 1 or 2).
"""

from __future__ import annotations

import importlib
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class KernelGroup:
    name: str
    modules: tuple[str, ...]       # every numba kernel defined in (or imported into) these modules
    sentinels: tuple[str, ...]     # "module:function": kernels the first frame always calls


# Cut where the CPU seconds of the first compile split about evenly (scripts/bench_first_compile.py
# --group N): each compile process alone on an empty cache took 31-34 s of CPU here, ~5 s of it the
# imports and the two frames whose other kernels run as Python (docs/first-run.md).
GROUPS = (
    KernelGroup("scan, tracker and recording kernels",
                ("sim.scan.kernels", "sim.random_kernels", "foveatrack.kernels", "foveatrack.recording.pack_kernels",
                 # the sky tracker's (a sky scene's run calls them from its first frame, and its warm-up's
                 # end in compile_sky_kernels): in one group, or both processes compile them, and a
                 # kernel of one calling an inline helper of foveatrack.kernels fails where that runs as Python
                 "foveatrack.openloop.kernels", "foveatrack.openloop.range_background", "foveatrack.sky.world_points",
                 "foveatrack.sky.features", "foveatrack.sky.motion", "foveatrack.sky.attention",
                 "foveatrack.pose_check"),
                ("sim.scan.kernels:scan_exact_kernel", "foveatrack.kernels:box_median_kernel",
                 "foveatrack.recording.pack_kernels:pack_grid_kernel")),
    KernelGroup("world and sensor kernels",
                ("sim.world.kernels", "sim.sensor_kernels", "sim.portable_exp"),
                ("sim.world.kernels:cast_static_kernel", "sim.world.kernels:rotate_head_pieces_kernel",
                 "sim.sensor_kernels:assemble_returns_kernel")),
)


def _dispatcher(spec: str):
    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)


def cache_is_cold() -> bool:
    """Whether a kernel every first frame calls has no up-to-date cache entry (a fresh clone, or its
    source changed since).  False where numba's cache cannot be read this way (then a first frame
    compiles what it needs itself, as before, and says so)."""
    try:
        for group in GROUPS:
            for spec in group.sentinels:
                # numba's own reader: empty when the file is missing, or its source stamp is stale
                if not _dispatcher(spec)._cache._cache_file._load_index():
                    return True
    except Exception:      # a numba without this layout: fall back to compiling in the first frame
        return False
    return False


def wants_split() -> bool:
    """Whether a run should compile in :func:`compile_split` first: two cores or more, and a cold
    cache (:func:`cache_is_cold`).  The one rule for ``simulate``, ``demo`` and ``warmup``."""
    import os

    return (os.cpu_count() or 1) >= 2 and cache_is_cold()


def run_kernels_as_python(modules) -> None:
    """Replace every numba dispatcher bound in ``modules`` by its Python function, for the rest of
    this process (a compile process only: modules that keep a kernel they looked up keep this one)."""
    from numba.core.dispatcher import Dispatcher

    for name in modules:
        module = importlib.import_module(name)
        for attr, value in list(vars(module).items()):
            if isinstance(value, Dispatcher):
                setattr(module, attr, value.py_func)


def compile_group(index: int, scene_path) -> None:
    """Compile group ``index``'s kernels in the types the scene's run uses, and the demo scene's (the
    body of a compile process).  The demo scene's too: its kernels include every sentinel, so a
    scene that calls fewer kernels does not leave the cache looking cold run after run."""
    import numpy as np

    from foveatrack.cli.demo_work import DEFAULT_SCENE, shipped_scene
    from sim.loop import run_scene
    from sim.scene import load_scene, with_run_overrides

    run_kernels_as_python([m for i, g in enumerate(GROUPS) if i != index for m in g.modules])
    demo = shipped_scene(DEFAULT_SCENE)
    for path in [Path(scene_path)] + ([] if Path(scene_path).resolve() == demo else [demo]):
        scene = load_scene(path)
        with np.errstate(all="ignore"):     # the Python twins' divisions by zero (numba's error_model="numpy")
            run_scene(with_run_overrides(scene, duration_s=2 * scene.tracker.period_s), ahead=False)
    if "sim.random_kernels" in GROUPS[index].modules:
        # the run above is one-threaded; with a free core the run draws its streams ahead in blocks
        # (sim.ahead.DrawsAhead), whose fill kernels it then calls: the demo compiled them in its own
        # process whenever it found a core free (a whole-suite run of tests/test_kernel_compile.py)
        from sim import random_kernels as rk

        for fill in (rk.fill_uniform_kernel, rk.fill_standard_normal_kernel):
            fill(np.random.default_rng(0), np.empty(4))
    if "sim.scan.kernels" in GROUPS[index].modules:
        from foveatrack.cli.demo_work import scan_analyses

        scan_analyses(load_scene(scene_path).optics, short=True)      # the demo's scan figures, after its run
    if "foveatrack.recording.pack_kernels" in GROUPS[index].modules:
        from foveatrack.cli.demo_work import warm_recording_kernels

        warm_recording_kernels()


def compile_split(scene_path, stream=None) -> float:
    """Compile the kernels of a run of ``scene_path`` in one process per group, at once, and wait
    for them; says on ``stream`` (None: silent) what it compiles and when each group is ready.
    Returns the wall time [s].  A process that fails is reported; the run then compiles what is
    missing in its first frame, as without this."""
    say = (lambda text: print(text, file=stream, flush=True)) if stream is not None else (lambda text: None)
    n = len(GROUPS)
    say(f"compiling the numba kernels, once per install (`foveatrack warmup` does it ahead), "
        f"{n} groups in {n} processes at once:")
    t0 = time.perf_counter()
    procs = []
    try:
        for i, group in enumerate(GROUPS):
            err = tempfile.TemporaryFile()
            cmd = [sys.executable, "-m", "foveatrack.cli.kernel_compile", str(i + 1), str(scene_path)]
            procs.append((i, group, subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err), err))
            say(f"  [{i + 1}/{n}] {group.name} ...")
        waiting = list(procs)
        while waiting:
            for item in list(waiting):
                i, group, proc, err = item
                if proc.poll() is None:
                    continue
                waiting.remove(item)
                if proc.returncode == 0:
                    say(f"  [{i + 1}/{n}] {group.name}: ready after {time.perf_counter() - t0:.0f} s")
                else:
                    err.seek(0)
                    lines = err.read().decode(errors="replace").strip().splitlines() or ["(no message)"]
                    say(f"  [{i + 1}/{n}] {group.name}: the compile process failed (exit {proc.returncode}: "
                        f"{lines[-1]}); the first frame compiles what is missing")
            time.sleep(0.05)
    finally:
        for _, _, proc, err in procs:
            _end(proc)                  # interrupted: do not leave a compile running
            err.close()
    wall = time.perf_counter() - t0
    from foveatrack.cli.kernel_cache import cached_text

    say(f"kernels compiled in {wall:.0f} s ({cached_text()})")
    return wall


def _end(proc) -> None:
    """Kill and reap a compile process that has not ended, without ``Popen.poll()`` or ``wait()``: a
    Ctrl-C just after ``poll()`` took the Popen's lock (the wait above polls) leaves it taken, and a
    ``wait()`` then blocks for ever (docs/interrupts.md, the writer process's same wait)."""
    import os
    import signal

    if proc.returncode is not None:
        return
    try:
        os.kill(proc.pid, signal.SIGKILL)
        proc.returncode = os.waitstatus_to_exitcode(os.waitpid(proc.pid, 0)[1])
    except (ProcessLookupError, ChildProcessError):     # already reaped
        pass


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0] not in {str(i + 1) for i in range(len(GROUPS))}:
        print(f"usage: python -m foveatrack.cli.kernel_compile GROUP(1..{len(GROUPS)}) SCENE.toml", file=sys.stderr)
        return 2
    compile_group(int(argv[0]) - 1, Path(argv[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
