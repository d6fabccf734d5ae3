"""Every moving object in the field, tracked from the moving head (issue 28).

Per frame:

1. The points go into the world at each point's head pose (:mod:`foveatrack.sky.world_points`).
2. The static scene is learned per direction from the pivot and taken out
   (:class:`~foveatrack.openloop.range_background.RangeBackground`: each cell's range interval, with a
   margin grown from its spread, so a swaying crown folds into one interval).  The rosette's
   incommensurable pattern covers the field over time (paper Fig. 6).  The first ``warmup_s`` the
   background learns alone; what it saw there is scenery in the making at once where it stayed
   (``warmup_stay_frames``), so a drone that flew through the warm-up is not.  Its frames are kept
   and tracked when it ends (``warmup_replay``), against the background that now knows what stayed:
   a drone in the field at power-on has its hits from the first frame, and can be confirmed in the
   first frame after the warm-up (seeds +200..+229 of the four sky scenes: confirmed within 2 s of
   entering the field 115 -> 158 of 270 drones).  What the replay starts and ends within the
   warm-up's frames is never shown, and not reported deleted.  Points of an object are kept out of the learning while its track may be
   something flying (a tentative track off the scenery, a confirmed one that went ``protect_excursion_m``
   or more) and the object is where the track's motion predicted it (within ``protect_m``); so are
   the points in the fixated track's D, if it is such a confirmed track (a hovering drone with one
   return a frame makes no object; flock seed +240: it became scenery and its track took a bird).  Objects
   mostly on *scenery in the making* (next to cells seen long ago, not yet background) give hits that
   do not count toward confirmation.
3. The remaining points are clustered into objects (:func:`foveatrack.openloop.objects.frame_objects`:
   single linkage with a gap growing with range, the clusters summarised, each point's object and the
   lone returns in one numba kernel, with its numpy twin); an object
   has at least ``min_points`` returns and at most ``max_extent_m`` across.  Each object: median
   position and time of its points, point count, bounding-box sides.
4. Association: global nearest neighbour.  The cost of track ``i`` and object ``j`` is the squared
   Mahalanobis distance of the object from the track's prediction (:mod:`foveatrack.sky.motion`); a
   pair is allowed when it is at most ``gate_chi2`` (16.27: 99.9 % of a chi-square of 3 degrees of
   freedom) and the object is at most ``gate_max_m`` (2.5 m) from the prediction.  The second
   bound is the one that holds a drone's track on its drone: a track unseen for a while has a
   Mahalanobis gate metres wide, and a bird flying past took it (on drone-and-flock the drone's own
   object lay within 0.59 m of its track's prediction in 99 % of 962 hits, 1.82 m at most, the birds
   the track took 1.1-4.4 m; 15 runs, seeds +200..+214).  2.5 m is a drone accelerating at 5 m/s^2
   for 1 s unseen.  Chosen on seeds +200..+229 of the four sky scenes against the 5 m before:
   id switches 44 -> 11 (flock), 62 -> 24 (swarm), 3 -> 1 (tree line), 0 -> 0 (crossing); drones
   confirmed within 2 s 160 -> 179 of 270; runs with every revisit within 3 s 25 -> 44 of 120; false
   drone tracks near birds 6 -> 5, near crowns 5 -> 8 (cold starts), second tracks on a drone
   11 -> 13.  scipy's
   ``linear_sum_assignment`` picks the assignment with the most allowed pairs, and among those the
   least total cost (forbidden pairs cost more than all allowed ones together, and are dropped).
   A tentative track with a hit off the scenery takes no object on the scenery: its velocity, from
   two or three hits, gates metres wide, and on the tree line such a candidate on the drone jumped
   to a crown's part 3-4 m below it (at 20-60 m/s) and the drone started over (cold hours: drones
   confirmed within 2 s 87 -> 129 of the 150 the scan's rays allowed; over the four scenes id
   switches 625 -> 650, false drone tracks near birds and crowns 47 -> 47).
5. Each matched track's filter takes its object's median; the fixated track (the one the fovea
   serves, :mod:`foveatrack.sky.attention`) takes the paper's Algorithm 1 instead: the per-axis
   median of the foreground points inside its D, a box of ``d_half_m`` around its prediction (in the
   world, tested at the frame's mid pose as the tracker's world D is), without the points of objects
   matched to other tracks -- a bird flying through the drone's D does not pull its median.
5b. Lone returns (``lone_returns``, default on): the tracks no object or Algorithm 1
   measured this frame take the frame's single returns off the scenery (clusters of one return,
   not next to scenery in the making) by the same gated global nearest neighbour, within
   ``lone_gate_m`` (1 m) of the prediction: a lone return updates the filter and is a hit toward
   confirmation, but starts no track and is no shape for the classifier (the history, and rule 5's
   count of measured frames, are the objects').  The low-confidence detections that extend tracks
   but start none, as in ByteTrack (Zhang et al., 2022).  A small drone 35-45 m out returns one
   point a frame at the rosette's sparse rim (paper Fig. 5), and ``min_points`` makes no object of
   it: on the swarm it is confirmed late or never, and its track coasts between objects.  Gates of
   0.5, 0.75, 1 and 2.5 m were tried on seeds +200..+229 of the sky scenes; checked on +230..+259
   with 1 m: drones confirmed within 2 s 157 -> 211 of 270 (swarm 67 -> 108, flock 19 -> 27).  The
   birds' tracks are confirmed sooner too, and unknown (no shapes yet) they took the fovea from the
   flock's drone (runs with every revisit within 3 s 20 -> 15), so it was an option until the
   classifier read their speed from the filter (:mod:`foveatrack.sky.classify` rule 1,
   ``bird_speed_after_hits``) and the attention summed a priority's unseen time over fixations.
   With both, against objects only, on seeds +200..+229 / +230..+259 / +0..+7: drones confirmed
   within 2 s swarm 81 -> 108 / 67 -> 107 / 20 -> 30, flock 26 -> 30 / 19 -> 27 / 7 -> 8, crossing
   and tree line within 4; runs with every revisit within 3 s flock 26 -> 26 / 24 -> 27 / 5 -> 8,
   tree line 17 -> 19 / 16 -> 19 / 5 -> 5; id switches flock 10 -> 5 / 18 -> 11 / 4 -> 3, but the
   swarm's 26 -> 33 / 30 -> 42 / 9 -> 8: a lost drone is tracked again sooner, and its new id counts
   as a switch (continuity up: 0.78 -> 0.97 on the regression's eight seeds).  The crossing's eight
   seeds have none either way.  Figures: docs/sky-tracks-figures.md.
6. Unmatched objects start tentative tracks, except one within ``spawn_clear_m`` of a confirmed
   track's hit of this frame: the sparse scan splits a drone into two clusters now and then, and a
   second track on it would take its hits in turn with the first (swarm-of-five, 24 runs: id
   switches 102 -> 74, second tracks labelled drone 16 -> 9).  A tentative track is confirmed after ``confirm_hits``
   hits off the scenery in its first ``confirm_window`` frames, and dropped if it is not.  A track is
   deleted once it has gone unseen for ``lost_after_s`` of the time where it was last seen lay in the
   lidar's field (``field_half_angle_deg`` around the optical axis at the frame's pose), or for
   ``lost_out_of_view_s`` in all: the time the head looked elsewhere does not count toward the first
   (the crossing, seed 33: the head turned back to a drone it had left 1.7 s before, and its track
   was deleted 0.5 s after the drone was back at the sparse rim; over the cold hours of the four
   scenes, id switches 847 -> 833); so is one merged with another track's object (an object matched to another track
   lies in its gate while none is left for it: two clusters became one) for longer.  A confirmed
   track that in ``static_window_s`` of life never got ``static_radius_m`` from where it was first
   seen is scenery (a part of a tree the background has not learned yet): dropped, and its D made
   background (as in the open-loop tracker).  Two confirmed tracks within ``merge_m`` and
   ``merge_v_m_s`` of each other ``merge_frames`` frames in a row are one object: the one with fewer
   hits in its history is dropped (a crown's track that came onto a drone took its hits in turn with
   the drone's own track: 28 id switches in a 20 s tree-line run).  Or within ``merge_m`` alone
   ``merge_close_frames`` frames in a row: two tracks that take one object's hits in turn drag each
   other's velocity about (two drones whose clusters merge as they cross part within a second).
   Over seeds +200..+229 of the four scenes, id switches 201 without the rule, 127 with it.

Ids are integers from 0 in the order tracks are created, never reused.  Everything is a function of
the frames and the pose: no random numbers, sums in a fixed order, a stable assignment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from collections.abc import Mapping

import numpy as np
from scipy.optimize import linear_sum_assignment

from foveatrack.config_util import dataclass_from_mapping
from foveatrack.detection import Detection, box_bounds, box_detection, frozen_maker
from foveatrack.errors import UserError
from foveatrack.fixed_order import dist3
from foveatrack.frames import Frame
from foveatrack.kernels import (association_kernel, box_inside_kernel, close_pairs_kernel, in_field_kernel,
                                valid_mask_kernel)
from foveatrack.openloop.objects import frame_objects
from foveatrack.reconstruction import head_trig, rotation_rows
from foveatrack.sky.classify import ClassifierConfig, classify_many, held_label
from foveatrack.sky.features import history_rows
from foveatrack.sky.motion import (ConstantVelocityFilter, positions_many, positions_velocities_many, predictions_many,
                                   variances_many)
from foveatrack.openloop.range_background import RangeBackground, check_cell_deg
from foveatrack.sky.world_points import lidar_to_world_in_box, lidar_to_world_per_point
from foveatrack.space_of_interest import Box

_BIG = 1e12

#: keys added to :class:`SkyTrackerConfig` since recordings began to keep the sky table, each with the
#: value that behaves as before it: a recording's table without one ran that way, and replays so
#: (:func:`foveatrack.sky.controller.recorded_sky_table`)
ADDED_SINCE_RECORDED = {"lone_returns": False}


@dataclass(frozen=True)
class SkyTrackerConfig:
    """Parameters of :class:`SkyTracker` (a scene's ``[sky]`` table; units in the names).

    cell_deg, background_frames, background_persist_frames, background_dilate,
    background_margin_m, background_spread_gain, background_margin_max_m
                                 the background's direction cells (:mod:`foveatrack.openloop.range_background`)
    warmup_s : >= 0 [s]          the background learns alone this long before tracks start
    warmup_replay : bool          the warm-up's frames are tracked when it ends (module docstring)
    warmup_stay_frames : int >= 0   what the warm-up saw is scenery at once only where it stayed: a cell
                                 within ``background_dilate`` steps returned at two times this many frames
                                 apart or more (0: all of it; :mod:`foveatrack.openloop.range_background`)
    cluster_tol_m, cluster_tol_rad                    cluster gap ``max(tol_m, tol_rad * range)``
    min_points : int >= 1        returns an object needs
    max_extent_m : > 0 [m]       largest side of an object (bigger: scenery, not tracked)
    q_m2_s3 : > 0                white-acceleration density of the filter (20: ~4.5 m/s^2 in 1 s)
    r_m2 : > 0                   variance of a cluster median per axis
    v0_sigma_m_s : > 0           velocity uncertainty of a new track
    gate_chi2 : > 0              largest squared Mahalanobis distance of an allowed pair
    gate_max_m : > 0 [m]         largest distance of an allowed pair from the prediction
    confirm_hits, confirm_window : ints    M hits of the first N frames
    lost_after_s : > 0 [s]       unseen this long in the field (summed): deleted
    lost_out_of_view_s : > 0 [s] unseen this long in all, in the field or out: deleted (below
                                 lost_after_s it decides alone)
    field_half_angle_deg : > 0 or None     the lidar's field around its axis (None: every track in view)
    static_window_s, static_radius_m       a confirmed track that stayed put this long is scenery
    d_half_m : > 0 [m]           half-size of the fixated track's D (Algorithm 1)
    protect_m : > 0 [m]          a confirmed track's object is kept out of the background only when
                                 it lies this close to the track's prediction (below)
    spawn_clear_m : >= 0 [m]     an unmatched object this close to a confirmed track's hit of the
                                 frame starts no track (0: every unmatched object starts one)
    history_s : > 0 [s]          how long a track keeps its measurements (the classifier's window)
    merge_m, merge_v_m_s, merge_frames   two confirmed tracks this close in position and velocity
                                 this many frames in a row are one object: the one with fewer hits
                                 in its history goes (merge_frames 0: never)
    merge_close_frames : int >= 0   ... or this close in position alone this many frames in a row (0:
                                 never; two tracks that take one object's hits in turn drag each
                                 other's velocity about)
    pose_nodes : int >= 2        head poses asked per frame for the per-point turn
    lone_returns : bool          tracks take single returns as hits (step 5b; default true; false:
                                 objects only, as a recording without the key ran)
    lone_gate_m : > 0 [m]        largest distance of a lone return from a track's prediction
    """

    cell_deg: float = 0.3
    background_frames: int = 3
    background_persist_frames: int = 8
    background_dilate: int = 3
    background_margin_m: float = 0.5
    background_spread_gain: float = 0.5
    background_margin_max_m: float = 1.5
    warmup_s: float = 1.0
    warmup_stay_frames: int = 5
    warmup_replay: bool = True
    cluster_tol_m: float = 0.5
    cluster_tol_rad: float = 0.01
    min_points: int = 2
    max_extent_m: float = 3.0
    q_m2_s3: float = 20.0
    r_m2: float = 0.04
    v0_sigma_m_s: float = 10.0
    gate_chi2: float = 16.27
    gate_max_m: float = 2.5
    confirm_hits: int = 3
    confirm_window: int = 15
    lost_after_s: float = 2.0
    lost_out_of_view_s: float = 5.0
    field_half_angle_deg: float | None = None
    static_window_s: float = 3.0
    static_radius_m: float = 1.5
    protect_excursion_m: float = 1.0
    spawn_clear_m: float = 1.0
    d_half_m: float = 1.0
    protect_m: float = 1.0
    history_s: float = 3.0
    merge_m: float = 0.6
    merge_v_m_s: float = 1.0
    merge_frames: int = 2
    merge_close_frames: int = 15
    pose_nodes: int = 11
    lone_returns: bool = True
    lone_gate_m: float = 1.0
    classifier: ClassifierConfig = field(default_factory=ClassifierConfig)

    def __post_init__(self) -> None:
        for k in ("cell_deg", "background_margin_m", "background_margin_max_m", "cluster_tol_m", "max_extent_m", "q_m2_s3", "r_m2", "v0_sigma_m_s", "gate_chi2",
                  "gate_max_m", "lost_after_s", "lost_out_of_view_s", "static_window_s", "static_radius_m",
                  "d_half_m", "protect_m", "history_s", "lone_gate_m"):
            if not getattr(self, k) > 0:
                raise UserError(f"{k} must be > 0, got {getattr(self, k)!r}")
        check_cell_deg(self.cell_deg)
        if self.field_half_angle_deg is not None and not 0 < self.field_half_angle_deg <= 180:
            raise UserError(f"field_half_angle_deg must be in (0, 180], got {self.field_half_angle_deg!r}")
        if not 0 <= self.background_dilate <= 3:
            raise UserError(f"background_dilate must be 0, 1, 2 or 3, got {self.background_dilate!r}")
        for k in ("warmup_s", "background_spread_gain", "background_persist_frames", "spawn_clear_m",
                  "warmup_stay_frames", "merge_m", "merge_v_m_s", "merge_frames", "merge_close_frames"):
            if not getattr(self, k) >= 0:
                raise UserError(f"{k} must be >= 0, got {getattr(self, k)!r}")
        for k in ("background_frames", "min_points", "confirm_hits"):
            if getattr(self, k) < 1:
                raise UserError(f"{k} must be >= 1, got {getattr(self, k)!r}")
        if self.pose_nodes < 2:
            raise UserError(f"pose_nodes must be >= 2, got {self.pose_nodes!r}")
        if self.confirm_window < self.confirm_hits:
            raise UserError("confirm_window must be >= confirm_hits")

    @classmethod
    def from_mapping(cls, data: Mapping, where: str) -> "SkyTrackerConfig":
        return dataclass_from_mapping(cls, data, where, parsers={"classifier": ClassifierConfig.from_mapping},
                                      none_ok=("field_half_angle_deg",))


@dataclass(frozen=True)
class SkyObject:
    """One cluster of a frame, in the world: median position [m] and time [s] of its points, their
    count, and the sides of their bounding box (x, y, z) [m]."""
    xyz_m: np.ndarray
    t_s: float
    n_points: int
    sides_m: np.ndarray
    on_scenery: bool = False

    @property
    def extent_m(self) -> float:
        return float(self.sides_m.max())


_make_object = frozen_maker(SkyObject)    # SkyObject(...) without the frozen init's cost per field, per object


def _add_row(tr: "SkyTrack", t_s: float, z, sides, n_points: int) -> None:
    """A hit's row after the track's rows (:class:`SkyTrack`'s ``rows``), as its history takes the
    hit; a full buffer's live rows move to a fresh one twice their number (32 at least)."""
    buf, end = tr.rows, tr.rows_end
    if buf is None or end == buf.shape[0]:
        lo = tr.rows_lo
        live = 0 if buf is None else end - lo
        new = np.empty((max(32, 2 * live), 8))
        if live:
            new[:live] = buf[lo:end]
        buf, end = new, live
        tr.rows, tr.rows_lo = new, 0
    row = buf[end]
    row[0] = t_s
    row[1] = n_points
    row[2:5] = z
    row[5:8] = sides
    tr.rows_end = end + 1


@dataclass
class SkyTrack:
    """A tentative or confirmed track.  ``history``: (t_s, xyz_m, sides_m, n_points) of its hits in
    the last ``history_s`` (the classifier reads it)."""
    track_id: int
    kf: ConstantVelocityFilter
    first_t_s: float
    last_hit_t_s: float
    frames_seen: int = 1
    hits: int = 1
    clear_hits: int = 0
    confirmed_t_s: float | None = None
    label: str = "unknown"
    seen_as: str = "unknown"        # what the classifier's rules 1-4 say this frame (label: after rule 5)
    drone_frames: int = 0           # frames in a row the rules said "drone" (> 0), or, labelled drone, otherwise (< 0)
    drone_hits: int = 0             # of those drone frames, how many brought a hit (classify rule 5)
    features: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    in_view: bool = True
    hit_now: bool = False
    lone_now: bool = False          # its hit this frame was a lone return (step 5b): it measured the position alone
    merged_t_s: float = -math.inf
    origin_xyz_m: np.ndarray | None = None
    excursion_m: float = 0.0
    last_xyz_m: np.ndarray | None = None
    last_seen_in_view: bool = True
    unseen_in_view_s: float = 0.0   # time since its last hit during which where it was last seen lay in the field
    reclassify: bool = True         # something rules 1-4 read has changed since they last ran (SkyTracker._classify)
    history_in_order: bool = True   # each hit's time >= the one before: the prune cuts a prefix (SkyTracker._prune)
    # the history's hits as rows (t_s, n_points, xyz_m, sides_m), rows[rows_lo:rows_end], each written
    # as its hit came (_add_row): the classifier's input without a list made into arrays each time it
    # runs (foveatrack.sky.features.kept_rows); rows_of: the history list they are of (another: not read)
    rows: np.ndarray | None = None
    rows_lo: int = 0
    rows_end: int = 0
    rows_of: list | None = None

    @property
    def confirmed(self) -> bool:
        return self.confirmed_t_s is not None

    @property
    def xyz_m(self) -> np.ndarray:
        return self.kf.p

    @property
    def velocity_m_s(self) -> np.ndarray:
        return self.kf.v


@dataclass(frozen=True)
class TrackView:
    """A track as a frame leaves it (a copy: the output does not change with later frames; its
    ``features`` are the track's dict of that frame, which the classifier replaces and nothing
    writes); its position is the filter's at the frame's mid time."""
    track_id: int
    confirmed: bool
    label: str
    xyz_m: np.ndarray
    velocity_m_s: np.ndarray
    hit: bool
    in_view: bool
    features: dict
    clear_hits: int = 0
    seen_as: str | None = None      # the classifier's rules 1-4 this frame, before rule 5's wait (None: the label)

    @property
    def looks_like(self) -> str:
        """What the fovea's schedule goes by: what the track looks like now, before the label waits
        (foveatrack.sky.classify rule 5: the fovea helps decide, so it looks at a possible drone)."""
        return self.label if self.seen_as is None else self.seen_as


_make_view = frozen_maker(TrackView)    # TrackView(...) without the frozen init's cost per field, per track


@dataclass(frozen=True)
class SkyFrameOutput:
    """One frame: every live track, the fixated track's Algorithm 1 detection (lidar frame) if it was
    asked for and seen, the counts, and the ids confirmed / deleted this frame."""
    t_s: float
    tracks: tuple[TrackView, ...]
    fovea_detection: Detection | None
    n_points: int
    n_foreground: int
    n_objects: int
    confirmed_now: tuple[int, ...]
    deleted_now: tuple[int, ...]


_make_output = frozen_maker(SkyFrameOutput)     # once a frame: without the frozen init's cost per field


class SkyTracker:
    """Frames of the moving head in, tracks of every moving object out (module docstring)."""

    def __init__(self, cfg: SkyTrackerConfig | None = None, region=None):
        """``region``: a world-frame space of interest (anything with ``contains(xyz)``, e.g. the
        scene's world box D that keeps the ground out); points outside it are not looked at."""
        self.cfg = cfg or SkyTrackerConfig()
        self.region = region
        c = self.cfg
        self.background = RangeBackground(c.cell_deg, c.background_frames, c.background_persist_frames,
                                          c.background_dilate, c.background_margin_m, c.background_spread_gain,
                                          c.background_margin_max_m)
        self._t0_s: float | None = None
        self._warmup_over = False
        self._warmup_kept: list[tuple] = []     # the warm-up's frames, tracked at its end (warmup_replay)
        self._shown: set[int] = set()           # the ids the last frame's output showed
        self.tracks: list[SkyTrack] = []
        self.confirmed_ever: list[int] = []
        self._next_id = 0
        self._together: dict[tuple[int, int], tuple[int, int]] = {}   # frames in a row two tracks were close, and with one velocity (merge_*)
        self._cos_field = None if c.field_half_angle_deg is None else math.cos(math.radians(c.field_half_angle_deg))

    def continue_ids_from(self, other: "SkyTracker") -> None:
        """New tracks' ids go on from ``other``'s (a fresh tracker that replaces it in the same run)."""
        self._next_id = max(self._next_id, other._next_id)

    # ------------------------------------------------------------------------------------------
    def process(self, frame: Frame, pose, fovea_track_id: int | None = None) -> SkyFrameOutput:
        """One frame.  ``pose``: the head's pose estimate (``angles_at(t_s)``, ``lidar_offset_m``: a
        :class:`~foveatrack.reconstruction.Reconstructor`).  ``fovea_track_id``: the track the fovea
        serves this frame, measured by Algorithm 1 in its D."""
        cfg = self.cfg
        t0, t1 = frame.t_start_s, frame.t_end_s
        xyz, t_ns = frame.xyz, frame.t_ns      # (N, 3) float64, C-contiguous (Frame)
        if type(self.region) is Box:
            # the valid points turned and cut to the region in one pass: the scenes' D keeps a tenth
            # of the points
            xyz, t_ns, world = lidar_to_world_in_box(xyz, t_ns, pose, t0, t1, cfg.pose_nodes,
                                                     *box_bounds(self.region))
        else:
            valid = np.empty(xyz.shape[0], np.bool_)
            if valid_mask_kernel(xyz, valid) < valid.size:
                xyz, t_ns = xyz[valid], t_ns[valid]
            world = lidar_to_world_per_point(xyz, t_ns, pose, t0, t1, cfg.pose_nodes)
            if self.region is not None and world.shape[0]:
                inside = np.flatnonzero(np.asarray(self.region.contains(world), bool))
                xyz, t_ns, world = xyz[inside], t_ns[inside], world[inside]
        cells, ranges = self.background.cells(world)
        if self._t0_s is None:
            self._t0_s = t0
        if t1 - self._t0_s <= cfg.warmup_s:
            # the background learns alone: it has not seen the scenery long enough to tell it from
            # what flies, and tracks started now would be the scenery's
            self.background.learn(cells, ranges)
            self.background.warmup_frames = self.background.frame_no
            if cfg.warmup_replay:
                self._warmup_kept.append((xyz, t_ns, world, cells, ranges, t0, t1))
            return _make_output(t1, (), None, frame.n_points, 0, 0, (), ())
        early_confirmed, early_deleted = [], []
        if not self._warmup_over:
            self.background.end_warmup(cfg.warmup_stay_frames)
            self._warmup_over = True
            # the warm-up's frames tracked now that the background knows what stayed: a drone in
            # the field at power-on has its hits from the first frame, not from the warm-up's end
            for kept in self._warmup_kept:
                c, d = self._track_frame(*kept, pose, None, learn=False)[2:4]
                early_confirmed += c
                early_deleted += d
            self._warmup_kept = []
        views, fovea_det, confirmed_now, deleted, n_fg, n_obj = self._track_frame(
            xyz, t_ns, world, cells, ranges, t0, t1, pose, fovea_track_id, learn=True)
        # a track is reported deleted only once a frame has shown it (one the warm-up's frames
        # started and ended was never shown: nothing was drawn of it)
        shown, self._shown = self._shown, {v.track_id for v in views}
        return _make_output(t1, views, fovea_det, frame.n_points, n_fg, n_obj,
                              tuple(i for i in early_confirmed if i in self._shown) + confirmed_now,
                              tuple(i for i in early_deleted + list(deleted) if i in shown))

    def _track_frame(self, xyz, t_ns, world, cells, ranges, t0, t1, pose, fovea_track_id, learn: bool):
        """Steps 2-6 of a frame after the warm-up (module docstring): ``(views, fovea detection,
        confirmed ids, deleted ids, foreground points, objects)``.  ``learn``: the frame's scenery
        goes into the background (not for the warm-up's frames, which it has learned already)."""
        cfg = self.cfg
        t_mid = 0.5 * (t0 + t1)
        is_bg, near = self.background.is_background(cells, ranges)
        fg_idx = np.flatnonzero(~is_bg)
        fg_world = world[fg_idx]
        objs, point_obj, lone = self._objects(fg_world, t_ns[fg_idx], near[fg_idx])
        pan, tilt, _, _ = pose.angles_at(t_mid)
        rows = rotation_rows(pan, tilt)
        off = np.asarray(pose.lidar_offset_m, np.float64).reshape(3)
        # every track's prediction at mid-frame, once: the field test, the association and the
        # fixated track's D all read it
        # (and their variances, with the positions from one gather, when there are objects to associate)
        kfs = [tr.kf for tr in self.tracks]
        pred_mid, var_mid = predictions_many(kfs, t_mid) if objs else (positions_many(kfs, t_mid), None)
        n = len(self.tracks)
        last = np.array([tr.last_xyz_m for tr in self.tracks]).reshape(n, 3)
        seen = self._in_view_many(np.concatenate((pred_mid, last)), rows, off)
        for tr, in_view, last_in_view in zip(self.tracks, seen[:n], seen[n:]):
            tr.frames_seen += 1
            tr.hit_now = tr.lone_now = False
            tr.in_view = in_view
            # lost while in view: where it was last seen is in the field now (a track that coasts out
            # of the field on its own velocity is not "out of view": the head did not look away)
            tr.last_seen_in_view = last_in_view
        match, allowed = self._associate(objs, t_mid, pred_mid, var_mid)
        obj_track = {j: i for i, j in match}
        # A confirmed track left without an object while an object matched to another track lies in
        # its gate has merged with it (two clusters became one): it coasts and is not lost meanwhile.
        if obj_track:
            matched = {i for i, _ in match}
            # the few tracks with an allowed pair among the matched objects, not a test of each track
            for i in set(np.nonzero(allowed[:, list(obj_track)])[0].tolist()):
                tr = self.tracks[i]
                if i not in matched and tr.confirmed_t_s is not None:
                    tr.merged_t_s = t_mid
        # Algorithm 1 for the fixated track: its D, without the points of other tracks' objects
        fovea_det = None
        fov = next((i for i, tr in enumerate(self.tracks) if tr.track_id == fovea_track_id), None)
        if fov is not None:
            tr = self.tracks[fov]
            others = np.zeros(len(objs) + 1, bool)      # by object index; the last, False, is -1: no object
            others[[j for j, i in obj_track.items() if i != fov]] = True
            keep = ~others[point_obj]
            sel = fg_idx[keep]
            c = pred_mid[fov]
            # D's bounds as box_bounds(Box(...)) has them (the same floats, read-only: the kernels'
            # one compiled signature, which compile_sky_kernels loads), without a Box a frame
            lo, hi = c - cfg.d_half_m, c + cfg.d_half_m
            lo.flags.writeable = hi.flags.writeable = False
            fovea_det = box_detection(np.ascontiguousarray(xyz[sel]), np.ascontiguousarray(t_ns[sel]),
                                      head_trig(pan, tilt), off, lo, hi)
        confirmed_now = []
        fixated_pts = None         # the foreground points in the fixated track's D, once asked for
        learn_pts = np.ones(fg_idx.size, bool)
        # the objects whose points are kept out of the learning, applied to learn_pts at once after
        # the loops (one pass over the foreground, not one per object); the last entry is -1: no object
        unlearn = np.zeros(len(objs) + 1, bool)
        if fov is not None and self._gone_somewhere(self.tracks[fov]):
            # the fixated track's D is the target's (Algorithm 1): a frame with a single return on a
            # hovering drone makes no object to protect, and a few such frames made it scenery
            fixated_pts = self._in_fixated_d(fg_world, lo, hi, keep)
            learn_pts[fixated_pts] = False
        for i, j in match:
            tr, ob = self.tracks[i], objs[j]
            z, tz = ob.xyz_m, ob.t_s
            if i == fov and fovea_det is not None:
                z = np.array(self._to_world(fovea_det.xyz, fovea_det.t_s, pose))
                tz = fovea_det.t_s
            protect = self._protects(tr, ob.t_s, ob.xyz_m, ob.on_scenery)
            self._hit(tr, tz, z, ob)
            self._confirm_if_due(tr, t_mid, confirmed_now)
            if protect:
                unlearn[j] = True
        if fov is not None and fovea_det is not None and not self.tracks[fov].hit_now:
            # seen by Algorithm 1 though no object matched (too few points for an object)
            self._measured(self.tracks[fov], fovea_det.t_s, self._to_world(fovea_det.xyz, fovea_det.t_s, pose))
        if lone is not None and lone.size and fovea_det is not None:
            # the returns Algorithm 1 took for the fixated track are its hit, not another track's
            # (by the world test of its D the learning uses)
            if fixated_pts is None:
                fixated_pts = self._in_fixated_d(fg_world, lo, hi, keep)
            taken = np.zeros(fg_idx.size, bool)
            taken[fixated_pts] = True
            lone = lone[~taken[lone]]
        if lone is not None and lone.size:
            self._lone_hits(fg_world, t_ns[fg_idx], lone, t_mid, pred_mid, var_mid, learn_pts, confirmed_now)
        hit_xyz = [self.tracks[i].last_xyz_m for i, _ in match if self.tracks[i].confirmed]
        for j, ob in enumerate(objs):
            if j not in obj_track and any(dist3(ob.xyz_m, p) < cfg.spawn_clear_m for p in hit_xyz):
                # a part of an object a confirmed track has just taken (the sparse scan split a drone
                # into two clusters): no new track, which would take the drone's hits in turn with
                # the old one; kept out of the background as the part that was taken
                unlearn[j] = True
                continue
            if j not in obj_track:
                tr = SkyTrack(self._next_id, ConstantVelocityFilter(ob.t_s, ob.xyz_m, cfg.q_m2_s3, cfg.r_m2,
                                                                    cfg.v0_sigma_m_s), ob.t_s, ob.t_s)
                tr.history.append((ob.t_s, ob.xyz_m, ob.sides_m, ob.n_points))
                tr.rows_of = tr.history
                _add_row(tr, ob.t_s, ob.xyz_m, ob.sides_m, ob.n_points)
                tr.origin_xyz_m = tr.last_xyz_m = np.asarray(ob.xyz_m, float)
                tr.hit_now = True
                tr.clear_hits = int(not ob.on_scenery)
                self._next_id += 1
                self._confirm_if_due(tr, t_mid, confirmed_now)      # confirm_hits 1: at once
                self.tracks.append(tr)
                if not ob.on_scenery:
                    unlearn[j] = True
        if learn:
            learn_pts &= ~unlearn[point_obj]
            keep = np.ones(cells.size, bool)
            keep[fg_idx[~learn_pts]] = False
            self.background.learn(cells[keep], ranges[keep])
        deleted, positions, velocities = self._prune(t_mid, fovea_track_id, t1 - t0)
        self._classify()
        # rule 5 and (after the warm-up's frames) the views in one pass over the tracks; each view
        # takes its track's features dict, not a copy (the classifier makes a new one each time,
        # nothing writes one): swarm + flock 0.23 -> 0.21 collections of the collector a frame
        views = []
        ccfg = cfg.classifier
        for tr, p, v in zip(self.tracks, positions, velocities):
            was = tr.label
            label, frames, hits = held_label(tr.seen_as, was, tr.drone_frames, tr.drone_hits,
                                             tr.hit_now and not tr.lone_now, ccfg, t_mid - tr.last_hit_t_s)
            tr.label, tr.drone_frames, tr.drone_hits = label, frames, hits
            if (label == "drone") != (was == "drone"):
                tr.reclassify = True        # rule 4 reads it
            if learn:
                views.append(_make_view(tr.track_id, tr.confirmed_t_s is not None, label, p, v,
                                        tr.hit_now, tr.in_view, tr.features, tr.clear_hits, tr.seen_as))
        if not learn:
            return (), None, tuple(confirmed_now), tuple(deleted), int(fg_idx.size), len(objs)
        views = tuple(views)
        return views, fovea_det, tuple(confirmed_now), tuple(deleted), int(fg_idx.size), len(objs)

    # ------------------------------------------------------------------------------------------
    @staticmethod
    def _to_world(xyz_lidar, t_s, pose) -> np.ndarray:
        p, t, _, _ = pose.angles_at(t_s)
        q = np.asarray(xyz_lidar, np.float64).reshape(3) + np.asarray(pose.lidar_offset_m, np.float64).reshape(3)
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_rows(p, t)
        x, y, z = q.tolist()
        return np.array([r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z])

    def _in_view_many(self, p_world: np.ndarray, rows, offset: np.ndarray) -> list[bool]:
        """Per world point of ``p_world`` (N, 3): is it inside the lidar's field at the frame's mid pose?"""
        if self._cos_field is None:
            return [True] * p_world.shape[0]
        # R.T p - offset (mat3T_vec's products and sums, in its order: the bits of the scalar form),
        # one kernel call for every track's two points of a frame (a dozen numpy calls before)
        out = np.empty(p_world.shape[0], np.bool_)
        in_field_kernel(np.ascontiguousarray(p_world, np.float64), np.array(rows[0] + rows[1] + rows[2], np.float64),
                        np.ascontiguousarray(offset, np.float64).reshape(3), self._cos_field, out)
        return out.tolist()

    def _objects(self, world: np.ndarray, t_ns: np.ndarray, near: np.ndarray
                 ) -> tuple[list[SkyObject], np.ndarray, np.ndarray | None]:
        """The frame's objects, per foreground point the index of its object (-1: none), and (with
        ``lone_returns``) the indices of the foreground points that are lone returns off the scenery:
        clusters of one return, not next to scenery in the making (None: not looked for)."""
        cfg = self.cfg
        if world.shape[0] == 0:
            return [], np.full(0, -1, np.int64), None
        # the kept clusters' summaries as arrays (objects_from_labels' objects, without a FrameObject
        # each), each point's object, each object's points on scenery in the making, and the lone
        # returns (not an object's -- min_points 1 makes one of a single return: a return is one
        # track's hit), in one kernel call
        meds, boxes, counts, t_med, point_obj, near_n, lone = frame_objects(
            world, t_ns, cfg.cluster_tol_m, cfg.cluster_tol_rad, cfg.min_points, cfg.max_extent_m, near,
            cfg.lone_returns)
        objs = [_make_object(m, t * 1e-9, n_pts, box, 2 * k >= n_pts)
                for m, t, n_pts, box, k in zip(meds, t_med.tolist(), counts.tolist(), boxes, near_n.tolist())]
        return objs, point_obj, lone

    def _confirm_if_due(self, tr: SkyTrack, t_mid: float, confirmed_now: list) -> None:
        """A tentative track with ``confirm_hits`` hits off the scenery in its first ``confirm_window``
        frames is confirmed now."""
        cfg = self.cfg
        if not tr.confirmed and tr.clear_hits >= cfg.confirm_hits and tr.frames_seen <= cfg.confirm_window:
            tr.confirmed_t_s = t_mid
            self.confirmed_ever.append(tr.track_id)
            confirmed_now.append(tr.track_id)

    def _lone_hits(self, fg_world: np.ndarray, fg_t_ns: np.ndarray, lone: np.ndarray, t_mid: float,
                   pred_mid: np.ndarray, var_mid: np.ndarray | None, learn_pts: np.ndarray,
                   confirmed_now: list) -> None:
        """Step 5b: the tracks no object measured this frame take the frame's lone returns off the
        scenery (``lone``: indices into the foreground), by the same gated global nearest neighbour
        as the objects: a return updates the track's filter and counts as a hit toward confirmation,
        but starts no track and is not a shape the classifier reads (its history is the objects')."""
        cfg = self.cfg
        idle = [i for i, tr in enumerate(self.tracks) if not tr.hit_now]
        if not idle:
            return
        P = np.ascontiguousarray(pred_mid[idle], np.float64)
        # the frame's variances where the association made them (the same bits, row by row)
        V = variances_many([self.tracks[i].kf for i in idle], t_mid) if var_mid is None else var_mid[idle]
        O = np.ascontiguousarray(fg_world[lone], np.float64)
        c = np.empty((len(idle), lone.size))
        allowed = np.empty(c.shape, np.bool_)
        none = np.zeros(len(idle), np.bool_)
        if not association_kernel(P, V, O, float(cfg.r_m2), float(cfg.gate_chi2), float(cfg.lone_gate_m * cfg.lone_gate_m),
                                  none, np.zeros(lone.size, np.bool_), _BIG, c, allowed):
            return
        rows, cols = linear_sum_assignment(c)
        for a, b in zip(rows.tolist(), cols.tolist()):
            if not allowed[a, b]:
                continue
            tr = self.tracks[idle[a]]
            z = O[b].copy()
            t_s = int(fg_t_ns[lone[b]]) * 1e-9
            protect = self._protects(tr, t_s, z, False)       # as an object's, at its time (off the scenery)
            self._measured(tr, t_s, z)
            tr.hits += 1
            tr.clear_hits += 1
            tr.lone_now = True
            self._confirm_if_due(tr, t_mid, confirmed_now)
            if protect:
                learn_pts[lone[b]] = False

    def _associate(self, objs: list[SkyObject], t_s: float, positions: np.ndarray,
                   variances: np.ndarray | None = None) -> tuple[list[tuple[int, int]], np.ndarray]:
        """Gated global nearest neighbour (module docstring): ``(track index, object index)`` pairs, and
        the allowed pairs (tracks x objects).  ``positions``: the tracks' predicted positions at
        ``t_s`` (:func:`positions_many`, made once a frame by the caller); ``variances``: theirs
        (:func:`predictions_many` with the positions; None: made here)."""
        cfg = self.cfg
        if not self.tracks or not objs:
            return [], np.zeros((len(self.tracks), len(objs)), bool)
        V = variances_many([tr.kf for tr in self.tracks], t_s) if variances is None else variances
        O = np.array([ob.xyz_m for ob in objs], np.float64).reshape(len(objs), 3)
        # a candidate (not confirmed) seen off the scenery takes no object on it (module docstring, step 4)
        candidate = np.array([tr.confirmed_t_s is None and tr.clear_hits > 0 for tr in self.tracks])
        on_scenery = np.array([ob.on_scenery for ob in objs])
        c = np.empty((len(self.tracks), len(objs)))
        allowed = np.empty(c.shape, np.bool_)
        if not association_kernel(np.ascontiguousarray(positions, np.float64), V, O, float(cfg.r_m2),
                                  float(cfg.gate_chi2), float(cfg.gate_max_m * cfg.gate_max_m), candidate, on_scenery,
                                  _BIG, c, allowed):
            return [], allowed
        rows, cols = linear_sum_assignment(c)
        # the assigned pairs' allowances read at once (a numpy scalar index per pair cost more)
        ok = allowed[rows, cols].tolist()
        return [(i, j) for i, j, yes in zip(rows.tolist(), cols.tolist(), ok) if yes], allowed

    def _classify(self) -> None:
        """Rules 1-4 of the classifier on the tracks, except those where nothing they read has changed
        since they last ran (most tracks get no hit in a frame): what they read is its history, its filter's
        velocity, its excursion, its last hit's time, its count of hits (rule 1's early bird) and
        whether it is labelled drone (rule 4 keeps the label), and what changes one of them sets ``tr.reclassify`` (:meth:`_measured`, the
        prune's cut of the history, the label's change to or from drone).  A flag, not a key of
        what was read compared every frame: the key cost ~1 us a track, a flock's twenty a frame.
        The due tracks' windows in one kernel call (:func:`classify_many`)."""
        due = [tr for tr in self.tracks if tr.reclassify]
        if due:
            # a new features dict each time (the frame's views hold the ones before: never written)
            for tr, (seen, f) in zip(due, classify_many(due, self.cfg.classifier)):
                tr.seen_as, tr.features = seen, f
                tr.reclassify = False

    def _protects(self, tr: SkyTrack, t_s: float, z, on_scenery: bool) -> bool:
        """Whether a hit at ``z`` (at ``t_s``; ``on_scenery``: on scenery in the making) is kept out of
        the background: while it is where the track predicted it (``protect_m``) and the track may be
        something flying -- a tentative track off the scenery, or :meth:`_gone_somewhere`.  A confirmed
        track that stays put (a crown's part the background has not learned yet) protects nothing:
        its points are learned and it starves."""
        return tr.kf.distance_at(t_s, z) <= self.cfg.protect_m and (
            (not tr.confirmed and not on_scenery) or self._gone_somewhere(tr))

    def _gone_somewhere(self, tr: SkyTrack) -> bool:
        """A confirmed track that has gone ``protect_excursion_m`` or more from where it began: its
        hits, and the fixated D's points when the fovea serves it, stay out of the background."""
        return tr.confirmed and tr.excursion_m >= self.cfg.protect_excursion_m

    @staticmethod
    def _in_fixated_d(fg_world: np.ndarray, lo, hi, keep: np.ndarray) -> np.ndarray:
        """Indices of the foreground points inside the fixated track's D (bounds ``lo``, ``hi``) that
        are not other tracks' objects' (``keep``): D's world test by the region's kernel,
        Box.contains' twin (one call, not a dozen numpy ones)."""
        inside = np.empty(fg_world.shape[0], np.int64)
        inside = inside[:box_inside_kernel(fg_world, lo, hi, inside)]
        return inside[keep[inside]]

    @staticmethod
    def _measured(tr: SkyTrack, t_s: float, z) -> None:
        """What every kind of hit does to a track: its filter takes ``z`` at ``t_s``, and its last hit,
        last position and excursion follow (an object's :meth:`_hit`, Algorithm 1's in the fixated D
        without one, a lone return's)."""
        tr.kf.update(t_s, z)
        tr.last_hit_t_s, tr.hit_now, tr.last_xyz_m = t_s, True, z
        tr.excursion_m = max(tr.excursion_m, dist3(z, tr.origin_xyz_m))
        tr.reclassify = True        # (an object's hit adds to the history too)

    def _hit(self, tr: SkyTrack, t_s: float, z: np.ndarray, ob: SkyObject) -> None:
        """An object's hit: :meth:`_measured`, counted, and its shape into the classifier's history."""
        z = np.asarray(z, float)
        self._measured(tr, t_s, z)
        tr.hits += 1
        tr.clear_hits += not ob.on_scenery
        h = tr.history
        if h and not t_s >= h[-1][0]:
            tr.history_in_order = False
        if tr.rows_of is h:
            _add_row(tr, t_s, z, ob.sides_m, ob.n_points)
        h.append((t_s, z, ob.sides_m, ob.n_points))

    def _prune(self, t_s: float, fovea_track_id: int | None, frame_s: float
               ) -> tuple[list[int], np.ndarray, np.ndarray]:
        """Drop failed candidates, tracks lost too long and static scenery; returns their ids, and the
        positions (N, 3) at ``t_s`` and velocities (N, 3) of the tracks left (rows of fresh arrays,
        :func:`positions_velocities_many`).  ``frame_s``: the frame's length, added to the unseen time
        in the field of each track not seen in it."""
        cfg = self.cfg
        keep, gone = [], []
        oldest = t_s - cfg.history_s
        # (the settings read once, not once a track)
        lost_after, lost_out, window, need = cfg.lost_after_s, cfg.lost_out_of_view_s, cfg.confirm_window, cfg.confirm_hits
        static_s, static_m = cfg.static_window_s, cfg.static_radius_m
        for tr in self.tracks:
            h = tr.history
            if h and tr.history_in_order:
                # the hits older than the window are a prefix: cut if there is one (most frames none)
                if not h[0][0] >= oldest:
                    k = 1
                    while k < len(h) and not h[k][0] >= oldest:
                        k += 1
                    tr.history = h[k:]
                    tr.reclassify = True
                    if tr.rows_of is h:         # the rows' prefix so
                        tr.rows_lo += k
                        tr.rows_of = tr.history
            elif h:
                tr.history = [x for x in h if x[0] >= oldest]
                if len(tr.history) < len(h):
                    tr.reclassify = True
                    if tr.rows_of is h:         # (rare: a hit older than the one before) made afresh
                        R = history_rows(tr.history)
                        tr.rows, tr.rows_lo, tr.rows_end = R, 0, R.shape[0]
                if tr.rows_of is h:
                    tr.rows_of = tr.history
            last, merged = tr.last_hit_t_s, tr.merged_t_s
            unseen = t_s - (merged if merged > last else last)      # (max(last, merged), as max picks)
            if tr.hit_now or merged == t_s:
                tr.unseen_in_view_s = 0.0
            elif tr.last_seen_in_view:
                tr.unseen_in_view_s += frame_s
            # the track the fovea is turning to is not given up while the head gets there: the
            # attention gives the turn saccade_timeout_s, and a revisit comes when a track at the
            # sparse rim may have gone unseen for lost_after_s
            in_view = tr.last_seen_in_view and tr.track_id != fovea_track_id
            lost = (in_view and tr.unseen_in_view_s > lost_after) or unseen > lost_out
            confirmed = tr.confirmed_t_s is not None        # (SkyTrack.confirmed, read once here)
            failed = not confirmed and tr.frames_seen >= window and tr.clear_hits < need
            if lost or failed:
                gone.append(tr.track_id)
            elif confirmed and tr.history and t_s - tr.first_t_s >= static_s and tr.excursion_m < static_m:
                # scenery: in static_window_s of life it never got static_radius_m from where it was
                # first seen (a crown sways around its place; a drone on its way leaves it).  (A
                # track without a hit in its history window is not seen standing anywhere: the lost
                # rule decides; its D would be the median of nothing)
                c = np.median(np.array([h[1] for h in tr.history]), axis=0)
                self.background.mark_box(c - cfg.d_half_m, c + cfg.d_half_m)
                gone.append(tr.track_id)
            else:
                keep.append(tr)
        # the positions once, for the merge rule and the frame's views (and the views' velocities)
        positions, velocities = positions_velocities_many([tr.kf for tr in keep], t_s)
        away = self._merged_away(keep, t_s, positions)
        gone += away
        if away:
            stay = [i for i, tr in enumerate(keep) if tr.track_id not in away]
            keep, positions, velocities = [keep[i] for i in stay], positions[stay], velocities[stay]
        self.tracks = keep
        return gone, positions, velocities

    def _merged_away(self, tracks: list[SkyTrack], t_s: float, positions: np.ndarray) -> list[int]:
        """Ids of confirmed tracks that have been one object with another for ``merge_frames``
        frames in a row (within ``merge_m`` and ``merge_v_m_s``), or ``merge_close_frames`` (within
        ``merge_m``): of each such pair the one with fewer hits in its history goes (a tie: the
        younger), in the order found.  A crown part or a split cluster can start a second track
        on a drone; the two then take its hits in turn and every turn is an id switch.  ``positions``:
        the tracks' at ``t_s`` (:func:`positions_many`)."""
        cfg = self.cfg
        if cfg.merge_frames <= 0 and cfg.merge_close_frames <= 0:
            return []
        idx = [i for i, tr in enumerate(tracks) if tr.confirmed_t_s is not None]     # (SkyTrack.confirmed)
        conf = [tracks[i] for i in idx]
        together, away = {}, []
        if len(conf) < 2:
            self._together = {}
            return away
        # every pair's distance in one call (|d| as norm3 sums it): a flock's twenty confirmed tracks
        # are 190 pairs a frame; few are close.  Each pair once, a < b, in row-major order
        pairs = np.empty((len(conf) * (len(conf) - 1) // 2, 2), np.int64)
        n_close = close_pairs_kernel(positions[idx], float(cfg.merge_m), pairs)
        for a, b in pairs[:n_close].tolist():
            ta, tb = conf[a], conf[b]
            if ta.track_id in away or tb.track_id in away:
                continue
            key = (ta.track_id, tb.track_id)
            close, same = self._together.get(key, (0, 0))
            same = same + 1 if dist3(ta.kf.v, tb.kf.v) <= cfg.merge_v_m_s else 0
            together[key] = (close + 1, same)
            if 0 < cfg.merge_frames <= same or 0 < cfg.merge_close_frames <= close + 1:
                weaker = tb if (len(tb.history), -tb.track_id) <= (len(ta.history), -ta.track_id) else ta
                away.append(weaker.track_id)
        self._together = {k: n for k, n in together.items() if k[0] not in away and k[1] not in away}
        return away
