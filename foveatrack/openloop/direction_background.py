"""The static scene of a fixed sensor learned per *direction* (a range image), beside the cubes of
:mod:`~foveatrack.openloop.background`.

A fixed sensor sees a static surface at one range in each direction, whatever its incidence.  The
sphere of directions is cut into cells of ``cell_deg`` in elevation and azimuth, and each cell
remembers in how many frames it returned a learned point (counted once a frame), the first and the
latest of those frames, and the nearest and farthest range it showed.  A cell is *established* once
it returned in ``min_frames`` frames spread over at least ``persist_frames`` (first to latest); a
point is background when an established cell within ``dilate`` steps (its own included) has shown a
range no farther than the point's plus a margin::

    margin = min(MARGIN_MIN_M + SPREAD_GAIN * (r_max_m - r_min_m), MARGIN_MAX_M)

(the rule of the sky tracker's :class:`foveatrack.sky.range_background.RangeBackground`, written
here for a sensor that does not move: an equal-angle grid, numpy only).  Anything at or behind a
learned surface is background; a drone in front of it by more than the margin, or in directions
that never returned (the sky), stays foreground.

Why beside the cubes: the rosette of a Livox Mid-40 puts ~10 000 returns a frame into a 38 deg
circle, about one per 0.3 deg cell a frame wherever the surface is, whereas a 0.3 m cube of ground
25 m out at grazing incidence (1.5 m below the sensor) subtends 0.04 deg in elevation and is hit
about once in four frames: its ``background_frames`` (10) returns take ~4 s, and until then its few
returns make drone-sized objects.  Measured on a simulated fixed Mid-40 (ground 1.5 m below, two
drones 12-18 m out): foreground returns per frame 1-2 s after the first frame 2324 (cubes) -> 332
(cubes or cells), 2-5 s 1367 -> 93, after 5 s 847 -> 69.  The cubes stay: a sparse 360 deg sensor
(a Mid-360, ~4000 returns a frame over 360 x 59 deg) hits a 0.3 deg cell about once in 60 frames
but the cubes of the ground next to it every frame, and a point background in either is background.

What is learned (:meth:`DirectionBackground.learn`; the tracker chooses the points): the
foreground points except those of a confirmed track that its motion predicted, and except those
*in front of a direction already learned* (:meth:`covered`): a return nearer than the learned
surface is something in front of the scenery, not scenery.  Without that rule the first frames of
a drone entering in front of a learned wall -- before its track is confirmed and its points kept
out -- brought the wall cells' nearest range down to the drone's, and with the dilation the drone
was background in its next frames and never confirmed (the simulated Mid-40 with a wall at 40 m
and both drones entering after 5 s: 0 frames tracked on a drone; with the rule, 63).  A new static
object in front of learned scenery is not learned here: the cubes learn it, or it is dropped as
static (:mod:`~foveatrack.openloop.tracker`).
"""

from __future__ import annotations

import math

import numpy as np

MARGIN_MIN_M = 0.5
SPREAD_GAIN = 0.5
MARGIN_MAX_M = 1.5


class DirectionBackground:
    """Per-direction range intervals of a fixed sensor (module docstring); :meth:`cells`,
    :meth:`is_background`, :meth:`covered`, :meth:`learn` (once a frame).

    cell_deg : > 0 [deg]          cell side in elevation and azimuth
    min_frames : int >= 1         frames a cell must have returned in to be established
    persist_frames : int >= 0     ... spread over at least this many frames (first to latest)
    dilate : int >= 0             a point is background if a cell this many steps away is
    """

    def __init__(self, cell_deg: float = 0.3, min_frames: int = 3, persist_frames: int = 8, dilate: int = 3):
        self.cell_rad = math.radians(cell_deg)
        self.n_el = int(math.ceil(math.pi / self.cell_rad))
        self.n_az = int(math.ceil(2.0 * math.pi / self.cell_rad))
        self.min_frames = int(min_frames)
        self.persist_frames = int(persist_frames)
        self.dilate = int(dilate)
        size = self.n_el * self.n_az
        self.frames = np.zeros(size, np.int32)
        self.first_frame = np.full(size, -1, np.int64)
        self.last_frame = np.full(size, -1, np.int64)
        self.r_min = np.full(size, np.inf)
        self.r_max = np.full(size, -np.inf)
        self.frame_no = 0
        self._near_limit = np.full(size, np.inf)     # r_min - margin where established, else inf
        d = self.dilate
        self._offsets = [(de, da) for de in range(-d, d + 1) for da in range(-d, d + 1)]

    def cells(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per point: its cell, ``el_index * n_az + az_index`` (-1 for the origin), and its range [m]."""
        xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
        x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        h = np.hypot(x, y)
        r = np.hypot(h, z)
        ie = np.clip(np.floor((np.arctan2(z, h) + 0.5 * math.pi) / self.cell_rad), 0, self.n_el - 1).astype(np.int64)
        ia = np.floor((np.arctan2(y, x) + math.pi) / self.cell_rad).astype(np.int64) % self.n_az
        return np.where(r > 0, ie * self.n_az + ia, -1), r

    def _neighbours(self, cells: np.ndarray):
        """For each offset of the ``dilate`` square: ``(inside, q)`` -- whether the neighbour exists
        (elevation clipped at the poles, azimuth wrapped) and its cell (0 where it does not)."""
        ok = cells >= 0
        c = np.where(ok, cells, 0)
        ie, ia = c // self.n_az, c % self.n_az
        for de, da in self._offsets:
            e = ie + de
            inside = ok & (e >= 0) & (e < self.n_el)
            yield inside, np.where(inside, np.clip(e, 0, self.n_el - 1) * self.n_az + (ia + da) % self.n_az, 0)

    def is_background(self, cells: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Per point: an established cell within ``dilate`` steps has shown a surface no farther
        than the point plus the margin."""
        out = np.zeros(cells.shape[0], bool)
        lim = self._near_limit
        for inside, q in self._neighbours(cells):
            out |= inside & (r >= lim[q])
        return out

    def covered(self, cells: np.ndarray) -> np.ndarray:
        """Per point: its direction (within ``dilate`` steps) is learned scenery, whatever its range."""
        out = np.zeros(cells.shape[0], bool)
        lim = self._near_limit
        for inside, q in self._neighbours(cells):
            out |= inside & (lim[q] < np.inf)
        return out

    def learn(self, cells: np.ndarray, r: np.ndarray) -> None:
        """This frame's points to learn (call once a frame, with none if nothing is to be learned)."""
        ok = cells >= 0
        c, rr = cells[ok], r[ok]
        if c.size:
            u = np.unique(c)
            self.first_frame[u[self.frames[u] == 0]] = self.frame_no
            self.frames[u] += 1
            self.last_frame[u] = self.frame_no
            np.minimum.at(self.r_min, c, rr)
            np.maximum.at(self.r_max, c, rr)
            spread = self.last_frame[u] - self.first_frame[u]
            e = u[(self.frames[u] >= self.min_frames) & (spread >= self.persist_frames)]     # established
            margin = np.minimum(MARGIN_MIN_M + SPREAD_GAIN * (self.r_max[e] - self.r_min[e]), MARGIN_MAX_M)
            self._near_limit[e] = self.r_min[e] - margin
        self.frame_no += 1
