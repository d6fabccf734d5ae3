"""Open-loop tracking of a fixed sensor: acquisition without a hand-made D, then Algorithm 1.

Per frame (points in the sensor frame, which is the world: the sensor does not move):

1. **Background out**: a point is the static scene if its cube returned in ``background_frames``
   frames (:mod:`~foveatrack.openloop.background`) *or* its direction shows a learned surface no
   farther than it (:class:`~foveatrack.openloop.range_background.RangeBackground`, the sky
   tracker's model: 0.3 deg cells, 3 returns over 8 frames).  The directions learn the scenery of a fixed Mid-40 far sooner than the cubes
   (a cube of ground at grazing incidence is hit once in four frames, a direction cell about once
   a frame); the cubes keep what a sparse 360 deg sensor hits near it.
2. **The tracked object** (once there is one): D is the box of half-size ``d_half_m`` around its
   predicted position, and the paper's Algorithm 1 (App. D.2, the per-axis median of the points in
   D, :func:`foveatrack.detection.detect_in_box`, the tracker's own kernel) gives its position.  A
   track not seen for ``lost_after_s`` is dropped.
3. **Acquisition**: the other foreground points are clustered into objects
   (:mod:`~foveatrack.openloop.objects`); objects are matched to candidate tracks by gated nearest
   neighbour (gate ``gate_m + max_speed_m_s * dt``, nearest pairs first).  A candidate is
   *confirmed* when it has been hit in ``confirm_hits`` frames within its first ``confirm_window``
   frames, every hit an object of at least ``min_points`` returns and at most ``max_extent_m``
   across (drone-sized).  While nothing is tracked, the confirmed object highest above the sensor's
   XY plane (largest elevation: the drone is the object against the sky, scenery sits near the
   horizon) becomes the tracked object; and while the tracked object is below that plane (the
   ground, seen before the background knew it), a confirmed object higher than it takes its place.
4. **Learning**: the cubes of every foreground point not in the tracked object's D or a confirmed
   track's object are counted toward the background.  The directions learn the same points, but
   keep out a confirmed track's object or D only where the track's motion predicted it (within
   ``protect_m``): a "track" that hops among patches of ground or wall the background has not
   learned yet (the rosette samples a different patch each frame, metres apart) is no drone, and
   its patches are learned and gone (a simulated Mid-40 before a wall, the drones entering at 5 s:
   wall patches followed to 4.8 s and a drone from 5.9 s when every confirmed object was kept out,
   to 4.0 s and from 5.0 s with this rule).  Nor do the directions learn a return in front of a
   direction they already know (:meth:`~foveatrack.openloop.range_background.RangeBackground.covered`:
   something in front of the scenery, e.g. a drone's first frames before its track is confirmed;
   without it, in the same run, no frame on a drone, 53 with it).

Why stray sky returns never confirm: they are single returns along scattered beams, 100-400 m out
(MMAUD seq1), so no ``min_points`` of them fall within one cluster gap (``max(cluster_tol_m,
cluster_tol_rad * range)``: 3 m at 300 m) in ``confirm_hits`` frames at one place.  A static,
drone-sized object seen from the first frame *is* confirmed (nothing tells it from a hovering drone
in 0.3 s); once it has stayed within ``static_radius_m`` for ``static_window_s`` it is taken for
scenery, dropped and its D's cubes made background (so a drone hovering that still for that long is
lost too: a drone is found as a *moving* object).  On a simulated fixed Mid-40 with the ground 1.5 m
below and two drones 12-18 m out (one 2.5 m up), the cubes alone confirmed 27 tracks and followed
ground patches 19-30 m out from 0.2 to 2.8 s, the drone from 3.9 s; with a wall at 40 m, 91 tracks
and wall patches at the field's rim (16 deg up) all along, never a drone.  With the directions and
the re-choice, in both: ground patches from 0.2 to 0.8 s (nothing above them confirmed yet), the
drone from 0.9 s to the end, 19 and 30 tracks.  With D given by the user (``space``) no
acquisition is done: Algorithm 1 runs with that D on every frame, as the paper's tracker does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from collections.abc import Mapping

import numpy as np

from foveatrack.config_util import dataclass_from_mapping
from foveatrack.detection import Detection, box_bounds, box_detection, detect, LEVEL
from foveatrack.errors import UserError
from foveatrack.fixed_order import norm3
from foveatrack.frames import Frame
from foveatrack.openloop.background import BackgroundModel, voxel_keys
from foveatrack.openloop.range_background import RangeBackground, check_cell_deg
from foveatrack.openloop.objects import cluster_labels, objects_from_labels
from foveatrack.space_of_interest import Box, SpaceOfInterest, space_from_mapping

_ZERO3 = np.zeros(3)


@dataclass(frozen=True)
class OpenLoopConfig:
    """Parameters of :class:`OpenLoopTracker` (a ``[openloop]`` table; units in the names).

    voxel_m : > 0 [m]                  background cube size
    background_frames : int >= 1       frames a cube must return in to be background (10 = 1 s at 10 Hz)
    background_dilate : int 0..2       a point is background if a cube this many steps away is
    direction_cell_deg : 0 or 0.1..5 [deg]  direction cells of the background learned per direction (0: none,
                                       cubes only; :mod:`~foveatrack.openloop.range_background`)
    direction_frames : int >= 1, direction_persist_frames : int >= 0   a cell is learned once it
                                       returned in that many frames spread over that many
    direction_dilate : int 0..3        a point is background if a learned cell this many steps away
                                       shows a surface no farther than it
    protect_m : > 0 [m]                a confirmed track's object (or D) is kept out of the directions'
                                       learning only when within this of the track's prediction
    cluster_tol_m : > 0 [m]            cluster gap near the sensor
    cluster_tol_rad : >= 0 [rad]       cluster gap per metre of range (beams spread)
    min_points : int >= 1              returns an object needs for a hit toward confirmation
    max_extent_m : > 0 [m]             largest side of an object that can be a drone
    gate_m : > 0 [m], max_speed_m_s : >= 0 [m/s]   association gate ``gate_m + max_speed_m_s * dt``
    confirm_hits : int >= 1, confirm_window : int >= confirm_hits   M of the first N frames
    lost_after_s : > 0 [s]             a track unseen this long is dropped
    static_window_s : > 0 [s], static_radius_m : > 0 [m]   a confirmed track whose positions over
                                       the last static_window_s all lie within static_radius_m of their
                                       median is static scenery: dropped, its D made background
    d_half_m : > 0 [m]                 half-size of the box D around a tracked object
    space : D or None                  a hand-made D: no acquisition, Algorithm 1 with it on every frame
    """

    voxel_m: float = 0.3
    background_frames: int = 10
    background_dilate: int = 1
    direction_cell_deg: float = 0.3
    direction_frames: int = 3
    direction_persist_frames: int = 8
    direction_dilate: int = 3
    protect_m: float = 1.0
    cluster_tol_m: float = 0.5
    cluster_tol_rad: float = 0.01
    min_points: int = 5
    max_extent_m: float = 2.0
    gate_m: float = 1.0
    max_speed_m_s: float = 20.0
    confirm_hits: int = 3
    confirm_window: int = 5
    lost_after_s: float = 1.0
    static_window_s: float = 3.0
    static_radius_m: float = 0.5
    d_half_m: float = 1.0
    space: SpaceOfInterest | None = None

    def __post_init__(self) -> None:
        for k in ("voxel_m", "cluster_tol_m", "max_extent_m", "gate_m", "lost_after_s", "d_half_m",
                  "static_window_s", "static_radius_m", "protect_m"):
            if not getattr(self, k) > 0:
                raise UserError(f"{k} must be > 0, got {getattr(self, k)!r}")
        if not 0 <= self.background_dilate <= 2:
            raise UserError(f"background_dilate must be 0, 1 or 2, got {self.background_dilate!r}")
        if not 0 <= self.direction_dilate <= 3:
            raise UserError(f"direction_dilate must be 0, 1, 2 or 3, got {self.direction_dilate!r}")
        if self.direction_cell_deg != 0:        # 0: no direction cells
            check_cell_deg(self.direction_cell_deg, "direction_cell_deg")
        if self.direction_persist_frames < 0:
            raise UserError(f"direction_persist_frames must be >= 0, got {self.direction_persist_frames!r}")
        for k in ("background_frames", "direction_frames", "min_points", "confirm_hits"):
            if getattr(self, k) < 1:
                raise UserError(f"{k} must be >= 1, got {getattr(self, k)!r}")
        if self.confirm_window < self.confirm_hits:
            raise UserError("confirm_window must be >= confirm_hits")

    @classmethod
    def from_mapping(cls, data: Mapping, where: str) -> "OpenLoopConfig":
        return dataclass_from_mapping(cls, data, where, parsers={"space": space_from_mapping})


@dataclass
class Track:
    """A candidate or confirmed object over frames."""
    track_id: int
    xyz_m: np.ndarray
    t_s: float
    first_t_s: float
    frames_seen: int = 0         # frames since creation (for the confirmation window)
    hits: int = 0
    confirmed_t_s: float | None = None
    vel_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mean_range_m: float = 0.0
    static: bool = False
    history: list = field(default_factory=list)    # (t_s, xyz) of the hits in the last static_window_s

    @property
    def confirmed(self) -> bool:
        return self.confirmed_t_s is not None

    def predict(self, t_s: float) -> np.ndarray:
        return self.xyz_m + self.vel_m_s * (t_s - self.t_s)

    def update(self, xyz: np.ndarray, t_s: float, max_speed_m_s: float) -> None:
        dt = t_s - self.t_s
        if dt > 0:
            v = (np.asarray(xyz, float) - self.xyz_m) / dt
            s = float(np.sqrt(np.sum(v * v)))
            if s > max_speed_m_s > 0:
                v = v * (max_speed_m_s / s)
            self.vel_m_s = 0.5 * self.vel_m_s + 0.5 * v if self.hits > 1 else v
        self.xyz_m = np.asarray(xyz, float)
        self.t_s = t_s
        self.history.append((t_s, self.xyz_m))

    def is_static(self, t_s: float, window_s: float, radius_m: float) -> bool:
        """Hit over the last ``window_s`` (its hits there span at least nine tenths of it) and every
        position of those hits within ``radius_m`` of their median: scenery, not a drone (a drone
        moves).  A track first seen long ago but hit only lately (a scenery patch's candidate that
        took a slow drone 1.4 s before) is not judged on those few hits: a drone at 0.3 m/s was."""
        self.history = [h for h in self.history if h[0] >= t_s - window_s]
        if (t_s - self.first_t_s < window_s or len(self.history) < 3
                or t_s - self.history[0][0] < 0.9 * window_s):
            return False
        p = np.array([h[1] for h in self.history])
        d = p - np.median(p, axis=0)
        return bool(np.all(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2] <= radius_m * radius_m))


@dataclass(frozen=True)
class OpenLoopOutput:
    """One frame's result: the tracked object's Algorithm 1 detection (or None), which track and
    in which state (``"tracking"`` detected, ``"coasting"`` tracked but unseen this frame,
    ``"searching"`` no tracked object), the D used, and the frame's counts."""
    detection: Detection | None
    track_id: int | None
    state: str
    d_min_m: np.ndarray | None
    d_max_m: np.ndarray | None
    n_points: int
    n_foreground: int
    n_objects: int
    n_candidates: int
    confirmed_now: tuple[int, ...]


