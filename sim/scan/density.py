"""Radial point density of the rosette pattern, simulated and analytic (paper eq. 1-4, Fig. 5).

Paraxially the beam is the sum of two equal rotating vectors of magnitude R (eq. 1), so its
off-axis angle is :math:`r = \\sqrt 2 R \\sqrt{1 + \\cos \\Delta\\omega t}` (eq. 2), and the density
of points per unit solid angle is (eq. 4)

.. math:: \\rho(r) = \\frac{N}{2\\pi R\\,\\Delta\\omega}\\,\\frac{1}{r\\sqrt{1 - r^2/4R^2}}.

Integrated over an annulus the expected fraction of all points is
:math:`\\tfrac{2}{\\pi}\\big(\\arcsin\\tfrac{r_2}{2R} - \\arcsin\\tfrac{r_1}{2R}\\big)`, which is what
:func:`radial_density` compares against (bin-averaged, so the divergences at r = 0 and r = 2R
do not bias the comparison).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.scan.model import ScanModel


@dataclass(frozen=True)
class RadialDensity:
    """Simulated and analytic radial density, bin by bin.

    Attributes
    ----------
    edges_deg : (B+1,) [deg]        bin edges of the off-axis angle r
    simulated : (B,) [1/deg^2]      fraction of points per unit solid angle (small-angle area
                                    ``pi (r2^2 - r1^2)``), i.e. normalised density
    analytic : (B,) [1/deg^2]       eq. (4) averaged over the same bins, same normalisation
    r_scale_deg : float [deg]       R, the one-prism deflection used by eq. (4)
    points : int                    valid points counted
    model : str                     scan model that produced the points
    """

    edges_deg: np.ndarray
    simulated: np.ndarray
    analytic: np.ndarray
    r_scale_deg: float
    points: int
    model: str = "exact"

    @property
    def centers_deg(self) -> np.ndarray:
        return 0.5 * (self.edges_deg[1:] + self.edges_deg[:-1])

    @property
    def relative_error(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.simulated / self.analytic - 1.0


def analytic_bin_fraction(edges_deg: np.ndarray, r_scale_deg: float) -> np.ndarray:
    """Eq. (4) integrated over each annulus: expected fraction of all points per bin."""
    x = np.clip(np.asarray(edges_deg, dtype=float) / (2.0 * r_scale_deg), 0.0, 1.0)
    return np.diff(2.0 / np.pi * np.arcsin(x))


def radial_density(model: ScanModel, duration_s: float, bins: int = 60, r_scale_deg: float | None = None,
                   progress=None) -> RadialDensity:
    """Histogram of the off-axis angle of every valid point over ``duration_s``.

    ``r_scale_deg`` defaults to the paraxial one-prism deflection (n - 1) alpha of the first prism
    (the R of eq. 1), so the exact model's departure from eq. (4) shows up rather than being
    absorbed by a fitted scale.  ``progress(points_done, points_total)`` is called after each chunk.
    """
    if r_scale_deg is None:
        r_scale_deg = model.optics.prisms[0].thin_prism_deviation_deg
    edges = np.linspace(0.0, 2.0 * r_scale_deg * 1.06, bins + 1)
    counts = np.zeros(bins, dtype=np.int64)
    total = 0
    n_points = int(round(duration_s * model.optics.point_rate_hz))
    for chunk in model.iter_chunks(duration_s):
        d = chunk.direction[chunk.valid]
        r = np.degrees(np.arccos(np.clip(d[:, 0], -1.0, 1.0)))
        counts += np.histogram(r, bins=edges)[0]
        total += d.shape[0]
        if progress is not None:
            progress(chunk.k0 + len(chunk), n_points)
    area = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    simulated = counts / max(total, 1) / area
    analytic = analytic_bin_fraction(edges, r_scale_deg) / area
    return RadialDensity(edges, simulated, analytic, float(r_scale_deg), int(total), model.model)
