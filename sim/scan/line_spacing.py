"""Scan-line spacing of a Risley scanner, measured the way Livox states it for the Horizon.

Livox's Point Cloud Characteristics page (Livox-SDK/livox_wiki_en, "HORIZON"): within 0.1 s, "in the
center of the FOV ... the average spacing of lines being 0.2 deg (most line spacing is from 0.1 to
0.3 deg)"; "the two circular areas on both sides have a lower scanning density, with an average line
spacing of 0.4 deg (most line spacing is between 0.2 to 0.8 deg)".  The Horizon's lines run roughly
horizontally (paper Fig. 9c), so the spacing between lines is measured along vertical cuts: every
channel's beam path over the integration time (traced at 8 x the point rate) is cut by the vertical
lines ``azimuth = a`` at each of ``az_cuts_deg``; the crossings' elevations inside ``el_range_deg``
are sorted, and the gaps between neighbouring crossings are the line spacings.
"""

from __future__ import annotations

import numpy as np

from sim.scan import kernels
from sim.scan.fov import az_el_deg
from sim.scan.model import ScanModel
from sim.scan.optics import RisleyOptics

#: Livox's two regions of the Horizon's 0.1 s pattern (Livox's 0.1 s figure: the dense central band,
#: and the sparse circles centred near +-30 deg azimuth): (azimuth cuts [deg], elevation range [deg])
HORIZON_CENTRE = (tuple(np.arange(-10.0, 10.01, 1.0)), (-5.0, 5.0))
HORIZON_SIDES = (tuple(np.r_[np.arange(-33.0, -26.9, 1.0), np.arange(27.0, 33.01, 1.0)]), (-4.0, 4.0))
#: Livox's statements: (average [deg], range "most" spacings fall in [deg])
LIVOX_HORIZON_SPACING = {"centre": (0.2, (0.1, 0.3)), "sides": (0.4, (0.2, 0.8))}


def line_gaps_deg(optics: RisleyOptics, duration_s: float, az_cuts_deg, el_range_deg, substeps: int = 8,
                  model: str = "exact") -> np.ndarray:
    """All gaps [deg] between neighbouring scan-line crossings of the vertical cuts (see module doc)."""
    scan = ScanModel(optics.with_(point_rate_hz=optics.point_rate_hz * substeps), model=model)
    n = int(round(duration_s * scan.optics.point_rate_hz))
    revs = scan.prism_revs(0, n)
    crossings = [[] for _ in az_cuts_deg]
    for c in range(optics.channels):
        d, st = ScanModel(optics, model=model).directions_from_revs(revs, np.full(n, c, dtype=np.int64))
        az, el = az_el_deg(d)
        ok = (st[:-1] == kernels.RAY_OK) & (st[1:] == kernels.RAY_OK)
        for i, a in enumerate(az_cuts_deg):
            s0, s1 = az[:-1] - a, az[1:] - a
            cross = ok & (np.sign(s0) != np.sign(s1)) & (s0 != s1)
            f = s0[cross] / (s0[cross] - s1[cross])
            e = el[:-1][cross] + f * (el[1:][cross] - el[:-1][cross])
            crossings[i].append(e[(e >= el_range_deg[0]) & (e <= el_range_deg[1])])
    gaps = []
    for per_cut in crossings:
        e = np.sort(np.concatenate(per_cut))
        gaps.append(np.diff(e))
    return np.concatenate(gaps)


def spacing_summary(gaps_deg: np.ndarray, most_range_deg: tuple[float, float]) -> dict:
    """Mean, median and the fraction of gaps inside ``most_range_deg``."""
    lo, hi = most_range_deg
    return {"mean_deg": float(np.mean(gaps_deg)), "median_deg": float(np.median(gaps_deg)),
            "p10_deg": float(np.percentile(gaps_deg, 10)), "p90_deg": float(np.percentile(gaps_deg, 90)),
            "fraction_in_range": float(np.mean((gaps_deg >= lo) & (gaps_deg <= hi))), "gaps": int(gaps_deg.size)}


def horizon_line_spacing(optics: RisleyOptics, duration_s: float = 0.1) -> dict[str, dict]:
    """The centre and side-region spacing summaries of a Horizon-like scanner against Livox's ranges."""
    out = {}
    for region, (cuts, el_range) in (("centre", HORIZON_CENTRE), ("sides", HORIZON_SIDES)):
        out[region] = spacing_summary(line_gaps_deg(optics, duration_s, cuts, el_range),
                                      LIVOX_HORIZON_SPACING[region][1])
    return out
