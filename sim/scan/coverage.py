"""FoV coverage versus accumulation time (paper Fig. 6e, Appendix C eq. 9; Fig. 7).

Three definitions, named wherever a figure is shown, because they answer different questions:

* ``voxel`` — the paper's Appendix C: the FoV is cut into a 100 x 100 grid (here over azimuth and
  elevation, the lidar's spherical coordinates); a cell counts once a point falls in it; cells the
  scanner can never reach (outside the circular FoV, inside a central hole) are not counted.
* ``footprint`` — Livox's FoV coverage definition (:func:`swath_coverage`), "the fraction of the FoV
  illuminated by laser beams" (Livox HAP manual: C = illuminated area / FoV area).  Its geometry is
  inferred from Livox's Mid-40 curve (``LIVOX_MID40_COVERAGE``, read off Livox's figure), which the
  ``mid40`` preset meets within 0.03 at every 0.05 s to 1.4 s (docs/livox-files.md): the
  0.28 x 0.03 deg footprint travels with its narrow axis along the scan, so the beam
  sweeps a swath as wide as the divergence's major axis (0.28 deg) across its path.  Measured on a
  0.02 deg grid in the azimuthal-equidistant projection about the optical axis (the circular FoV is
  a disc there, distances are angles from the axis), the trajectory sub-sampled finely enough that
  the union of 0.14 deg discs is the swath to within 0.002 deg.  The FoV is every cell the swath can
  reach (found from rays at random prism phases), so a long run tends to 1.
* ``footprint-fixed`` — the illuminated area of a footprint held in a fixed orientation
  (:func:`footprint_coverage`): every ray painted with its elliptical divergence footprint kept
  aligned with azimuth/elevation (0.28 deg along azimuth), on a grid of half the minor axis, with the
  trajectory sub-sampled so the swept path is painted.  A legitimate different measure (the spot of
  an emitter that does not turn with the scan) and this project's earlier "footprint"; it sweeps a
  0.03 deg swath where the beam moves along azimuth and 0.28 deg where it moves along elevation, so
  it stays below Livox's figures (Mid-40: 11 / 46 / 71 % at 0.1 / 0.5 / 1 s against Livox's 19.5 / 68.3 / 92.3).

"Can be reached" is decided from the optics, not from the run being measured: rays at uniformly
random prism phases (prisms driven as a locked counter-rotating pair share one phase) sample every
direction the scanner can produce; the long-time pattern of incommensurable speeds fills exactly
that set.  So a commensurable (repeating) pattern is measured against the same FoV and plateaus.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.scan import kernels
from sim.scan.fov import az_el_deg
from sim.scan.model import ScanModel
from sim.scan.optics import RisleyOptics

COVERAGE_METHODS = ("voxel", "footprint", "footprint-fixed")
#: Livox's Mid-40 FoV coverage against accumulation time {t [s]: fraction} at 0.1, 0.5 and 1 s, read off
#: the figure on the Livox wiki's Point Cloud Characteristics page (sim.scan.livox_published, +-0.006).
LIVOX_MID40_COVERAGE = {0.1: 0.195, 0.5: 0.683, 1.0: 0.923}
SWATH_CELL_DEG = 0.02   # grid of the Livox definition: 14 cells across the Mid-40 swath
VOXEL_GRID = 100  # paper Appendix C


def locked_pairs(optics: RisleyOptics) -> dict[int, int]:
    """Prisms driven as a locked counter-rotating pair (paper Fig. 9a): ``{follower: leader}``.

    Prism j follows prism i (i < j) when their speeds are exactly opposite and their start phases
    mirrored (``phase_j = -phase_i`` mod 360), so ``theta_j = -theta_i`` at all times.
    """
    pairs: dict[int, int] = {}
    ps = optics.prisms
    for j in range(len(ps)):
        for i in range(j):
            if i not in pairs and ps[j].rpm == -ps[i].rpm and (ps[j].phase_deg + ps[i].phase_deg) % 360 == 0:
                pairs[j] = i
                break
    return pairs


def reachable_directions(model: ScanModel, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` valid directions per channel at random prism phases (see module docstring)."""
    optics = model.optics
    pairs = locked_pairs(optics)
    out = []
    for c in range(optics.channels):
        revs = rng.random((count, model.prism_count))
        for j, i in pairs.items():
            revs[:, j] = (-revs[:, i]) % 1.0
        d, st = model.directions_from_revs(revs, np.full(count, c, dtype=np.int64))
        out.append(d[st == kernels.RAY_OK])
    return np.concatenate(out)


