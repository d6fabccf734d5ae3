"""The static scene learned per direction as a range interval, and taken out: of the sky tracker
(issue 28: "the static background learned from the scan itself ... and subtracted",
:mod:`foveatrack.sky.tracks`) and of the open-loop tracker of a fixed sensor
(:mod:`foveatrack.openloop.tracker`, beside its cubes), one model for both.

The head turns about its pivot (the world origin), so a static object keeps its *direction* from
the pivot whatever the head does (a fixed sensor is its own pivot); the rosette's incommensurable
pattern covers every direction of the field over time (paper Fig. 6).  The sphere of directions is cut into cells (a cube map: the
face of the largest coordinate, then the two others divided by it, cut every ``tan(cell_deg)`` --
divisions only, no trigonometry, so the same cell on every CPU), and each cell remembers

* ``frames``  -- in how many frames it returned a point that was learned (counted once a frame),
* ``first_frame``, ``last_frame`` -- the first and the latest of those frames,
* ``r_min_m`` -- the nearest range it has shown, ``r_max_m`` the farthest.

A point is *background* when its cell, or a cell up to ``dilate`` steps away on the same face,
has returned in at least ``min_frames`` frames spread over at least ``persist_frames`` (from its
first to its latest), and the point is no nearer than that cell's nearest range less a margin::

    margin = min(margin_min_m + spread_gain * (r_max_m - r_min_m), margin_max_m)

The margin grows with what the cell has shown: a cell on a swaying tree crown sees its surface come
and go over decimetres, and its interval widens to the crown's whole swing; a cell on a wall shows
one range and keeps the least margin.  Anything at or behind a learned surface is background
(nothing behind an opaque tree is tracked); a drone in front of it by more than the margin, or in a
cell that never returned anything (the sky), stays foreground.

A point is *on scenery in the making* (``near``) when such a cell has returned at least once, first
``near_frames`` ago or earlier, or is *warm scenery* (below): the edge of a crown that swings into
cells it reached once before is not background yet (too few returns) but is not a new object
either.  ``near_frames`` (2 s) is long enough that a drone is far from the cells it crossed that
long ago, even those learned while it was not tracked yet.  The tracker confirms no track on such
points alone (:mod:`foveatrack.sky.tracks`); a stray near return or a bird that passed once does
not blind the cells behind it (it is not background).

Warm scenery (:meth:`RangeBackground.end_warmup`): what the warm-up (the first ``warmup_frames``
frames, before any track) saw is scenery in the making at once -- the crowns must not start tracks
the moment tracking starts -- but only where it *stayed*: a cell the warm-up saw counts if a cell
within ``dilate`` steps returned at two times at least ``persist`` frames apart during the warm-up.
A crown's patch returns again and again where it is; a drone that flew through the field during
the warm-up left a trail of cells each seen for a frame or two (0.3 deg cells, a drone at 40 m and
1 m/s stays in one for ~0.2 s), so its next hits, a few cells on, are not on scenery and confirm it
as soon as the scan allows.  With ``persist`` 0 every cell the warm-up saw counts (the rule before:
on the tuning seeds it cost 38 of 216 drones their confirmation within 2 s,
docs/sky-tracks-figures.md).  A drone that hovers through the warm-up stays scenery until it moves.
The tracker asks 5 frames apart (``warmup_stay_frames``; 3 before the warm-up's frames were
tracked at its end: a drone slow in angle -- 1 m/s at 33 m crosses the dilated neighbourhood in
about a second -- stayed by the 3-frame test; seeds +200..+229 of the four scenes, within 2 s 143
-> 158 of 270 drones, id switches 132 -> 127, false drone tracks 24 -> 26; at 8 frames the crowns'
edges no longer stay: false drone tracks 39).

The persistence (``persist_frames``) keeps a flying object out of the background before its track
protects it: a drone of 0.35 m at 0.8 m/s crosses a 0.3 deg cell at 33 m in 0.65 s, a scenery
cell returns for as long as it is scanned.  The dilation lets a learned crown cover the cells it
sways into between two scans (0.9 deg at the default 3 steps: 0.55 m at 36 m).

Why per direction and not per cube of space (the open-loop tracker's
:class:`~foveatrack.openloop.background.BackgroundModel`, used here before): a crown that sways by
a few decimetres moves its surface through many cubes, each hit rarely by the sparse scan, so the
cubes at the moving surface stay unlearned for seconds and keep making small objects; the direction
cell folds the whole swing into one range interval, hit every few frames.

The hot loops are numba kernels (:func:`cell_kernel`, :func:`background_kernel`,
:func:`learn_kernel`) with a plain-numpy twin each (``*_numpy`` below) that
``tests/sky/test_range_background.py`` compares them against, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from foveatrack.errors import UserError


# ------------------------------------------------------------------------------------------ kernels

@njit(cache=True)
def cell_kernel(xyz, du, n, cells, r):
    """Per point of ``xyz`` (N, 3) [m, world, from the pivot]: its direction cell (``cells`` int64,
    -1 for the origin) and range (``r`` [m]).  Cell = ``(face * n + iu) * n + iv``; face 0..5 is
    +x, -x, +y, -y, +z, -z (the largest |coordinate|, ties to the earlier axis)."""
    for k in range(xyz.shape[0]):
        x = xyz[k, 0]
        y = xyz[k, 1]
        z = xyz[k, 2]
        r[k] = math.sqrt(x * x + y * y + z * z)
        ax = abs(x)
        ay = abs(y)
        az = abs(z)
        if ax >= ay and ax >= az:
            m = ax
            face = 0 if x > 0 else 1
            a = y
            b = z
        elif ay >= az:
            m = ay
            face = 2 if y > 0 else 3
            a = x
            b = z
        else:
            m = az
            face = 4 if z > 0 else 5
            a = x
            b = y
        if m == 0.0:
            cells[k] = -1
            continue
        iu = int(math.floor((a / m + 1.0) / du))
        iv = int(math.floor((b / m + 1.0) / du))
        iu = min(max(iu, 0), n - 1)
        iv = min(max(iv, 0), n - 1)
        cells[k] = (face * n + iu) * n + iv


@njit(cache=True)
def background_kernel(cells, r, n, frames, first_frame, last_frame, r_min, r_max, min_frames, persist_frames,
                      dilate, margin_min, spread_gain, margin_max, frame_no, near_frames, warm_near, out, near):
    """``out[k]`` = point k is background, ``near[k]`` = it lies on scenery in the making (module
    docstring)."""
    nn = n * n
    for k in range(cells.size):
        c = cells[k]
        out[k] = False
        near[k] = False
        if c < 0:
            continue
        face = c // nn
        iu = (c - face * nn) // n
        iv = c - face * nn - iu * n
        for du in range(-dilate, dilate + 1):
            u = iu + du
            if u < 0 or u >= n:
                continue
            for dv in range(-dilate, dilate + 1):
                v = iv + dv
                if v < 0 or v >= n:
                    continue
                q = (face * n + u) * n + v
                if frames[q] >= 1 and (first_frame[q] <= frame_no - near_frames or warm_near[q]):
                    margin = margin_min + spread_gain * (r_max[q] - r_min[q])
                    if margin > margin_max:
                        margin = margin_max
                    if r[k] >= r_min[q] - margin:
                        near[k] = True
                        if frames[q] >= min_frames and last_frame[q] - first_frame[q] >= persist_frames:
                            out[k] = True
                            break
            if out[k]:
                break


@njit(cache=True)
def learn_kernel(cells, r, frame_no, frames, first_frame, last_frame, r_min, r_max):
    """Learn the points: each cell's frame count (once a frame: ``last_frame``), its first frame
    and its range interval."""
    for k in range(cells.size):
        c = cells[k]
        if c < 0:
            continue
        if last_frame[c] != frame_no:
            if frames[c] == 0:
                first_frame[c] = frame_no
            last_frame[c] = frame_no
            frames[c] += 1
        if r[k] < r_min[c]:
            r_min[c] = r[k]
        if r[k] > r_max[c]:
            r_max[c] = r[k]


# ------------------------------------------------------------------------------------------ numpy twins

def cells_numpy(xyz: np.ndarray, du: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Twin of :func:`cell_kernel`."""
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    r = np.sqrt(x * x + y * y + z * z)
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    fx = (ax >= ay) & (ax >= az)
    fy = ~fx & (ay >= az)
    m = np.where(fx, ax, np.where(fy, ay, az))
    face = np.where(fx, np.where(x > 0, 0, 1), np.where(fy, np.where(y > 0, 2, 3), np.where(z > 0, 4, 5)))
    a = np.where(fx, y, x)
    b = np.where(fx | fy, z, y)
    with np.errstate(divide="ignore", invalid="ignore"):
        iu = np.floor((a / m + 1.0) / du)
        iv = np.floor((b / m + 1.0) / du)
    ok = m != 0.0
    iu = np.clip(np.where(ok, iu, 0), 0, n - 1).astype(np.int64)
    iv = np.clip(np.where(ok, iv, 0), 0, n - 1).astype(np.int64)
    cells = np.where(ok, (face.astype(np.int64) * n + iu) * n + iv, -1)
    return cells, r