def _elevation(tr: Track) -> float:
    x, y, z = tr.xyz_m.tolist()
    return math.atan2(z, math.hypot(x, y))


class OpenLoopTracker:
    """Frames of a fixed sensor in, one tracked object's position out (see the module docstring)."""

    def __init__(self, cfg: OpenLoopConfig | None = None):
        self.cfg = cfg or OpenLoopConfig()
        self.background = BackgroundModel(self.cfg.voxel_m, self.cfg.background_frames,
                                          self.cfg.background_dilate)
        c = self.cfg
        # a cell is background once established, however recent (near_frames 0: the sky tracker's wait
        # for scenery in the making is for a turning head's field)
        self.directions = (RangeBackground(c.direction_cell_deg, c.direction_frames, c.direction_persist_frames,
                                           c.direction_dilate, near_frames=0) if c.direction_cell_deg > 0 else None)
        self.tracks: list[Track] = []        # candidates and confirmed, not the tracked one
        self.tracked: Track | None = None
        self.confirmed: list[Track] = []     # every track ever confirmed, in order
        self._next_id = 0

    def process(self, frame: Frame) -> OpenLoopOutput:
        cfg = self.cfg
        t = frame.t_start_s
        xyz, t_ns = frame.xyz, frame.t_ns
        if cfg.space is not None:   # a hand-made D: the paper's Algorithm 1 as it is
            det = detect(frame, cfg.space)
            return OpenLoopOutput(det, None, "tracking" if det else "searching", None, None, frame.n_points,
                                  frame.n_points, 0, 0, ())
        keys = voxel_keys(xyz, cfg.voxel_m)
        bg = self.background.is_background(keys)
        dirs = self.directions
        if dirs is not None:
            cells, ranges = dirs.cells(xyz)
            bg |= dirs.is_background(cells, ranges)[0]
        fg = ~bg
        fg0 = fg.copy()
        n_fg = int(np.count_nonzero(fg))
        learn = fg.copy()            # the cubes learn these
        learn_dir = fg.copy()        # the directions these (step 4 of the module docstring)
        det = None
        d_lo = d_hi = None
        tr = self.tracked
        if tr is not None:
            c = tr.predict(t)
            d_lo, d_hi = c - cfg.d_half_m, c + cfg.d_half_m
            box = Box(tuple(d_lo.tolist()), tuple(d_hi.tolist()))
            lo, hi = box_bounds(box)
            in_d = fg & box.contains(xyz)
            det = box_detection(np.ascontiguousarray(xyz[fg]), np.ascontiguousarray(t_ns[fg]), LEVEL, _ZERO3, lo, hi)
            learn &= ~in_d
            fg &= ~in_d
            if det is None or norm3(np.asarray(det.xyz, float) - c) <= cfg.protect_m:
                learn_dir &= ~in_d
            if det is not None:
                tr.hits += 1
                tr.update(det.xyz, t, cfg.max_speed_m_s)
            elif t - tr.t_s > cfg.lost_after_s:
                self.tracked = tr = None
        objs = self._objects(xyz[fg])
        confirmed_now, hit_keys = self._associate(objs, t)
        # the points of confirmed objects are not learned (a hovering drone stays foreground); by the
        # directions only where the track's motion predicted them
        if hit_keys:
            fg_idx = np.flatnonzero(fg)
            for mask, predicted in hit_keys:
                learn[fg_idx[mask]] = False
                if predicted:
                    learn_dir[fg_idx[mask]] = False
        self.background.learn(keys[learn])
        if dirs is not None:
            i = np.flatnonzero(learn_dir)
            i = i[~dirs.covered(cells[i])]    # not what is in front of known scenery
            dirs.learn(cells[i], ranges[i])
        self._drop_static(t)
        tr = self.tracked
        if tr is not None and _elevation(tr) < 0 and any(k.confirmed and _elevation(k) > _elevation(tr)
                                                          for k in self.tracks):
            # below the sensor's XY plane (the ground, confirmed before the background knew it), and a
            # confirmed object higher up: that one is chosen below, this one stays a confirmed candidate
            self.tracks.append(tr)
            self.tracked = None
        if self.tracked is None:
            live = [k for k in self.tracks if k.confirmed]
            if live:
                # the highest above the sensor's XY plane (the drone is the object against the sky;
                # ties: the first confirmed), tracked from this frame on: Algorithm 1 in its D here too
                self.tracked = tr = max(live, key=_elevation)
                self.tracks.remove(tr)
                c = tr.xyz_m
                d_lo, d_hi = c - cfg.d_half_m, c + cfg.d_half_m
                lo, hi = box_bounds(Box(tuple(d_lo.tolist()), tuple(d_hi.tolist())))
                det = box_detection(np.ascontiguousarray(xyz[fg0]), np.ascontiguousarray(t_ns[fg0]),
                                    LEVEL, _ZERO3, lo, hi)
                if det is not None:
                    tr.update(det.xyz, t, cfg.max_speed_m_s)
        state = "searching" if self.tracked is None else ("tracking" if det is not None else "coasting")
        return OpenLoopOutput(det, None if self.tracked is None else self.tracked.track_id, state,
                              d_lo, d_hi, frame.n_points, n_fg,
                              len(objs[0]), len(self.tracks), tuple(confirmed_now))

    def _drop_static(self, t: float) -> None:
        """Confirmed tracks that have not moved (:meth:`Track.is_static`) are scenery confirmed
        before the background had learned it: dropped, and their D's cubes made background (not its
        directions: that would hide everything behind the D)."""
        cfg = self.cfg
        for tr in [k for k in self.tracks if k.confirmed] + ([self.tracked] if self.tracked else []):
            if tr.is_static(t, cfg.static_window_s, cfg.static_radius_m):
                tr.static = True
                self.background.mark_box(tr.xyz_m - cfg.d_half_m, tr.xyz_m + cfg.d_half_m)
                if tr is self.tracked:
                    self.tracked = None
                else:
                    self.tracks.remove(tr)

    def _objects(self, xyz: np.ndarray):
        """The frame's drone-like objects (at least ``min_points`` returns, at most ``max_extent_m``
        across), their labels and the point labels."""
        cfg = self.cfg
        if xyz.shape[0] == 0:
            return [], [], np.empty(0, np.int64)
        labels, n = cluster_labels(xyz, cfg.cluster_tol_m, cfg.cluster_tol_rad)
        objs, kept = objects_from_labels(xyz, labels, n, cfg.min_points, cfg.max_extent_m)
        return objs, kept, labels

    def _associate(self, objs_labels, t: float):
        """Gated nearest-neighbour matching of the drone-like objects to candidate tracks (nearest
        pairs first, ties by order: a stable sort), new candidates from unmatched objects,
        confirmation, deletion.  Returns the ids confirmed this frame and, for each object matched to
        a confirmed track, its point mask (kept out of the background) and whether it lay within
        ``protect_m`` of the track's prediction."""
        cfg = self.cfg
        objs, kept, labels = objs_labels
        for tr in self.tracks:
            tr.frames_seen += 1
        pairs = []
        if self.tracks and objs:
            p = np.array([tr.predict(t) for tr in self.tracks])
            gate = np.array([cfg.gate_m + cfg.max_speed_m_s * max(t - tr.t_s, 0.0) for tr in self.tracks])
            o = np.array([ob.xyz_m for ob in objs])
            d = o[None, :, :] - p[:, None, :]
            dist = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])
            ti, oi = np.nonzero(dist <= gate[:, None])
            order = np.argsort(dist[ti, oi], kind="stable")
            pairs = list(zip(ti[order].tolist(), oi[order].tolist()))
        used_t, used_o = set(), set()
        confirmed_now, keep_out = [], []
        for ti, oi in pairs:
            if ti in used_t or oi in used_o:
                continue
            used_t.add(ti)
            used_o.add(oi)
            tr, ob = self.tracks[ti], objs[oi]
            predicted = bool(dist[ti, oi] <= cfg.protect_m)
            tr.hits += 1
            tr.mean_range_m += (ob.range_m - tr.mean_range_m) / tr.hits
            tr.update(ob.xyz_m, t, cfg.max_speed_m_s)
            if not tr.confirmed and tr.hits >= cfg.confirm_hits and tr.frames_seen <= cfg.confirm_window:
                tr.confirmed_t_s = t
                self.confirmed.append(tr)
                confirmed_now.append(tr.track_id)
            if tr.confirmed:
                keep_out.append((labels == kept[oi], predicted))
        for oi, ob in enumerate(objs):
            if oi in used_o:
                continue
            tr = Track(self._next_id, ob.xyz_m, t, t, frames_seen=1, hits=1, mean_range_m=ob.range_m)
            self._next_id += 1
            if cfg.confirm_hits == 1:
                tr.confirmed_t_s = t
                self.confirmed.append(tr)
                confirmed_now.append(tr.track_id)
            self.tracks.append(tr)
        # drop candidates past their window unconfirmed, and any track unseen too long
        self.tracks = [k for k in self.tracks
                       if (k.confirmed or k.frames_seen < cfg.confirm_window) and t - k.t_s <= cfg.lost_after_s]
        return confirmed_now, keep_out
