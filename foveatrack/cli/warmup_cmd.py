"""``foveatrack warmup``: compile the numba kernels ahead, once per install.

The kernels are compiled on first use and cached next to the sources (``cache=True``), so the first
``foveatrack demo`` after an install spends about a minute compiling inside its first frame.  This
command does that work up front: it runs two frames of every shipped scene (which compiles the scan,
world, sensor and tracker kernels in the argument types the closed loop uses) and the scan analyses the
demo draws (radial density, voxel coverage), and the recording's point packing.  A second call only loads the cache and takes a few seconds.
"""

from __future__ import annotations

import sys
import time

from foveatrack.cli.demo_cmd import shipped_scene


def register(sub) -> None:
    p = sub.add_parser("warmup", help="compile the numba kernels ahead (about a minute, once per install)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_warmup)


def warm_up(progress: bool = True) -> float:
    """Run every kernel path the demo and the shipped scenes use once; returns the wall time [s]."""
    from tqdm import tqdm

    from sim.loop import run_scene
    from sim.scan.coverage import voxel_coverage, voxel_grid
    from sim.scan.density import radial_density
    from sim.scan.model import ScanModel
    from sim.scene import load_scene, with_run_overrides

    scenes_dir = shipped_scene("fig12-tracking.toml").parent
    paths = sorted(scenes_dir.glob("*.toml"))
    t0 = time.perf_counter()
    with tqdm(total=len(paths) + 1, desc="compiling numba kernels", unit=" step", disable=not progress,
              file=sys.stderr) as bar:
        for path in paths:
            scene = load_scene(path)
            bar.set_postfix_str(path.stem)
            run_scene(with_run_overrides(scene, duration_s=2 * scene.tracker.period_s))
            bar.update(1)
        bar.set_postfix_str("scan analyses")
        optics = load_scene(shipped_scene("fig12-tracking.toml")).optics
        radial_density(ScanModel(optics), 0.01)
        voxel_coverage(ScanModel(optics), 0.01, voxel_grid(optics, reference_rays=20_000))
        _warm_recording_kernels()
        bar.update(1)
    return time.perf_counter() - t0


def _warm_recording_kernels() -> None:
    """The recording's point packing (``simulate --out``, the daemon): a frame on the mm grid, int16
    and int32 times."""
    import numpy as np

    from foveatrack.recording.pack_kernels import pack_points

    xyz = np.zeros((2, 3))
    for dt in (np.array([0, -10_000], np.int64), np.array([0, -1_000_001], np.int64)):
        pack_points(xyz, dt, np.zeros(2, np.uint8))


def cmd_warmup(args) -> int:
    wall = warm_up(progress=not args.no_progress)
    print(f"numba kernels ready in {wall:.1f} s (cached next to the sources; later runs load them)")
    return 0