def face_neighbours(cells: np.ndarray, n: int, dilate: int):
    """For each offset of the square neighbourhood the kernels walk (``dilate`` steps either way on
    the cell's own face), ``(inside, q)``: whether each cell's neighbour there exists (a cell of -1 has
    none) and its index (0 where it does not)."""
    nn = n * n
    ok = cells >= 0
    c = np.where(ok, cells, 0)
    face, rest = c // nn, c % nn
    iu, iv = rest // n, rest % n
    for du in range(-dilate, dilate + 1):
        for dv in range(-dilate, dilate + 1):
            u, v = iu + du, iv + dv
            inside = ok & (u >= 0) & (u < n) & (v >= 0) & (v < n)
            yield inside, np.where(inside, (face * n + np.clip(u, 0, n - 1)) * n + np.clip(v, 0, n - 1), 0)


def face_neighbourhood(cells: np.ndarray, n: int, dilate: int) -> np.ndarray:
    """Every neighbour that :func:`face_neighbours` finds of ``cells``, all offsets at once (flat, in no
    particular order; repeats kept): what is marked around a few hundred cells without a round of numpy
    calls per offset."""
    nn = n * n
    c = cells[cells >= 0]
    face, rest = c // nn, c % nn
    d = np.arange(-dilate, dilate + 1)
    u = (rest // n)[:, None, None] + d[None, :, None]
    v = (rest % n)[:, None, None] + d[None, None, :]
    inside = (u >= 0) & (u < n) & (v >= 0) & (v < n)
    return ((face[:, None, None] * n + u) * n + v)[inside]


def background_numpy(cells, r, n, frames, first_frame, last_frame, r_min, r_max, min_frames, persist_frames,
                     dilate, margin_min, spread_gain, margin_max, frame_no, near_frames,
                     warm_near) -> tuple[np.ndarray, np.ndarray]:
    """Twin of :func:`background_kernel`: ``(out, near)``."""
    out = np.zeros(cells.size, bool)
    near = np.zeros(cells.size, bool)
    for inside, q in face_neighbours(cells, n, dilate):
        margin = np.minimum(margin_min + spread_gain * (r_max[q] - r_min[q]), margin_max)
        with np.errstate(invalid="ignore"):
            old = (first_frame[q] <= frame_no - near_frames) | warm_near[q]
            ok_q = inside & (frames[q] >= 1) & old & (r >= r_min[q] - margin)
        near |= ok_q
        out |= ok_q & established_numpy(q, frames, first_frame, last_frame, min_frames, persist_frames)
    return out, near


def established_numpy(q, frames, first_frame, last_frame, min_frames, persist_frames) -> np.ndarray:
    """Per cell of ``q``: established scenery, returned in ``min_frames`` frames spread over at least
    ``persist_frames`` (the test :func:`background_kernel` makes inline)."""
    return (frames[q] >= min_frames) & (last_frame[q] - first_frame[q] >= persist_frames)


def learn_numpy(cells, r, frame_no, frames, first_frame, last_frame, r_min, r_max) -> None:
    """Twin of :func:`learn_kernel` (in place)."""
    ok = cells >= 0
    c, rr = cells[ok], r[ok]
    u = np.unique(c)
    fresh = u[last_frame[u] != frame_no]
    first_frame[fresh[frames[fresh] == 0]] = frame_no
    frames[fresh] += 1
    last_frame[u] = frame_no
    np.minimum.at(r_min, c, rr)
    np.maximum.at(r_max, c, rr)


# ------------------------------------------------------------------------------------------ the model

#: the background's direction cells [deg]: finer takes hundreds of MB, coarser is metres across
CELL_DEG_RANGE = (0.1, 5.0)


def check_cell_deg(cell_deg: float, key: str = "cell_deg") -> None:
    """A UserError for a cell size outside :data:`CELL_DEG_RANGE`: the direction map holds 6 n^2 cells
    (:func:`face_side_cells`), ~37 bytes each: 0.3 deg is 0.9 M cells (32 MB), 0.1 deg 7.9 M
    (290 MB), 0.01 deg 29 GB; a cell of several degrees is metres across at the scenes' ranges and
    would take a drone for the tree behind it."""
    if not CELL_DEG_RANGE[0] <= cell_deg <= CELL_DEG_RANGE[1]:
        n = face_side_cells(min(cell_deg, 89.0)) if cell_deg > 0 else math.inf
        raise UserError(f"{key} must be in [{CELL_DEG_RANGE[0]}, {CELL_DEG_RANGE[1]}] deg, got "
                        f"{cell_deg!r} (its direction map would hold {6 * n * n:.3g} cells)")


def face_side_cells(cell_deg: float) -> int:
    """Cells along a cube face's side for a cell of ``cell_deg`` at the face's centre: the face spans
    ``[-1, 1]`` in the two coordinates divided by the largest, cut every ``tan(cell_deg)``; the map
    holds ``6 n^2`` cells (module docstring)."""
    return int(math.ceil(2.0 / math.tan(math.radians(cell_deg))))


class RangeBackground:
    """Per-direction range intervals (module docstring); :meth:`cells`, :meth:`is_background`,
    :meth:`learn` (once a frame), :meth:`mark_box`.

    cell_deg : > 0 [deg]          cell side at a face's centre (smaller off it, down to about half)
    min_frames : int >= 1         frames a cell must have returned in to be background
    persist_frames : int >= 0     ... spread over at least this many frames (first to latest)
    near_frames : int >= 0        a cell first seen this long ago (or warm scenery) makes ``near``
    dilate : int 0..3             a point is background if a cell this many steps away is
    margin_min_m, spread_gain, margin_max_m     the margin (module docstring)
    """

    def __init__(self, cell_deg: float = 0.3, min_frames: int = 3, persist_frames: int = 8, dilate: int = 3,
                 margin_min_m: float = 0.5, spread_gain: float = 0.5, margin_max_m: float = 1.5, near_frames: int = 20,
                 warmup_frames: int = 0):
        self.du = math.tan(math.radians(cell_deg))
        self.n = face_side_cells(cell_deg)
        size = 6 * self.n * self.n
        self.min_frames = int(min_frames)
        self.persist_frames = int(persist_frames)
        self.near_frames = int(near_frames)
        self.warmup_frames = int(warmup_frames)     # set by the tracker when its warm-up ends
        self.dilate = int(dilate)
        self.margin_min_m = float(margin_min_m)
        self.spread_gain = float(spread_gain)
        self.margin_max_m = float(margin_max_m)
        self.frames = np.zeros(size, np.int32)
        self.first_frame = np.full(size, -1, np.int64)
        self.last_frame = np.full(size, -1, np.int64)
        self.r_min = np.full(size, np.inf)
        self.r_max = np.full(size, -np.inf)
        self.frame_no = 0
        self.warm_near = np.zeros(size, np.bool_)     # warm scenery (end_warmup)

    def cells(self, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Direction cell and range [m] of each world point."""
        xyz = np.ascontiguousarray(world, np.float64).reshape(-1, 3)
        cells = np.empty(xyz.shape[0], np.int64)
        r = np.empty(xyz.shape[0])
        cell_kernel(xyz, self.du, self.n, cells, r)
        return cells, r

    def is_background(self, cells: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per point: background, and on scenery in the making (``near``)."""
        out = np.empty(cells.size, np.bool_)
        near = np.empty(cells.size, np.bool_)
        background_kernel(cells, r, self.n, self.frames, self.first_frame, self.last_frame, self.r_min, self.r_max,
                          self.min_frames, self.persist_frames, self.dilate, self.margin_min_m, self.spread_gain,
                          self.margin_max_m, self.frame_no, self.near_frames, self.warm_near, out, near)
        return out, near

    def end_warmup(self, persist_frames: int) -> None:
        """The warm-up (its first ``warmup_frames`` frames) is over: mark its warm scenery (module
        docstring), the cells it saw within ``dilate`` steps of one that returned at two times at
        least ``persist_frames`` apart in it (0: every cell it saw)."""
        # the cells seen so far, a few thousand of the 0.9 M, looked at by index (the comparisons over
        # the whole sphere took ~2 ms, a stall at the warm-up's end)
        seen = np.flatnonzero(self.frames >= 1)
        first = self.first_frame[seen]
        warm = seen[(first >= 0) & (first < self.warmup_frames)]
        if persist_frames > 0:
            # the kernel's neighbourhood of every stayed cell, marked by index (a whole-sphere image
            # dilation took 37 ms)
            stayed = warm[self.last_frame[warm] - self.first_frame[warm] >= persist_frames]
            near = np.zeros(self.frames.size, np.bool_)
            near[face_neighbourhood(stayed, self.n, self.dilate)] = True
            warm = warm[near[warm]]
        self.warm_near = np.zeros(self.frames.size, np.bool_)
        self.warm_near[warm] = True

    def covered(self, cells: np.ndarray) -> np.ndarray:
        """Per point: a cell within ``dilate`` steps is established (it returned in ``min_frames``
        frames spread over ``persist_frames``), whatever the point's range: its direction is known
        scenery, and a foreground point there is something in front of it.  The open-loop tracker
        learns no such point (a drone's first frames before its track is confirmed brought a wall's
        cells down to its range, and the drone was background from then on)."""
        out = np.zeros(cells.size, np.bool_)
        for inside, q in face_neighbours(cells, self.n, self.dilate):
            out |= inside & established_numpy(q, self.frames, self.first_frame, self.last_frame, self.min_frames,
                                              self.persist_frames)
        return out

    def learn(self, cells: np.ndarray, r: np.ndarray) -> None:
        """This frame's points to learn (call once a frame, with none if nothing is to be learned)."""
        learn_kernel(cells, r, self.frame_no, self.frames, self.first_frame, self.last_frame, self.r_min, self.r_max)
        self.frame_no += 1

    def mark_box(self, lo_m: np.ndarray, hi_m: np.ndarray) -> None:
        """Make the cells that see the box ``[lo_m, hi_m]`` background at once, from its near side
        on (an object found to be static scenery)."""
        lo, hi = np.asarray(lo_m, float), np.asarray(hi_m, float)
        r_far = float(np.sqrt(np.sum(np.maximum(np.abs(lo), np.abs(hi)) ** 2)))
        step = max(0.25 * self.du * max(r_far, 1.0), 1e-3)
        axes = [np.linspace(a, b, max(2, int(math.ceil((b - a) / step)) + 1)) for a, b in zip(lo, hi)]
        # the box's six faces, not its volume: a ray from the pivot through the box enters and leaves
        # it through them (its nearest and farthest points are there), and the faces cost ~6 n^2 cells
        # to look up where the volume cost n^3 (a 2 m box at 15 m: 64 k against 1.1 M, 67 ms a call in
        # the daemon's loop)
        faces = []
        for a in range(3):
            b, c = [x for x in range(3) if x != a]
            g = np.stack(np.meshgrid(axes[b], axes[c], indexing="ij"), -1).reshape(-1, 2)
            for v in (lo[a], hi[a]):
                f = np.empty((g.shape[0], 3))
                f[:, a], f[:, b], f[:, c] = v, g[:, 0], g[:, 1]
                faces.append(f)
        cells, r = self.cells(np.concatenate(faces))
        ok = cells >= 0
        cells, r = cells[ok], r[ok]
        np.minimum.at(self.r_min, cells, r)
        np.maximum.at(self.r_max, cells, r)
        u = np.unique(cells)
        fresh = u[self.frames[u] == 0]
        self.first_frame[fresh] = self.frame_no
        self.last_frame[fresh] = self.frame_no
        self.frames[u] = np.maximum(self.frames[u], self.min_frames)
        # seen long enough ago to be scenery (near_frames) and spread over persist_frames: background
        # now (with persist_frames alone, a box marked after the warm-up waited out near_frames first)
        self.first_frame[u] = np.minimum(self.first_frame[u],
                                         self.last_frame[u] - max(self.persist_frames, self.near_frames))
