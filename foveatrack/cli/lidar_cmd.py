"""``foveatrack lidar ...``: the scan model's analyses (paper Fig. 4-9, Appendix B, C).

``PRESET`` is a preset name (``prototype``, ``mid40``, ``horizon``) or a TOML file whose ``[lidar]``
table (or top level) describes custom optics: ``point_rate_hz``, ``channel_offsets_deg``,
``beam_divergence_deg`` and ``[[lidar.prisms]]`` with ``wedge_deg``, ``index``, ``tilted_face``,
``rpm``, ``phase_deg``.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from foveatrack.config_util import positive_arg, seed_arg
from foveatrack.errors import UserError

TWO_PRISM_PRESETS = ("prototype", "mid40", "mid70", "avia", "tele15", "mid100")   # coverage-map's (Fig. 7)


def register(sub) -> None:
    lidar = sub.add_parser("lidar", help="scan-model analyses: FoV, pattern, density, coverage")
    lsub = lidar.add_subparsers(dest="lidar_command", metavar="ANALYSIS", required=True)

    def common(p, duration: float | None = None):
        p.add_argument("preset", metavar="PRESET",
                       help="prototype | mid40 | horizon | mid70 | avia | tele15 | mid100 | optics.toml")
        p.add_argument("--model", choices=("exact", "paraxial"), default="exact",
                       help="exact refraction (default) or the paraxial vector sum")
        if duration is not None:
            p.add_argument("--duration", type=positive_arg, default=duration, metavar="S",
                           help=f"accumulation time in seconds (default {duration:g})")
            p.add_argument("--noise", type=float, default=None, metavar="FRAC",
                           help="motor speed noise, 1-sigma relative (paper: 0.01); default none")
            p.add_argument("--seed", type=seed_arg, default=0, help="seed of the speed noise")
        p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
        p.add_argument("--plot", metavar="FILE.png", help="write a plot")

    p = lsub.add_parser("info", help="FoV, point rate, channels (paraxial model reported alongside)")
    common(p)
    p.set_defaults(func=cmd_info)

    p = lsub.add_parser("pattern", help="the scan pattern (paper Fig. 4, 8, 9c)")
    common(p, duration=0.1)
    p.set_defaults(func=cmd_pattern)

    p = lsub.add_parser("density", help="radial density vs the analytic eq. (4) (paper Fig. 5)")
    common(p, duration=2.0)
    p.add_argument("--bins", type=int, default=60, help="radial bins of the density profile (default 60)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr (shown on long runs)")
    p.set_defaults(func=cmd_density)

    p = lsub.add_parser("coverage", help="coverage vs accumulation time (paper Fig. 6e)")
    common(p, duration=2.0)
    p.add_argument("--method", choices=("voxel", "footprint", "footprint-fixed"), default="voxel",
                   help="voxel: paper Appendix C 100x100 grid; footprint: Livox's FoV coverage (the beam's "
                        "swath, as wide as its divergence's major axis); footprint-fixed: the area of a "
                        "footprint held aligned with az/el (docs/livox-files.md)")
    p.add_argument("--compare", metavar="FILE.png",
                   help="plot ours against Livox's published curve (mid40, horizon, tele15; --method footprint; "
                        "runs to the curve's plateau, --duration ignored) and print the largest deviation")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr (shown on long runs)")
    p.set_defaults(func=cmd_coverage)

    p = lsub.add_parser("coverage-map", help="time to 90%% coverage over the two prism speeds (paper Fig. 7)")
    # (the two-prism presets by name, not imported at every start of the CLI: a test holds them to sim.scan.presets)
    p.add_argument("preset", metavar="PRESET", help=f"a two-prism scanner: {' | '.join(TWO_PRISM_PRESETS)} | optics.toml")
    p.add_argument("--rpm1", default="1000:12000", metavar="LO:HI", help="prism 1 speed range [rpm]")
    p.add_argument("--rpm2", default="-12000:-1000", metavar="LO:HI",
                   help="prism 2 speed range [rpm]; negative ranges need '=': --rpm2=-12000:-1000")
    p.add_argument("--grid", type=int, default=30, metavar="N", help="N x N speeds (default 30)")
    p.add_argument("--cap", type=positive_arg, default=5.0, metavar="S", help="time cap in seconds (paper: 5)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the motor speed noise (default 0)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on the Dask cluster at ADDRESS (tcp://host:port)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--json", action="store_true", help="print the map as JSON on stdout")
    p.add_argument("--plot", metavar="FILE.png", help="write the map as a plot (paper Fig. 7)")
    p.set_defaults(func=cmd_coverage_map)

    from foveatrack.cli.lidar_serve import add_serve_parser  # the virtual lidar (issue 6)

    add_serve_parser(lsub)


def _load(args):
    """The command's optics, after checking that its --plot file can be written (before the work)."""
    from foveatrack.config_util import check_output_file

    if getattr(args, "plot", None):
        check_output_file(args.plot, "--plot")
    return load_optics(args.preset)


