"""``foveatrack demo``: the main job of the README quick start.

A closed-loop tracking run of the default scene (``scenes/fig12-tracking.toml``: a Mid-40 on a
PTS-303H head tracking a quadrotor that enters the FoV off-centre), printing its metrics and writing
its recording and plots, followed by the scan model's own figures (pattern, radial density against
eq. 4, coverage) for the same lidar.
"""

from __future__ import annotations

from pathlib import Path

from foveatrack.cli.demo_work import DEFAULT_SCENE, scan_analyses, shipped_scene

DEFAULT_OUT = "out/demo"      # the demo's own directory: a second demo replaces the first's files

def register(sub) -> None:
    p = sub.add_parser("demo", help="the quick-start demo: a closed-loop tracking run, metrics and plots")
    p.add_argument("--out", default=DEFAULT_OUT, help="directory for the recording, plots and summary (default "
                                                    f"{DEFAULT_OUT}, which a demo replaces; another directory's "
                                                    "recording is replaced only with --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace the recording an --out directory holds")
    p.add_argument("--scene", default=None, help=f"scene file (default: scenes/{DEFAULT_SCENE})")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_demo)


def replaces(out, asked: bool) -> bool:
    """Whether the demo replaces the recording ``out`` holds: its own directory's (the quick start is
    run again), another's only when asked (simulate's rule; it replaced another run's recording)."""
    return asked or Path(out) == Path(DEFAULT_OUT)


def cmd_demo(args) -> int:
    from foveatrack.cli.lidar_cmd import _pattern_plot, info_dict
    from foveatrack.cli.scan_plots import plot_coverage, plot_density
    from foveatrack.cli.simulate_cmd import run_and_report
    from sim.scene import load_scene

    out = Path(args.out)
    scene_path = args.scene or shipped_scene(DEFAULT_SCENE)
    run_and_report(scene_path, out, plot=True, progress=not args.no_progress,
                   overwrite=replaces(args.out, args.overwrite))

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
