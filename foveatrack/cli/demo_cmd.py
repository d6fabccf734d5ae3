"""``foveatrack demo``: the main job of the README quick start.

A closed-loop tracking run of the default scene (``scenes/fig12-tracking.toml``: a Mid-40 on a
PTS-303H head tracking a quadrotor that enters the FoV off-centre), printing its metrics and writing
its recording and plots, followed by the scan model's own figures (pattern, radial density against
eq. 4, coverage) for the same lidar.
"""

from __future__ import annotations

from pathlib import Path

from foveatrack.errors import UserError

DEFAULT_SCENE = "fig12-tracking.toml"


def shipped_scene(name: str) -> Path:
    """Path of a scene shipped in the repository's ``scenes/`` folder."""
    path = Path(__file__).resolve().parents[2] / "scenes" / name
    if not path.is_file():
        raise UserError(f"shipped scene {name} not found at {path}; run from a checkout (pip install -e .)")
    return path


def register(sub) -> None:
    p = sub.add_parser("demo", help="the quick-start demo: a closed-loop tracking run, metrics and plots")
    p.add_argument("--out", default="out/demo", help="directory for the recording, plots and summary")
    p.add_argument("--scene", default=None, help=f"scene file (default: scenes/{DEFAULT_SCENE})")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_demo)


def scan_analyses(optics, short: bool = False) -> dict:
    """The demo's scan figures for ``optics``: the radial density (exact and paraxial, two-prism
    scanners only) and the voxel coverage with 1 % speed noise.  ``short``: a few milliseconds of
    each (the same kernels in the same types; for the first compile, :mod:`foveatrack.cli.kernel_compile`)."""
    import numpy as np

    from sim.scan.coverage import voxel_coverage
    from sim.scan.density import radial_density
    from sim.scan.model import ScanModel
    from sim.scan.optics import SpeedNoise

    density_s, coverage_s = (0.01, 0.01) if short else (1.0, 2.0)
    out = {}
    if len(optics.prisms) == 2:
        out["density_exact"] = radial_density(ScanModel(optics), density_s)
        out["density_paraxial"] = radial_density(ScanModel(optics, model="paraxial"), density_s)
    noisy = ScanModel(optics, speed_noise=SpeedNoise(), rng=np.random.default_rng(0))
    out["coverage"] = voxel_coverage(noisy, coverage_s)
    return out


def cmd_demo(args) -> int:
    from foveatrack.cli.lidar_cmd import _pattern_plot, info_dict
    from foveatrack.cli.scan_plots import plot_coverage, plot_density
    from foveatrack.cli.simulate_cmd import run_and_report
    from sim.scene import load_scene

    out = Path(args.out)
    scene_path = args.scene or shipped_scene(DEFAULT_SCENE)
    run_and_report(scene_path, out, plot=True, progress=not args.no_progress)

    optics = load_scene(scene_path).optics
    scan_dir = out / "scan"
    scan_dir.mkdir(parents=True, exist_ok=True)
    info = info_dict(optics, "exact")
    print(f"lidar {optics.name}: FoV {info['fov_deg'][0]:.2f} x {info['fov_deg'][1]:.2f} deg exact "
          f"({info['paraxial_fov_deg'][0]:.2f} paraxial), {optics.point_rate_hz} points/s")
    _pattern_plot(optics, "exact", 0.1, scan_dir / "pattern.png")
    figures = scan_analyses(optics)
    if "density_exact" in figures:
        plot_density(figures["density_paraxial"], figures["density_exact"],
                     f"{optics.name}: radial density, 1 s (paper Fig. 5, eq. 4)", scan_dir / "density.png")
    curve = figures["coverage"]
    plot_coverage([("voxel, 1 % speed noise", curve)], f"{optics.name}: coverage, voxel definition (paper Fig. 6e)",
                  scan_dir / "coverage.png")
    print(f"  coverage (voxel, 1 % speed noise): 50 % at {curve.t50_s:.2f} s, 90 % at {curve.t90_s:.2f} s")
    print(f"plots: {out}/error.png, points_on_target.png, trajectory.png, head.png, scan/*.png")
    return 0
