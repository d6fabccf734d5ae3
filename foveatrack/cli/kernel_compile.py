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

The demo's scan figures after its run (the FoV line, density and coverage: ``trace_exact_kernel`` and
the coverage kernels, ~10 s of CPU) are no part of any run, so the two processes the run waits for do
not compile them: a third process (:class:`FigureCompile`) does, started when the group that owns the
scan kernels is done, beside the other group and then the demo's run, and the demo waits for it only
before its figures.

``python -m foveatrack.cli.kernel_compile GROUP SCENE.toml`` is one such process (GROUP: 1, 2 or
``figures``).
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
                ("sim.scan.kernels", "sim.random_kernels", "foveatrack.kernels", "foveatrack.recording.pack_kernels"),
                ("sim.scan.kernels:scan_exact_kernel", "foveatrack.kernels:box_median_kernel",
                 "foveatrack.recording.pack_kernels:pack_grid_kernel")),
    KernelGroup("world and sensor kernels",
                ("sim.world.kernels", "sim.sensor_kernels", "sim.portable_exp"),
                ("sim.world.kernels:cast_static_kernel", "sim.world.kernels:rotate_head_pieces_kernel",
                 "sim.sensor_kernels:assemble_returns_kernel")),
)


# The process of the demo's scan figures starts once this group (the owner of sim.scan.kernels, whose
# kernels the figures also call) is done: then it only loads that group's kernels and compiles its own.
FIGURES_AFTER_GROUP = 0
# A kernel only the scan figures call (through ScanModel.directions_from_revs): whether they are cached.
FIGURES_SENTINEL = "sim.scan.kernels:trace_exact_kernel"


def _dispatcher(spec: str):
    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)


def cache_is_cold(sentinels=None) -> bool:
    """Whether a kernel every first frame calls (or one of ``sentinels``) has no up-to-date cache entry
    (a fresh clone, or its source changed since).  False where numba's cache cannot be read this way
    (then a first frame compiles what it needs itself, as before, and says so)."""
    if sentinels is None:
        sentinels = [spec for group in GROUPS for spec in group.sentinels]
    try:
        for spec in sentinels:
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
    if "foveatrack.recording.pack_kernels" in GROUPS[index].modules:
        from foveatrack.cli.demo_work import warm_recording_kernels

        warm_recording_kernels()


def compile_figures(scene_path) -> None:
    """Compile the kernels of the demo's scan figures for the scene's lidar (the body of the figures
    process): what the scan kernels' group left, that group's own kernels loaded from the cache; the
    other group's, which the figures do not call, as Python (that group may still be compiling)."""
    import numpy as np

    from foveatrack.cli.demo_work import scan_analyses
    from sim.scan.model import ScanModel
    from sim.scene import load_scene

    run_kernels_as_python([m for i, g in enumerate(GROUPS) if i != FIGURES_AFTER_GROUP for m in g.modules])
    optics = load_scene(scene_path).optics
    with np.errstate(all="ignore"):
        scan_analyses(optics, short=True)
        # the FoV line (sim.scan.fov): the same trace kernel, in the types the FoV search calls it with
        ScanModel(optics).directions_from_revs(np.zeros((4, len(optics.prisms))), np.zeros(4, np.int64))


def _saying(stream):
    return (lambda text: print(text, file=stream, flush=True)) if stream is not None else (lambda text: None)


class _CompileProcess:
    """One ``python -m foveatrack.cli.kernel_compile WHAT SCENE.toml``, its stderr kept for the last
    line of a failure."""

    def __init__(self, what: str, scene_path, label: str):
        self.label = label
        self._err = tempfile.TemporaryFile()
        cmd = [sys.executable, "-m", "foveatrack.cli.kernel_compile", what, str(scene_path)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=self._err)

    def running(self) -> bool:
        return self.proc.poll() is None

    def outcome(self, t0: float, if_failed: str) -> str:
        """How it ended, to say once it has: ready after how long since ``t0``, or why not."""
        if self.proc.returncode == 0:
            return f"  {self.label}: ready after {time.perf_counter() - t0:.0f} s"
        self._err.seek(0)
        lines = self._err.read().decode(errors="replace").strip().splitlines() or ["(no message)"]
        return f"  {self.label}: the compile process failed (exit {self.proc.returncode}: {lines[-1]}); {if_failed}"

    def end(self) -> None:
        """Kill it if it still runs (an interrupted caller must not leave a compile running)."""
        _end(self.proc)
        self._err.close()