# ``lidar density`` / ``lidar coverage`` stream the scan in chunks (memory does not grow with --duration),
# so a long run is only slow: a progress bar on stderr shows how far it is once it has run this long.
PROGRESS_DELAY_S = 1.0


class _Progress:
    """A tqdm bar on stderr over a run's scan samples, for a run of ``passes`` equal passes (``part(i)``
    is pass i's ``progress(done, total)`` callback); hidden with ``--no-progress`` and on runs shorter
    than :data:`PROGRESS_DELAY_S`.  ``total`` (all passes) when known before the run, else the
    first callback sets it."""

    def __init__(self, args, desc: str, total: int | None = None, passes: int = 1):
        from tqdm import tqdm

        self.passes = passes
        self.bar = tqdm(total=total, desc=desc, unit=" pts", unit_scale=True, file=sys.stderr, leave=False,
                        delay=PROGRESS_DELAY_S, disable=args.no_progress)

    def part(self, i: int = 0):
        def progress(done: int, total: int) -> None:
            self.bar.total = self.passes * total
            self.bar.update(i * total + done - self.bar.n)
        return progress

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.bar.close()


# ``lidar pattern`` holds every point (directions, times, channels) in memory: ~50 bytes a point.
PATTERN_MAX_POINTS = 20_000_000


def load_optics(spec: str):
    """A preset name or a TOML file of custom optics -> RisleyOptics (errors name the file and key)."""
    from foveatrack.config_util import read_toml
    from sim.scan.optics import OpticsError, optics_from_table
    from sim.scan.presets import PRESETS

    if spec in PRESETS:
        return PRESETS[spec]
    path = Path(spec)
    if path.suffix != ".toml":
        raise UserError(f"unknown preset {spec!r}: allowed {sorted(PRESETS)} or a .toml optics file")
    data, _ = read_toml(path, "optics")
    table = data.get("lidar", data)
    if not isinstance(table, dict):
        raise UserError(f"{path}: [lidar] must be a table of optics keys (prisms, point_rate_hz, ...)")
    table = {k: v for k, v in table.items() if k not in ("preset", "mount")}
    try:
        return optics_from_table(table, where=f"{path} [lidar]")
    except OpticsError as exc:
        raise UserError(str(exc)) from None


def _scan_model(args, optics):
    import numpy as np

    from sim.scan.model import ScanModel
    from sim.scan.optics import OpticsError, SpeedNoise

    noise = getattr(args, "noise", None)
    if noise is None:
        return ScanModel(optics, model=args.model)
    try:
        sn = SpeedNoise(sigma_frac=noise)
    except OpticsError as exc:
        raise UserError(f"--noise: {exc}") from None
    return ScanModel(optics, model=args.model, speed_noise=sn, rng=np.random.default_rng(args.seed))


def _emit(args, result: dict, lines: list[str]) -> None:
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print("\n".join(lines))


def info_dict(optics, model: str) -> dict:
    from sim.scan.fov import field_of_view_deg

    fov = field_of_view_deg(optics, model=model)
    other = "paraxial" if model == "exact" else "exact"
    fov_other = field_of_view_deg(optics, model=other)
    exact, paraxial = (fov, fov_other) if model == "exact" else (fov_other, fov)
    period = optics.repeat_period_s()
    return {
        "name": optics.name,
        "model": model,
        "fov_deg": [round(fov[0], 4), round(fov[1], 4)],
        "point_rate_hz": optics.point_rate_hz,
        "channels": optics.channels,
        "exact_fov_deg": [round(exact[0], 4), round(exact[1], 4)],
        "paraxial_fov_deg": [round(paraxial[0], 4), round(paraxial[1], 4)],
        "paraxial_error_deg": [round(paraxial[0] - exact[0], 4), round(paraxial[1] - exact[1], 4)],
        "repeat_period_s": period,
        "prisms": [
            {"wedge_deg": p.wedge_deg, "index": p.index, "tilted_face": p.tilted_face, "rpm": p.rpm, "phase_deg": p.phase_deg}
            for p in optics.prisms
        ],
        "channel_offsets_deg": [list(c) for c in optics.channel_offsets_deg],
        "beam_divergence_deg": list(optics.beam_divergence_deg),
        **({"head_yaw_deg": list(optics.head_yaw_deg)} if optics.head_yaw_deg else {}),
    }