@dataclass(frozen=True)
class CoverageGrid:
    """A grid over azimuth/elevation and the cells the scanner can reach."""

    az_min_deg: float
    el_min_deg: float
    cell_az_deg: float
    cell_el_deg: float
    reachable: np.ndarray  # (n_el, n_az) bool

    @property
    def shape(self) -> tuple[int, int]:
        return self.reachable.shape

    def cells(self, direction: np.ndarray) -> np.ndarray:
        """Flat cell index of each direction, -1 outside the grid or outside the reachable set."""
        az, el = az_el_deg(direction)
        n_el, n_az = self.shape
        i = np.floor((az - self.az_min_deg) / self.cell_az_deg).astype(np.int64)
        r = np.floor((el - self.el_min_deg) / self.cell_el_deg).astype(np.int64)
        inside = (i >= 0) & (i < n_az) & (r >= 0) & (r < n_el)
        flat = np.where(inside, r * n_az + i, -1)
        ok = flat >= 0
        ok[ok] = self.reachable.ravel()[flat[ok]]
        return np.where(ok, flat, -1)


def voxel_grid(optics: RisleyOptics, model: str = "exact", n: int = VOXEL_GRID, reference_rays: int = 2_000_000, seed: int = 0) -> CoverageGrid:
    """The paper's n x n grid over the FoV's az/el box, with its reachable cells."""
    ref = ScanModel(optics, model=model)
    d = reachable_directions(ref, reference_rays // optics.channels, np.random.default_rng(seed))
    az, el = az_el_deg(d)
    az0, az1, el0, el1 = az.min(), az.max(), el.min(), el.max()
    # A hair of margin so the extreme rays fall inside the last cell.
    pad_az, pad_el = 1e-9 * (az1 - az0), 1e-9 * (el1 - el0)
    grid = CoverageGrid(az0 - pad_az, el0 - pad_el, (az1 - az0 + 2 * pad_az) / n, (el1 - el0 + 2 * pad_el) / n,
                        np.ones((n, n), dtype=bool))
    hit = np.zeros(n * n, dtype=bool)
    cells = grid.cells(d)
    hit[cells[cells >= 0]] = True
    return CoverageGrid(grid.az_min_deg, grid.el_min_deg, grid.cell_az_deg, grid.cell_el_deg, hit.reshape(n, n))


@dataclass(frozen=True)
class CoverageCurve:
    """Coverage (0-1) of the reachable FoV against accumulation time."""

    method: str
    times_s: np.ndarray
    coverage: np.ndarray
    cells: int
    stopped_early: bool

    def time_to(self, level: float) -> float | None:
        """First time coverage reaches ``level``, or None if it never did within the run."""
        idx = np.flatnonzero(self.coverage >= level)
        return round(float(self.times_s[idx[0]]), 9) if idx.size else None

    @property
    def t50_s(self) -> float | None:
        return self.time_to(0.5)

    @property
    def t90_s(self) -> float | None:
        return self.time_to(0.9)


def _curve(method, first_hit_k, mask, rate_hz, duration_s, stopped_early, samples=400) -> CoverageCurve:
    k = first_hit_k[mask]
    hits = np.sort(k[k >= 0])
    times = np.linspace(0.0, duration_s, samples + 1)[1:]
    # A point fired at t_k = k / rate counts for every t >= t_k.
    counts = np.searchsorted(hits, np.floor(times * rate_hz + 1e-9), side="right")
    return CoverageCurve(method, times, counts / max(int(mask.sum()), 1), int(mask.sum()), stopped_early)


def voxel_coverage(model: ScanModel, duration_s: float, grid: CoverageGrid | None = None, stop_at: float | None = None,
                   chunk_points: int = 20_000, progress=None) -> CoverageCurve:
    """Paper Appendix C coverage of ``model``'s scan over ``duration_s`` (eq. 9).

    ``stop_at`` (0-1) ends the run as soon as that coverage is reached (the Fig. 7 map only needs
    the time to 90 %); the curve then ends at the stopping time.  ``progress(points_done,
    points_total)`` is called after each chunk.
    """
    if grid is None:
        grid = voxel_grid(model.optics, model.model)
    mask = grid.reachable.ravel()
    first_hit = np.full(mask.size, -1, dtype=np.int64)
    target = math.inf if stop_at is None else stop_at * mask.sum()
    hit = 0
    end_k = int(round(duration_s * model.optics.point_rate_hz))
    stopped = False
    for chunk in model.iter_chunks(duration_s, chunk_points=chunk_points):
        cells = grid.cells(chunk.direction[:, :])
        cells[~chunk.valid] = -1
        hit += kernels.first_hit_kernel(cells, chunk.k0, first_hit)
        if progress is not None:
            progress(chunk.k0 + len(chunk), end_k)
        if hit >= target:
            end_k = chunk.k0 + len(chunk)
            stopped = True
            break
    run_s = end_k / model.optics.point_rate_hz
    return _curve("voxel", first_hit, mask, model.optics.point_rate_hz, run_s, stopped)


def _beam_speed_bound(optics: RisleyOptics) -> float:
    """A bound on the beam's angular speed [deg/s x rad]: the sum of the prisms' (deviation x angular
    rate), doubled for exact refraction; sets how finely the coverage methods sample the trajectory."""
    return sum(2 * p.thin_prism_deviation_deg * abs(p.rpm) / 60 * 2 * math.pi for p in optics.prisms)


def _trajectory_chunks(model: ScanModel, substeps: int, duration_s: float, chunk_points: int, project):
    """The scan's trajectory at ``substeps`` x the point rate: the same noise process in time (its
    draws depend on time segments only), each channel traced from the shared prism angles.  Yields,
    per chunk, ``(samples_done, samples_total, [(x, y, sample_index) per channel])`` with ``project``
    (directions -> two angle arrays [deg]) applied to the valid rays."""
    optics = model.optics
    fine_rate = optics.point_rate_hz * substeps
    fine = ScanModel(optics.with_(point_rate_hz=fine_rate), model=model.model,
                     speed_noise=model.speed_noise, rng=model._rng)
    total = int(round(duration_s * fine_rate))
    for k in range(0, total, chunk_points):
        n = min(chunk_points, total - k)
        revs = fine.prism_revs(k, n)
        per_channel = []
        for c in range(optics.channels):
            d, st = model.directions_from_revs(revs, np.full(n, c, dtype=np.int64))
            ok = st == kernels.RAY_OK
            x, y = project(d[ok])
            per_channel.append((x, y, np.flatnonzero(ok).astype(np.int64) + k))
        yield k + n, total, per_channel


def footprint_coverage(model: ScanModel, duration_s: float, substeps: int | None = None,
                       reference_rays: int = 1_000_000, seed: int = 0, chunk_points: int = 20_000,
                       progress=None) -> CoverageCurve:
    """Livox-style coverage: the illuminated fraction of the reachable FoV (see module docstring).

    ``progress(samples_done, samples_total)`` is called after each chunk (samples at ``substeps``
    times the point rate)."""
    optics = model.optics
    div_az, div_el = optics.beam_divergence_deg
    half_az, half_el = div_az / 2, div_el / 2
    cell = min(div_az, div_el) / 2
    if substeps is None:
        # keep sub-sample spacing below the footprint's minor semi-axis
        substeps = max(1, math.ceil(_beam_speed_bound(optics) / optics.point_rate_hz / half_el))
    ref = reachable_directions(ScanModel(optics, model=model.model), reference_rays // optics.channels,
                               np.random.default_rng(seed))
    az, el = az_el_deg(ref)
    az0, el0 = az.min() - half_az, el.min() - half_el
    n_az = int(math.ceil((az.max() + half_az - az0) / cell))
    n_el = int(math.ceil((el.max() + half_el - el0) / cell))
    reach = np.full((n_el, n_az), -1, dtype=np.int64)
    kernels.paint_footprint_kernel(az, el, 0, half_az, half_el, az0, el0, cell, reach)
    mask = reach.ravel() >= 0
    first_hit = np.full((n_el, n_az), -1, dtype=np.int64)
    for done, total, per_channel in _trajectory_chunks(model, substeps, duration_s, chunk_points, az_el_deg):
        for a, e, kidx in per_channel:
            _paint_runs(kernels.paint_footprint_kernel, a, e, kidx, (half_az, half_el, az0, el0, cell, first_hit))
        if progress is not None:
            progress(done, total)
    fine_rate = optics.point_rate_hz * substeps
    return _curve("footprint-fixed", first_hit.ravel(), mask, fine_rate, duration_s, False)


def axis_projection_deg(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuthal-equidistant projection about the lidar's +X axis [deg]: a direction at angle
    ``theta`` from the axis, toward ``psi`` (from +Y toward +Z), maps to ``theta (cos psi, sin psi)``.
    A circular FoV is a disc, and distances near the axis are angles."""
    x = np.clip(direction[:, 0], -1.0, 1.0)
    theta = np.degrees(np.arccos(x))
    psi = np.arctan2(direction[:, 2], direction[:, 1])
    return theta * np.cos(psi), theta * np.sin(psi)


def swath_coverage(model: ScanModel, duration_s: float, cell_deg: float | None = None,
                   substeps: int | None = None, reference_rays: int = 1_000_000, seed: int = 0,
                   chunk_points: int = 20_000, progress=None) -> CoverageCurve:
    """Livox's FoV coverage against accumulation time: the fraction of the FoV the beam's swath has
    swept (see module docstring, ``footprint``; compared with Livox's published curves in docs/livox-files.md).

    model : the scan (its speed noise included); the swath is ``beam_divergence_deg[0]`` wide
    duration_s : > 0 [s]
    cell_deg : grid cell [deg], <= a quarter of the swath's half-width; default SWATH_CELL_DEG or that
        quarter if smaller (the Mid-40 curve is the same to 0.001 on 0.01 and 0.02 deg grids)
    substeps : trajectory samples per point interval; default keeps them <= a quarter of the
        swath's half-width apart (bound on the beam's angular speed as in :func:`footprint_coverage`)
    reference_rays : rays at random prism phases that fix the FoV (the cells the swath can reach)

    ``progress(samples_done, samples_total)`` is called after each chunk.
    """
    optics = model.optics
    radius = max(optics.beam_divergence_deg) / 2
    if cell_deg is None:
        cell_deg = min(SWATH_CELL_DEG, radius / 4)
    if not 0 < cell_deg <= radius / 4:
        raise ValueError(f"cell_deg = {cell_deg!r}: must be in (0, {radius / 4:g}] (a quarter of the swath half-width)")
    if substeps is None:
        substeps = max(1, math.ceil(_beam_speed_bound(optics) / optics.point_rate_hz / (radius / 4)))
    ref = reachable_directions(ScanModel(optics, model=model.model), reference_rays // optics.channels,
                               np.random.default_rng(seed))
    u, v = axis_projection_deg(ref)
    u0, v0 = u.min() - radius, v.min() - radius
    n_u = int(math.ceil((u.max() + radius - u0) / cell_deg))
    n_v = int(math.ceil((v.max() + radius - v0) / cell_deg))
    # The FoV: every cell the swath can reach (reference rays painted with the swath's own disc), so
    # a long enough run tends to 1 and the FoV's rim is treated as the swath treats it.
    reach = np.full((n_v, n_u), -1, dtype=np.int64)
    kernels.paint_swath_kernel(u, v, 0, radius, u0, v0, cell_deg, reach)
    mask = reach.ravel() >= 0
    first_hit = np.full((n_v, n_u), -1, dtype=np.int64)
    # chunks on whole 256-ray blocks: the trace's vectorised loop gives the same bits only for
    # blocks that start alike, so any chunk_points gives the same curve
    chunk_points = max(256, -(-int(chunk_points) // 256) * 256)
    for done, total, per_channel in _trajectory_chunks(model, substeps, duration_s, chunk_points,
                                                       axis_projection_deg):
        for a, e, kidx in per_channel:
            _paint_runs(kernels.paint_swath_kernel, a, e, kidx, (radius, u0, v0, cell_deg, first_hit))
        if progress is not None:
            progress(done, total)
    fine_rate = optics.point_rate_hz * substeps
    return _curve("footprint", first_hit.ravel(), mask, fine_rate, duration_s, False)


def _paint_runs(kernel, a, e, kidx, args):
    """Paint contiguous runs of valid samples so the kernel's ``k0 + j`` indexing stays exact."""
    if kidx.size == 0:
        return
    breaks = np.flatnonzero(np.diff(kidx) != 1) + 1
    for lo, hi in zip(np.r_[0, breaks], np.r_[breaks, kidx.size]):
        kernel(a[lo:hi], e[lo:hi], int(kidx[lo]), *args)
