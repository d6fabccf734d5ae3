"""``foveatrack demo``: the main job of the README quick start.

Until the closed-loop tracker lands this is the scan-model demo: the prototype's FoV (exact and
paraxial), its pattern, its radial density against eq. (4) and its coverage curve, printed and
plotted into ``--out``.
"""

from __future__ import annotations

import json
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("demo", help="the quick-start demo: run the default scene, print metrics, write plots")
    p.add_argument("--out", default="out/demo", help="directory for plots and the JSON summary")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args) -> int:
    import numpy as np

    from foveatrack.cli.lidar_cmd import _pattern_plot, info_dict
    from foveatrack.cli.scan_plots import plot_coverage, plot_density
    from sim.scan.coverage import voxel_coverage
    from sim.scan.density import radial_density
    from sim.scan.model import ScanModel
    from sim.scan.optics import SpeedNoise
    from sim.scan.presets import PRESETS

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    optics = PRESETS["prototype"]
    info = info_dict(optics, "exact")
    print(f"prototype (paper Appendix B): FoV {info['fov_deg'][0]:.2f} deg exact, "
          f"{info['paraxial_fov_deg'][0]:.2f} deg paraxial")
    _pattern_plot(optics, "exact", 0.1, out / "pattern.png")
    exact = radial_density(ScanModel(optics), 2.0)
    para = radial_density(ScanModel(optics, model="paraxial"), 2.0)
    plot_density(para, exact, "prototype: radial density, 2 s", out / "density.png")
    noisy = ScanModel(optics, speed_noise=SpeedNoise(), rng=np.random.default_rng(0))
    curve = voxel_coverage(noisy, 2.0)
    plot_coverage([("voxel, 1 % speed noise", curve)], "prototype: coverage (paper Appendix C)", out / "coverage.png")
    print(f"coverage (voxel, 1 % speed noise): 50 % at {curve.t50_s:.3f} s, 90 % at {curve.t90_s:.3f} s")
    summary = {"info": info, "coverage_t50_s": curve.t50_s, "coverage_t90_s": curve.t90_s}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"plots and summary.json written to {out}/")
    return 0