def cmd_info(args) -> int:
    optics = _load(args)
    info = info_dict(optics, args.model)
    err = info["paraxial_error_deg"]
    # the second line names the other model, so it never repeats the first (with --model paraxial it did)
    other = "paraxial" if args.model == "exact" else "exact"
    fov_other = info[f"{other}_fov_deg"]
    _emit(args, info, [
        f"{info['name']}: FoV {info['fov_deg'][0]:.2f} x {info['fov_deg'][1]:.2f} deg ({args.model} model)",
        f"  {other} model of the same optics: {fov_other[0]:.2f} x {fov_other[1]:.2f} deg "
        f"(the paraxial model is off by {err[0]:+.2f} / {err[1]:+.2f} deg)",
        f"  {info['point_rate_hz']} points/s, {info['channels']} channel(s), {len(optics.prisms)} prisms, "
        + ("the pattern repeats only after more than 1e9 s (noise-free)" if info["repeat_period_s"] is None
           else f"pattern repeats every {info['repeat_period_s']} s (noise-free)"),
    ])
    if args.plot:
        _pattern_plot(optics, args.model, 0.1, args.plot)
    return 0


def _pattern_plot(optics, model, duration, path, scan=None):
    """Plot ``duration`` seconds of the pattern; ``scan`` (a ScanModel, e.g. with speed noise)
    overrides the noise-free model built from ``optics`` and ``model``."""
    import numpy as np

    from foveatrack.cli.scan_plots import plot_pattern
    from sim.scan.fov import az_el_deg
    from sim.scan.model import ScanModel

    scan = ScanModel(optics, model=model) if scan is None else scan
    chunk = scan.scan(0, int(round(duration * optics.point_rate_hz)))
    az, el = az_el_deg(chunk.direction[chunk.valid])
    plot_pattern(az, el, chunk.channel[chunk.valid].astype(np.int64),
                 f"{optics.name}: scan pattern, {duration * 1000:g} ms, {scan.model} model\n(cf. paper Fig. 4, 8, 9c)",
                 path)
    return az, el


def cmd_pattern(args) -> int:
    optics = _load(args)
    scan = _scan_model(args, optics)
    count = int(round(args.duration * optics.point_rate_hz))
    if count < 2:
        raise UserError(f"--duration {args.duration:g}: holds no points at {optics.point_rate_hz} points/s")
    if count > PATTERN_MAX_POINTS:
        raise UserError(f"--duration {args.duration:g}: {count} points; the pattern holds every point in memory, "
                        f"at most {PATTERN_MAX_POINTS} ({PATTERN_MAX_POINTS / optics.point_rate_hz:g} s at "
                        f"{optics.point_rate_hz} points/s)")
    chunk = scan.scan(0, count)
    from sim.scan.fov import az_el_deg

    az, el = az_el_deg(chunk.direction[chunk.valid])
    if args.plot:
        _pattern_plot(optics, args.model, args.duration, args.plot, scan=scan)
    result = {
        "name": optics.name, "model": args.model, "duration_s": args.duration, "points": len(chunk),
        "valid_points": int(chunk.valid.sum()),
        "az_range_deg": [float(az.min()), float(az.max())], "el_range_deg": [float(el.min()), float(el.max())],
    }
    _emit(args, result, [f"{optics.name}: {len(chunk)} points in {args.duration:g} s, "
                         f"az {az.min():.2f}..{az.max():.2f} deg, el {el.min():.2f}..{el.max():.2f} deg"
                         + (f"; plot: {args.plot}" if args.plot else "")])
    return 0