class FigureCompile:
    """The demo's scan-figure kernels compiled by a process of their own (:func:`compile_figures`),
    beside the run: :meth:`start` it (:func:`compile_split` does, once the scan kernels' group is
    done), :meth:`wait` for it before the figures, :meth:`close` it in any case.  Says on ``stream``
    (None: silent) what it does."""

    LABEL = "the scan figures' kernels"

    def __init__(self, scene_path, stream=None):
        self._scene_path = scene_path
        self._say = _saying(stream)
        self._process: _CompileProcess | None = None
        self._t0 = time.perf_counter()

    @classmethod
    def wanted(cls, scene_path, stream=None) -> "FigureCompile | None":
        """One for ``scene_path`` where it pays (two cores or more, the figures' kernels not cached),
        else None (the figures then load or compile their kernels in the caller's process)."""
        import os

        if (os.cpu_count() or 1) < 2 or not cache_is_cold([FIGURES_SENTINEL]):
            return None
        return cls(scene_path, stream)

    def start(self) -> None:
        if self._process is None:
            self._process = _CompileProcess("figures", self._scene_path, f"[+] {self.LABEL}")
            self._say(f"  {self._process.label}: compiling beside the run ...")

    def wait(self) -> None:
        """Wait for the process (starting it first if nothing did) and say how it ended; the figures
        compile what a failed process left, in the caller's process."""
        self.start()
        try:
            while self._process.running():
                time.sleep(0.05)
            self._say(self._process.outcome(self._t0, "the figures compile what is missing"))
        finally:
            self._process.end()

    def close(self) -> None:
        if self._process is not None:
            self._process.end()


def compile_split(scene_path, stream=None, figures: FigureCompile | None = None) -> float:
    """Compile the kernels of a run of ``scene_path`` in one process per group, at once, and wait
    for them; says on ``stream`` (None: silent) what it compiles and when each group is ready.
    ``figures``: started as soon as group :data:`FIGURES_AFTER_GROUP` is ready (not waited for).
    Returns the wall time [s].  A process that fails is reported; the run then compiles what is
    missing in its first frame, as without this."""
    say = _saying(stream)
    n = len(GROUPS)
    say(f"compiling the numba kernels, once per install (`foveatrack warmup` does it ahead), "
        f"{n} groups in {n} processes at once:")
    t0 = time.perf_counter()
    procs: list[_CompileProcess] = []
    try:
        for i, group in enumerate(GROUPS):
            procs.append(_CompileProcess(str(i + 1), scene_path, f"[{i + 1}/{n}] {group.name}"))
            say(f"  {procs[-1].label} ...")
        waiting = list(enumerate(procs))
        while waiting:
            for item in list(waiting):
                i, process = item
                if process.running():
                    continue
                waiting.remove(item)
                say(process.outcome(t0, "the first frame compiles what is missing"))
                if figures is not None and i == FIGURES_AFTER_GROUP and process.proc.returncode == 0:
                    figures.start()
            time.sleep(0.05)
    finally:
        for process in procs:
            process.end()
    wall = time.perf_counter() - t0
    say(f"kernels compiled in {wall:.0f} s (cached next to the sources; later runs load them)")
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
    if len(argv) != 2 or argv[0] not in {str(i + 1) for i in range(len(GROUPS))} | {"figures"}:
        print(f"usage: python -m foveatrack.cli.kernel_compile GROUP(1..{len(GROUPS)}|figures) SCENE.toml",
              file=sys.stderr)
        return 2
    if argv[0] == "figures":
        compile_figures(Path(argv[1]))
    else:
        compile_group(int(argv[0]) - 1, Path(argv[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
