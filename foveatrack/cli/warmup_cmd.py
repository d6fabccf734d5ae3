"""``foveatrack warmup``: compile the numba kernels ahead, once per install.

The kernels are compiled on first use and cached next to the sources (``cache=True``), so the first
``foveatrack demo`` after an install compiles them before its first frame
(:mod:`foveatrack.cli.kernel_compile`: two processes at once).  This command does that work up front:
the demo scene's kernels in two processes (when the cache is cold), then two frames of every shipped
scene (which compiles what the other scenes add: fog, flapping wings, mixed pixels, ...), the scan
analyses and the recording's point packing.  A second call only loads the cache and takes a few seconds.
"""

from __future__ import annotations

import sys
import time

from foveatrack.cli.demo_work import DEFAULT_SCENE, scan_analyses, shipped_scene, warm_recording_kernels


def register(sub) -> None:
    p = sub.add_parser("warmup", help="compile the numba kernels ahead (about a minute, once per install)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_warmup)


def warm_up(progress: bool = True, split: bool = True) -> float:
    """Run every kernel path the demo and the shipped scenes use once; returns the wall time [s].
    ``split``: on a cold cache and two cores or more, compile the demo scene's kernels in two
    processes at once first (:func:`foveatrack.cli.kernel_compile.compile_split`)."""
    from tqdm import tqdm

    from foveatrack.cli import kernel_compile

    from sim.loop import run_scene
    from sim.scan.coverage import voxel_coverage, voxel_grid
    from sim.scan.model import ScanModel
    from sim.scene import load_scene, with_run_overrides

    scenes_dir = shipped_scene(DEFAULT_SCENE).parent
    paths = sorted(scenes_dir.glob("*.toml"))
    t0 = time.perf_counter()
    if split and kernel_compile.wants_split():
        kernel_compile.compile_split(shipped_scene(DEFAULT_SCENE), stream=sys.stderr if progress else None)
    with tqdm(total=len(paths) + 1, desc="compiling numba kernels", unit=" step", disable=not progress,
              file=sys.stderr) as bar:
        for path in paths:
            scene = load_scene(path)
            bar.set_postfix_str(path.stem)
            run_scene(with_run_overrides(scene, duration_s=2 * scene.tracker.period_s))
            bar.update(1)
        bar.set_postfix_str("scan analyses")
        optics = load_scene(shipped_scene(DEFAULT_SCENE)).optics
        voxel_coverage(ScanModel(optics), 0.01, voxel_grid(optics, reference_rays=20_000))
        scan_analyses(optics, short=True)       # the demo's density (exact, paraxial) and coverage
        warm_recording_kernels()
        bar.update(1)
    return time.perf_counter() - t0


def cmd_warmup(args) -> int:
    wall = warm_up(progress=not args.no_progress)
    from foveatrack.cli.kernel_cache import cached_text

    print(f"numba kernels ready in {wall:.1f} s ({cached_text()})")
    return 0