def cmd_density(args) -> int:
    import numpy as np

    from sim.scan.density import radial_density
    from sim.scan.model import ScanModel

    optics = _load(args)
    if len(optics.prisms) != 2:
        raise UserError(f"{optics.name}: eq. (4) describes two-prism patterns; this scanner has {len(optics.prisms)}")
    if optics.channels != 1:
        # several lasers (Avia, Tele-15) or heads (Mid-100) overlay shifted patterns: not eq. (4)'s radial law
        kind = "heads" if optics.head_yaw_deg else "channels"
        raise UserError(f"{optics.name}: eq. (4) describes a single beam's pattern; this scanner has "
                        f"{optics.channels} {kind}")
    if args.bins < 1:
        raise UserError(f"--bins {args.bins}: at least 1")
    if args.duration * optics.point_rate_hz < 1000:
        raise UserError(f"--duration {args.duration:g}: too short for a density (< 1000 points at "
                        f"{optics.point_rate_hz} points/s)")
    # The other model is always computed alongside so the departure is visible.
    other = "paraxial" if args.model == "exact" else "exact"
    n = int(round(args.duration * optics.point_rate_hz))
    with _Progress(args, "density", total=2 * n, passes=2) as bar:
        dens = radial_density(_scan_model(args, optics), args.duration, bins=args.bins, progress=bar.part(0))
        dens_other = radial_density(ScanModel(optics, model=other), args.duration, bins=args.bins,
                                    progress=bar.part(1))
    x = dens.centers_deg / dens.r_scale_deg
    sel = (x >= 0.1) & (x <= 1.8)
    worst = float(np.max(np.abs(dens.relative_error[sel])))
    result = {
        "name": optics.name, "model": args.model, "duration_s": args.duration, "points": dens.points,
        "r_scale_deg": dens.r_scale_deg,
        "radius_edges_deg": dens.edges_deg.tolist(),
        "radius_centers_deg": dens.centers_deg.tolist(),
        "simulated": dens.simulated.tolist(),
        "analytic": dens.analytic.tolist(),
        "units": "fraction of all points per deg^2 of solid angle (small-angle annulus area)",
        "max_relative_error_0.1R_1.8R": worst,
        other: {"simulated": dens_other.simulated.tolist(),
                "max_relative_error_0.1R_1.8R": float(np.max(np.abs(dens_other.relative_error[sel])))},
    }
    if args.plot:
        from foveatrack.cli.scan_plots import plot_density

        para, exact = (dens, dens_other) if args.model == "paraxial" else (dens_other, dens)
        plot_density(para, exact, f"{optics.name}: radial density, {args.duration:g} s (paper Fig. 5, eq. 4)",
                     args.plot)
    _emit(args, result, [f"{optics.name}: {dens.points} points; {args.model} model vs eq. (4) between 0.1R and 1.8R: "
                         f"max relative error {worst:.2%}; {other}: {result[other]['max_relative_error_0.1R_1.8R']:.2%}"])
    return 0


def coverage_curve(optics, scan, method, duration, progress=None):
    from sim.scan.coverage import footprint_coverage, swath_coverage, voxel_coverage

    if method == "voxel":
        return voxel_coverage(scan, duration, progress=progress)
    if method == "footprint":
        return swath_coverage(scan, duration, progress=progress)
    return footprint_coverage(scan, duration, progress=progress)


