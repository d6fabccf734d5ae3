"""Time to 90 % coverage over a grid of the two prism speeds (paper Fig. 7 a/b).

Each cell runs the voxel coverage of the scanner with those speeds, with or without the paper's 1 %
gaussian motor speed noise, and stops as soon as 90 % is reached or at the cap (paper: 5 s).  The
cells are independent, so they run through :mod:`sim.sweep` (local processes or a Dask cluster).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.scan.coverage import CoverageGrid, voxel_coverage, voxel_grid
from sim.scan.model import ScanModel
from sim.scan.optics import RisleyOptics, SpeedNoise
from sim.sweep import run_tasks


@dataclass(frozen=True)
class MapCell:
    """One cell of the map (picklable: it travels to worker processes)."""

    optics: RisleyOptics
    grid: CoverageGrid
    rpm1: float
    rpm2: float
    noise: bool
    cap_s: float
    seed: int
    level: float = 0.9
    row: int = 0  # position in the map (speeds may repeat after rounding to whole rpm)
    col: int = 0


def time_to_level(cell: MapCell) -> float:
    """Time [s] at which the cell's scan reaches ``cell.level`` coverage; ``inf`` past the cap."""
    optics = cell.optics.with_prism(0, rpm=cell.rpm1).with_prism(1, rpm=cell.rpm2)
    noise = SpeedNoise() if cell.noise else None
    rng = np.random.default_rng(cell.seed) if cell.noise else None
    curve = voxel_coverage(ScanModel(optics, speed_noise=noise, rng=rng), cell.cap_s, cell.grid, stop_at=cell.level)
    t = curve.time_to(cell.level)
    return float("inf") if t is None else t


@dataclass(frozen=True)
class CoverageMap:
    rpm1: np.ndarray  # (n1,)
    rpm2: np.ndarray  # (n2,)
    t90_noise_s: np.ndarray  # (n2, n1), inf where the cap was reached
    t90_clean_s: np.ndarray
    cap_s: float
    level: float


def coverage_map(optics: RisleyOptics, rpm1: np.ndarray, rpm2: np.ndarray, cap_s: float, executor, seed: int = 0,
                 level: float = 0.9, progress: bool = True) -> CoverageMap:
    """Both panels of Fig. 7: with 1 % speed noise (a) and without (b).  Speeds are rounded to
    whole rpm, as a motor controller sets them, so commensurability shows as in the paper."""
    rpm1 = np.round(np.asarray(rpm1, dtype=float))
    rpm2 = np.round(np.asarray(rpm2, dtype=float))
    grid = voxel_grid(optics)
    ss = np.random.SeedSequence(seed)
    seeds = ss.generate_state(rpm1.size * rpm2.size)
    cells = []
    for j, r2 in enumerate(rpm2):
        for i, r1 in enumerate(rpm1):
            for noise in (True, False):
                cells.append(MapCell(optics, grid, float(r1), float(r2), noise, cap_s, int(seeds[j * rpm1.size + i]),
                                     level, row=j, col=i))
    results = run_tasks(time_to_level, cells, executor, desc="coverage map", progress=progress)
    t_noise = np.full((rpm2.size, rpm1.size), np.nan)
    t_clean = np.full((rpm2.size, rpm1.size), np.nan)
    for cell, t in results:
        target = t_noise if cell.noise else t_clean
        target[cell.row, cell.col] = t
    return CoverageMap(rpm1, rpm2, t_noise, t_clean, cap_s, level)
