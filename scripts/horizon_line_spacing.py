"""The Horizon's line spacing in 0.1 s, measured as Livox's wiki states it, against Livox's figures.

Livox (Point Cloud Characteristics page, "HORIZON"): within 0.1 s, the centre's lines are 0.2 deg apart
on average, most 0.1-0.3 deg; the two circular side regions' 0.4 deg on average, most 0.2-0.8 deg.
The measure is :func:`sim.scan.line_spacing.horizon_line_spacing` (vertical cuts through every channel's
beam path; the gaps between neighbouring crossings).  Prints one row per region and whether it meets
Livox's statement: the mean within 25 % of Livox's average, and most gaps (more than half) inside the
stated range, as a table for docs/livox-files.md.

Usage: python scripts/horizon_line_spacing.py [--rpm P12 P3]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from sim.scan.line_spacing import LIVOX_HORIZON_SPACING, horizon_line_spacing
from sim.scan.presets import HORIZON

MEAN_TOLERANCE = 0.25


def meets(summary: dict, region: str) -> bool:
    average, (lo, hi) = LIVOX_HORIZON_SPACING[region]
    return abs(summary["mean_deg"] - average) <= MEAN_TOLERANCE * average and summary["fraction_in_range"] > 0.5


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rpm", type=float, nargs=2, metavar=("P12", "P3"),
                    help="P1/P2 and P3 speeds to measure instead of the preset's")
    args = ap.parse_args(argv)
    optics = HORIZON
    if args.rpm:
        optics = optics.with_prism(0, rpm=args.rpm[0]).with_prism(1, rpm=-args.rpm[0]).with_prism(2, rpm=args.rpm[1])
    t0 = time.perf_counter()
    got = horizon_line_spacing(optics, 0.1)
    wall = time.perf_counter() - t0
    rpms = " / ".join(f"{p.rpm:g}" for p in optics.prisms)
    print(f"horizon line spacing in 0.1 s, prisms {rpms} rpm ({wall:.1f} s, load {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores)")
    print("| region | mean | median | 10th-90th percentile | gaps in Livox's \"most\" range | Livox | meets |")
    print("|---|---|---|---|---|---|---|")
    ok = True
    for region, s in got.items():
        average, (lo, hi) = LIVOX_HORIZON_SPACING[region]
        good = meets(s, region)
        ok &= good
        print(f"| {region} | {s['mean_deg']:.3f} deg | {s['median_deg']:.3f} deg | {s['p10_deg']:.3f}-{s['p90_deg']:.3f} "
              f"| {100 * s['fraction_in_range']:.0f} % in {lo:g}-{hi:g} | {average:g} average, most {lo:g}-{hi:g} "
              f"| {'yes' if good else 'no'} |")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
