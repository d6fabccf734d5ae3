"""Livox's published FoV coverage curves, as read off the Livox wiki's figures.

The data files ``sim/scan/data/livox_coverage_{preset}.csv`` are written by
``scripts/digitise_livox_coverage.py`` (how each figure was read, and the +- of every point, are in
their comment lines and that script's docstring).  Livox defines coverage as the illuminated area over
the FoV area; :func:`sim.scan.coverage.swath_coverage` is our measure of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

DATA_DIR = Path(__file__).parent / "data"
#: presets with a published Livox coverage curve, and the step [s] the issue compares them at
PUBLISHED_STEP_S = {"mid40": 0.05, "horizon": 0.05, "tele15": 0.01}


@dataclass(frozen=True)
class PublishedCurve:
    """One of Livox's curves: coverage (0-1) at each read time, its +-, and where it plateaus."""

    preset: str
    times_s: np.ndarray
    coverage: np.ndarray
    plus_minus: np.ndarray
    plateau_s: float

    def compared_points(self) -> np.ndarray:
        """Indices of the points a preset is held to: every step (0.05 s, Tele-15 0.01 s) up to the plateau."""
        step = PUBLISHED_STEP_S[self.preset]
        on_step = np.isclose(np.round(self.times_s / step) * step, self.times_s, atol=1e-9)
        return np.flatnonzero(on_step & (self.times_s <= self.plateau_s + 1e-9))


def published_coverage(preset: str) -> PublishedCurve:
    """The published curve of ``preset`` (``mid40``, ``horizon``, ``tele15``); KeyError for others."""
    if preset not in PUBLISHED_STEP_S:
        raise KeyError(f"Livox publishes no coverage curve for {preset!r} (only {', '.join(PUBLISHED_STEP_S)})")
    path = DATA_DIR / f"livox_coverage_{preset}.csv"
    lines = path.read_text().splitlines()
    plateau = next(float(line.split("=")[1].split(":")[0]) for line in lines if line.startswith("# plateau_s = "))
    rows = np.array([[float(v) for v in line.split(",")] for line in lines
                     if line and not line.startswith("#") and not line.startswith("time_s")])
    return PublishedCurve(preset, rows[:, 0], rows[:, 1] / 100, rows[:, 2] / 100, plateau)