def cmd_coverage(args) -> int:
    optics = _load(args)
    scan = _scan_model(args, optics)
    published = None
    if args.compare:
        from sim.scan.livox_published import PUBLISHED_STEP_S, published_coverage

        if args.preset not in PUBLISHED_STEP_S:
            raise UserError(f"--compare: Livox publishes a coverage curve only for {', '.join(PUBLISHED_STEP_S)}, "
                            f"not {args.preset!r}")
        if args.method != "footprint":
            raise UserError(f"--compare: Livox's curve is the illuminated fraction; use --method footprint "
                            f"(not {args.method})")
        published = published_coverage(args.preset)
        args.duration = float(published.times_s[published.compared_points()].max())  # to the curve's plateau
    t0 = time.perf_counter()
    n = int(round(args.duration * optics.point_rate_hz)) if args.method == "voxel" else None  # footprint: substeps
    with _Progress(args, f"{args.method} coverage", total=n) as bar:
        curve = coverage_curve(optics, scan, args.method, args.duration, progress=bar.part())
    result = {
        "name": optics.name, "model": args.model, "method": args.method, "duration_s": args.duration,
        "speed_noise": args.noise, "cells": curve.cells,
        "times_s": [round(t, 6) for t in curve.times_s.tolist()], "coverage": curve.coverage.tolist(),
        "t50_s": curve.t50_s, "t90_s": curve.t90_s, "wall_s": round(time.perf_counter() - t0, 3),
    }
    if args.plot:
        from foveatrack.cli.scan_plots import plot_coverage

        noise = f"{args.noise * 100:g} % speed noise" if args.noise else "no speed noise"
        plot_coverage([(f"{args.method}, {noise}", curve)],
                      f"{optics.name}: coverage, {args.method} definition (paper Fig. 6e)", args.plot)
    lines = [f"{optics.name}: {args.method} coverage after {args.duration:g} s: {curve.coverage[-1]:.1%} "
             f"of {curve.cells} cells; 50 % {_reached(curve.t50_s, args.duration)}, "
             f"90 % {_reached(curve.t90_s, args.duration)}"]
    if published is not None:
        import numpy as np

        from foveatrack.cli.scan_plots import plot_coverage_vs_published

        idx = published.compared_points()
        ours = np.array([curve.coverage[np.argmin(np.abs(curve.times_s - t))] for t in published.times_s[idx]])
        dev = ours - published.coverage[idx]
        worst = int(np.argmax(np.abs(dev)))
        result["livox"] = {"times_s": published.times_s[idx].tolist(), "coverage": published.coverage[idx].tolist(),
                           "ours": ours.tolist(), "max_abs_deviation": float(abs(dev[worst])),
                           "at_s": float(published.times_s[idx][worst])}
        plot_coverage_vs_published(curve, published, f"{optics.name}: ours (footprint, exact refraction) "
                                   f"against Livox's published curve", args.compare)
        lines.append(f"against Livox's published curve: largest deviation {dev[worst]:+.3f} at "
                     f"{published.times_s[idx][worst]:g} s; plot {args.compare}")
    _emit(args, result, lines)
    return 0


def _reached(t_s: float | None, duration_s: float) -> str:
    """``at T s``, or ``not reached in D s`` when the run ended before that coverage (not "at None s")."""
    return f"at {t_s:.2f} s" if t_s is not None else f"not reached in {duration_s:g} s"


def _range(text: str, name: str):
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise UserError(f"{name} {text!r}: expected LO:HI in rpm, e.g. 1000:12000") from None
    if not all(math.isfinite(v) and abs(v) <= 60000 for v in (lo, hi)):
        raise UserError(f"{name} {text!r}: speeds must be finite and within +-60000 rpm")
    return lo, hi


def cmd_coverage_map(args) -> int:
    import numpy as np

    from sim.scan.coverage_map import coverage_map
    from sim.sweep import make_executor

    optics = _load(args)
    if len(optics.prisms) != 2:
        raise UserError(f"{optics.name}: the speed map varies two prisms; this scanner has {len(optics.prisms)}")
    if args.grid < 2:
        raise UserError(f"--grid {args.grid}: at least 2")
    r1 = np.linspace(*_range(args.rpm1, "--rpm1"), args.grid)
    r2 = np.linspace(*_range(args.rpm2, "--rpm2"), args.grid)
    t0 = time.perf_counter()
    with make_executor(args.scheduler, args.workers) as ex:
        cmap = coverage_map(optics, r1, r2, args.cap, ex, seed=args.seed, progress=not args.no_progress)
    wall = time.perf_counter() - t0

    def clean(a):
        return [[None if not math.isfinite(v) else round(v, 4) for v in row] for row in a.tolist()]

    result = {
        "name": optics.name, "rpm1": cmap.rpm1.tolist(), "rpm2": cmap.rpm2.tolist(), "cap_s": args.cap,
        "level": cmap.level, "t90_noise_s": clean(cmap.t90_noise_s), "t90_clean_s": clean(cmap.t90_clean_s),
        "note": "rows follow rpm2, columns rpm1; null = not reached within the cap",
        "wall_s": round(wall, 2), "scheduler": args.scheduler or "local processes",
    }
    if args.plot:
        from foveatrack.cli.scan_plots import plot_coverage_map

        plot_coverage_map(cmap, f"{optics.name}: time to 90 % voxel coverage (paper Fig. 7)", args.plot,
                          device_rpm=(optics.prisms[0].rpm, optics.prisms[1].rpm))
    frac_noise = float(np.mean(cmap.t90_noise_s < args.cap))
    frac_clean = float(np.mean(cmap.t90_clean_s < args.cap))
    _emit(args, result, [f"{optics.name}: {args.grid}x{args.grid} speeds, cap {args.cap:g} s, {wall:.1f} s wall: "
                         f"90 % reached in {frac_noise:.0%} of cells with 1 % noise, {frac_clean:.0%} without"])
    return 0
