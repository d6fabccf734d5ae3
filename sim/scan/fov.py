"""Field of view of a scan pattern: the azimuth and elevation span its beams reach.

``fov_deg = [max az - min az, max el - min el]`` with azimuth ``atan2(Y, X)`` and elevation
``atan2(Z, hypot(X, Y))`` in the lidar frame (Livox's spherical convention).  For the paper's circular
pattern (Fig. 4) both spans equal twice the maximum deflection half-angle; for the three-prism
pattern (Fig. 9c) they are the horizontal and vertical FoV.

The span is measured on the noise-free trajectory the scanner actually follows: a dense scan finds
the neighbourhood of each extreme, then a bounded scalar search over continuous time refines it,
so the answer does not depend on the point rate.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from sim.scan import kernels
from sim.scan.model import ScanModel
from sim.scan.optics import RisleyOptics


def az_el_deg(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation [deg] of unit directions (N, 3) in the lidar frame."""
    x, y, z = direction[:, 0], direction[:, 1], direction[:, 2]
    return np.degrees(np.arctan2(y, x)), np.degrees(np.arctan2(z, np.hypot(x, y)))


def _directions_at_times(model: ScanModel, t_s: np.ndarray, channel: int) -> tuple[np.ndarray, np.ndarray]:
    prisms = model.optics.prisms
    revs = np.empty((t_s.size, len(prisms)))
    for p, prism in enumerate(prisms):
        revs[:, p] = (prism.phase_deg / 360.0 + prism.rpm / 60.0 * t_s) % 1.0
    return model.directions_from_revs(revs, np.full(t_s.size, channel, dtype=np.int64))


def field_of_view_deg(
    optics: RisleyOptics,
    model: str = "exact",
    sample_s: float | None = None,
    samples: int = 400_000,
) -> tuple[float, float]:
    """Horizontal and vertical FoV [deg] of the noise-free pattern.

    Parameters
    ----------
    optics : RisleyOptics
    model : {"exact", "paraxial"}
    sample_s : float > 0 [s], optional
        Length of the pattern searched for extremes; default: the repeat period capped to 2 s (the
        pattern's envelope is reached long before).
    samples : int
        Points of the coarse search (spread evenly over ``sample_s``, all channels).
    """
    scan = ScanModel(optics, model=model)
    if sample_s is None:
        period = optics.repeat_period_s()
        sample_s = 2.0 if (period is None or period == 0 or period > 2.0) else period
    # Largest per-point angular step of any prism, to size the refinement bracket.
    rev_rate = max(abs(p.rpm) for p in optics.prisms) / 60.0
    t = np.linspace(0.0, sample_s, samples, endpoint=False)
    dt = t[1] - t[0]
    lo_hi = []
    for c in range(optics.channels):
        direction, status = _directions_at_times(scan, t, c)
        ok = status == kernels.RAY_OK
        if not ok.any():
            raise ValueError(f"{optics.name}: every ray of channel {c} is totally reflected")
        az, el = az_el_deg(direction)
        for values, idx in ((az, 0), (el, 1)):
            v = np.where(ok, values, np.nan)
            for sign in (1.0, -1.0):
                j = int(np.nanargmax(sign * v))
                lo_hi.append((idx, sign, _refine(scan, t[j], dt, c, idx, sign, sign * v[j], rev_rate)))
    span = []
    for idx in (0, 1):
        top = max(val for i, s, val in lo_hi if i == idx and s > 0)
        bottom = -max(val for i, s, val in lo_hi if i == idx and s < 0)
        span.append(top - bottom)
    return float(span[0]), float(span[1])


def _refine(scan, t0, dt, channel, idx, sign, start, rev_rate) -> float:
    def objective(t):
        d, st = _directions_at_times(scan, np.array([t]), channel)
        if st[0] != kernels.RAY_OK:
            return 1e3  # worse than any real angle: the search stays on valid rays
        az, el = az_el_deg(d)
        return -sign * float((az, el)[idx][0])

    res = minimize_scalar(objective, bounds=(t0 - dt, t0 + dt), method="bounded", options={"xatol": 1e-12})
    return max(-res.fun, start)
