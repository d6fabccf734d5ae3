"""The static scene of a fixed sensor, learned from the scans over time and taken out.

The sensor frame is the world here (the sensor does not move).  Space is cut into cubes of
``voxel_m``; a cube is *background* once points fell in it in ``background_frames`` frames (each
frame counts a cube once).  A static object (a building, a tree, the ground) keeps returning from the
same cubes and becomes background after ``background_frames`` frames; a flying drone moves through
cubes and a tracked one is never learned (the tracker does not show it its points), so it stays
foreground.  The sky returns nothing and learns nothing.

A point is background when its cube *or one of its 26 neighbours* is (``dilate = 1``): a sparse
scan (the rosette leaves gaps from frame to frame) leaves cubes at the edge of a surface unlearned
for a long time, and their few points would otherwise come out as small objects.  The cost: a drone
within one cube of the static scene is taken for it.

Cube keys are three 21-bit signed integers packed in an int64 (cubes within +-1e6 voxels: +-300 km
at 0.3 m); counts live in a dict (sparse: a scene holds ~10^5 cubes).
"""

from __future__ import annotations

import numpy as np

_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1


def voxel_keys(xyz: np.ndarray, voxel_m: float) -> np.ndarray:
    """One int64 key per point: its cube's integer coordinates packed (far points clipped to the
    outermost cube, which no scene reaches)."""
    ijk = np.floor(np.asarray(xyz, np.float64).reshape(-1, 3) / voxel_m)
    ijk = np.clip(ijk, -_OFFSET, _OFFSET - 1).astype(np.int64) + _OFFSET
    return (ijk[:, 0] << (2 * _BITS)) | (ijk[:, 1] << _BITS) | ijk[:, 2]


class BackgroundModel:
    """Per-cube frame counts; :meth:`is_background` and :meth:`learn`.

    voxel_m : float > 0 [m]             cube size
    background_frames : int >= 1        frames a cube must be hit in to be background
    dilate : int 0..2                   a point is background if a cube this many steps away is
    """

    def __init__(self, voxel_m: float = 0.3, background_frames: int = 10, dilate: int = 1):
        self.voxel_m = float(voxel_m)
        self.background_frames = int(background_frames)
        d = int(dilate)
        self._offsets = np.array([(i << (2 * _BITS)) + (j << _BITS) + k for i in range(-d, d + 1)
                                  for j in range(-d, d + 1) for k in range(-d, d + 1)], np.int64)
        self._count: dict[int, int] = {}
        self._background = np.empty(0, np.int64)    # sorted keys of background cubes
        self._dirty = False

    @property
    def n_background_voxels(self) -> int:
        self._refresh()
        return int(self._background.size)

    def _refresh(self) -> None:
        if self._dirty:
            nb = self.background_frames
            self._background = np.sort(np.fromiter((k for k, c in self._count.items() if c >= nb), np.int64))
            self._dirty = False

    def is_background(self, keys: np.ndarray) -> np.ndarray:
        """Mask of the points (given by their :func:`voxel_keys`) in background cubes."""
        self._refresh()
        bg = self._background
        if bg.size == 0 or keys.size == 0:
            return np.zeros(keys.shape[0], bool)
        out = np.zeros(keys.shape[0], bool)
        for off in self._offsets:   # packed keys add per axis (no axis carries: cubes are offset inside 21 bits)
            q = keys + off
            i = np.searchsorted(bg, q)
            i[i == bg.size] = 0
            out |= bg[i] == q
        return out

    def learn(self, keys: np.ndarray) -> None:
        """Count each cube of this frame's points once."""
        if keys.size == 0:
            return
        nb = self.background_frames
        count = self._count
        for k in np.unique(keys).tolist():
            c = count.get(k, 0) + 1
            count[k] = c
            if c == nb:
                self._dirty = True

    def mark_box(self, lo_m: np.ndarray, hi_m: np.ndarray) -> None:
        """Make every cube of the box ``[lo_m, hi_m]`` background at once (an object found to be
        static scenery: :mod:`foveatrack.openloop.tracker`)."""
        v = self.voxel_m
        i0, i1 = np.floor(np.asarray(lo_m) / v).astype(np.int64), np.floor(np.asarray(hi_m) / v).astype(np.int64)
        grid = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(i0, i1)], indexing="ij"), -1).reshape(-1, 3)
        keys = voxel_keys((grid + 0.5) * v, v)
        for k in keys.tolist():
            self._count[k] = max(self._count.get(k, 0), self.background_frames)
        self._dirty = True
