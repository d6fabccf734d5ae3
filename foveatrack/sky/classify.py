"""Drone, bird or clutter, from what the lidar measures of a track over its last ``history_s``.

Features (each from the track's hits in the window; sums exactly rounded, as ``math.fsum`` sums: the
same bits everywhere):

``hits``            measurements in the window
``size_m``          median of the largest side of the object's bounding box
``speed_m_s``       the filter's speed
``net_speed_m_s``   straight-line distance from the first to the last position over the time between
                    (a tree crown swaying in the wind goes back and forth: near 0)
``manoeuvre_m_s2``  change of the least-squares velocity between the window's first and second half,
                    per second (a bird weaves, a drone on a mission flies straight or turns slowly)
``flap_cv``         coefficient of variation (std / mean) of the box's vertical side: a flapping
                    bird's wings sweep up and down (sim: 40 deg amplitude), a drone's rotor disc
                    does not
``flap_period_s``   the apparent period of the vertical side: the lag of the first autocorrelation
                    peak above 0.5, if the window holds two periods (None otherwise).  Wingbeats of
                    4-14 Hz are faster than the 10 Hz frames: this is the aliased period, periodic
                    only while the bird flaps steadily; it counts as flapping evidence when found.

``excursion_m``     farthest the track has been from where it was first seen, ``age_s`` its age
``median_points``   median returns of its objects in the window (how well the lidar resolves it)

Rules, in order (thresholds in :class:`ClassifierConfig`; documented in docs/sky-tracks.md):

1. fewer than ``min_hits`` hits: ``unknown`` -- unless the track has had ``bird_speed_after_hits``
   (3, as many as confirm a track) hits since it began (``track.hits``: its objects and its lone
   returns, :mod:`foveatrack.sky.tracks` step 5b; not Algorithm 1's in the fixated D, which are not
   counted) and its filter's speed is at least ``bird_speed_m_s``:
   ``bird`` (rule 3's speed test, which reads no shape).  With lone returns a bird's track is
   confirmed on single returns before its window holds five objects; unknown, it weighed ten times a
   bird in the fovea's schedule, and the flock's drone lost the fovea to such tracks, coasting ones
   too.  Chosen with lone returns on; seeds +200..+229 / +230..+259 / +0..+7 of the flock, runs with
   every revisit within 3 s: without the rule (and before the attention summed a priority's unseen
   time) 16 / 15 / -, at 5 hits 20 / 20 / 4, at 3 hits
   26 / 27 / 8 (objects only, no lone returns: 26 / 24 / 5), id switches at 5 hits 20 / 22 / 8, at 3
   hits 5 / 11 / 3 (objects only 10 / 18 / 4); the tree line's runs 14 / 17 / 5 -> 19 / 19 / 5; the
   crossing and the swarm within 2 drones confirmed or runs.  Filter speeds from three hits are
   rough, but the scenes' drones fly at 0.5-2.6 m/s: of the tracks on the flock's drones, 5 and 9
   ended labelled bird on the two blocks (second tracks on a drone; each drone kept a drone track).
   The hits are the track's life's, not its window's, so an old track whose window has thinned is
   read so too: a track that drifted off its drone (a reviewer's runs: five in four 20 s runs of the
   swarm with the flock, 1.4-5.7 m from the nearest drone, their filters at 4.8-8.1 m/s) is called a
   bird, where unknown the schedule would have kept its last label, drone.  0: never (recordings
   made before it);
2. ``net_speed_m_s < clutter_net_speed_m_s``, or older than ``clutter_age_s`` and never farther than
   ``clutter_excursion_m`` from where it started: ``clutter`` (a swaying crown goes back and forth
   around its place; a drone hovering from the start is called clutter too -- a hover is found by
   the operator, not by this rule) -- unless the track is labelled drone (``drone_stays_when_still``,
   default true): a drone that flew in and stopped to hover lost its label to this rule, scored 0
   and lost the fovea (a user-level audit: labelled clutter in 193 of 240 frames; now drone in 203,
   the rest unknown and bird as before).  On seeds +200..+229 of the four sky scenes it changed one
   figure: the swarm's second tracks on a drone labelled drone 3 -> 4.  False: the rule before
   (recordings made before it);
3. ``manoeuvre_m_s2 >= bird_manoeuvre_m_s2`` or ``speed_m_s >= bird_speed_m_s``, or -- only where
   the fovea resolves the object (``median_points >= flap_min_points``) -- ``flap_cv >= bird_flap_cv``
   or a ``flap_period_s`` found: ``bird``;
4. ``size_m >= clutter_size_m`` and ``manoeuvre_m_s2 >= clutter_turn_1_s * net_speed_m_s``:
   ``clutter``; otherwise ``drone``.  A crown's part before the background has learned it (the
   first seconds after power-on) is a patch of the crown, tenths of a metre to a metre across,
   whose centroid swings one way and back: its velocity turns over about as fast as it goes.  A
   drone is as small as its span and flies on.  Where a track was first labelled drone (before this
   rule; seeds +200..+259 of the tree line, +200..+229 of the three others), the crowns' parts
   measured 0.28-0.89 m (5th-95th percentile) and turned at up to 2.4 /s, the drones 0.1-0.33 m
   and 0-0.74 /s; 30 of 43 crown parts and 3 of 274 drones were both.  It comes after the bird rule,
   so a large bird that weaves stays a bird.  The scenes' drones span 0.35-0.5 m: a larger one
   (0.9 m) that turns before it is labelled drone is called clutter while it turns.  The rule
   keeps a track from the drone label; it does not take the label back from a track that has it (a
   drone's world track swings too when the head's pose estimate errs in a turn, and a drone called
   clutter loses the fovea).  ``clutter_turn_1_s = 0`` turns the rule off (docs/sky-tracks-figures.md
   gives what it changed);
5. held (:func:`held_label`): a track is labelled ``drone`` only once rules 1-4 have said so in
   ``drone_after_frames`` frames in a row and ``drone_after_hits`` of the frames of that run (not a
   window: the run may be longer) measured the track -- an object matched to it, or Algorithm 1 in
   its D while it was fixated; until then it keeps the label it had.  A crown part that swings one
   way for a moment looks like a slow straight drone to rules 2-4; a drone keeps looking like one.
   The measurements count because rules 1-4 read only what was measured: a track that got its five
   hits and then coasted unseen for the rest of the frames had given one verdict, repeated.
   Without them (``drone_after_hits = 0``, the rule before 2026-12-07) most of the false drone tracks
   on crowns were labelled that way in the first seconds after power-on: on the tree line's seeds
   +200..+259, the eleven crown parts first labelled drone had 0.37-1.79 s of hits, seven under
   0.9 s; the 59 drones 0.9 s or more.  docs/sky-tracks-figures.md gives what the count changed.
   The label is given in a frame that measured the track (``drone_label_on_hit``, default true;
   false: the rule before 2026-12-07 evening): a run that becomes ready while the track coasts
   unseen repeats the verdict of its last hit, and waits for the next.  Traced on the tree line's
   cold hour, seed 39 (+9): a crown part's track, its first hit 1.6 m below the others (so a net
   speed of 0.9-1.4 m/s), was labelled drone at 3.9 s, 0.4 s after its last hit, and never seen
   again.  Over the cold hours (+0..+179) of the four scenes it removed that track and changed
   little else; on +200..+289 it changed no figure of three scenes (docs/sky-tracks-figures.md).
   Leaving
   the label takes another verdict: unknown (fewer than ``min_hits`` hits in the window, what a
   track gets out of the fovea at the sparse rim) is no news and keeps it while the track had a hit
   of any kind (lone returns too) in the last ``drone_through_unknown_s`` (default 1 s; 0: the rule
   before, which recordings made before it replay with), as the attention's ``keep_verdict`` already
   did for the schedule.  Without it the daemon's status line flipped between drone and unknown, and
   the confusion matrices put half the drones' tracks under unknown.  Seeds +200..+229 of the four
   scenes, 0 -> 1 s: the crossing's drone tracks ending labelled drone 31 -> 38 of 60, the swarm's
   79 -> 94 of 172 (most of the rest end coasting, as a track does before it is deleted); the
   swarm's median longest revisit gap 5.2 -> 4.9 s and id switches 34 -> 35; every other figure the
   same.  Kept through a whole coast (no time limit) the crossing's ended drone 60 of 60, but the
   swarm's ghost tracks labelled drone (coasting off their drone) went 4 -> 7.  Leaving
   on another verdict is at once unless ``drone_leave_frames`` > 1 (it then waits that many frames of other
   output in a row): a measured trade-off, not the default.  At 5 the daemon's status
   line no longer flickers between drone and unknown, but a second track on a drone keeps the drone
   label longer: seeds +200..+229 of the four scenes, false drone tracks near a drone 4 -> 19
   (flock) and 7 -> 18 (swarm), everything else the same.

The thresholds were chosen on seeds +8 and +9 of the four sky scenes (two-drones-crossing,
drone-tree-line, swarm-of-five, drone-and-flock: the confirmed tracks' features, each labelled by the
nearest truth object), between the classes' 5th and 95th percentiles: drones 0.5-2.6 m/s and
0.02-1.8 m/s^2, birds 6.8-14 m/s and 2.6-10 m/s^2, crowns' net speed about 0.4 m/s.  The figures in
docs/sky-tracks-figures.md are measured on seeds +0 to +7, which were not used.  ``flap_cv`` of a
sparse cluster does not tell a flapping wing (drones 0.32-0.99, birds 0.42-0.82 there): it counts
only where the object is resolved.

The features are computed in :mod:`foveatrack.sky.features`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from collections.abc import Mapping

from foveatrack.config_util import as_float, check_keys
from foveatrack.errors import UserError
from foveatrack.sky.features import window_features_many

LABELS = ("unknown", "clutter", "bird", "drone")

#: keys added to :class:`ClassifierConfig` since recordings began to keep the sky table, each with the
#: value that behaves as before it: a recording's table without one ran that way, and replays so
#: (:func:`foveatrack.sky.controller.recorded_sky_table`)
ADDED_SINCE_RECORDED = {"drone_after_hits": 0, "bird_speed_after_hits": 0, "drone_label_on_hit": False,
                        "drone_stays_when_still": False, "drone_through_unknown_s": 0.0}


@dataclass(frozen=True)
class ClassifierConfig:
    """Thresholds of :func:`classify` (a ``[sky.classifier]`` table)."""
    min_hits: int = 5
    clutter_net_speed_m_s: float = 0.6
    clutter_age_s: float = 3.0
    clutter_excursion_m: float = 1.5
    clutter_size_m: float = 0.3
    clutter_turn_1_s: float = 0.5
    bird_flap_cv: float = 0.35
    flap_min_points: float = 20.0
    bird_manoeuvre_m_s2: float = 2.2
    bird_speed_m_s: float = 4.5
    min_flap_period_s: float = 0.2
    flap_autocorr: float = 0.5
    drone_after_frames: int = 10
    drone_after_hits: int = 5
    drone_leave_frames: int = 1
    bird_speed_after_hits: int = 3
    drone_label_on_hit: bool = True
    drone_stays_when_still: bool = True
    drone_through_unknown_s: float = 1.0

    def __post_init__(self) -> None:
        # rules 2-4 read a net speed and a velocity, which take two hits (a table's types are checked
        # by from_mapping; this holds for a configuration built in code too)
        if not self.min_hits >= 2:
            raise UserError(f"min_hits must be an integer >= 2, got {self.min_hits!r}")
        for k in ("drone_after_frames", "drone_leave_frames"):
            if not getattr(self, k) >= 1:
                raise UserError(f"{k} must be an integer >= 1, got {getattr(self, k)!r}")
        for k in ("drone_after_hits", "bird_speed_after_hits"):
            if not getattr(self, k) >= 0:
                raise UserError(f"{k} must be an integer >= 0, got {getattr(self, k)!r}")
        if not 0.0 < self.flap_autocorr <= 1.0:     # a normalised autocorrelation never exceeds 1
            raise UserError(f"flap_autocorr must be in (0, 1], got {self.flap_autocorr!r}")

    @classmethod
    def from_mapping(cls, data: Mapping, where: str) -> "ClassifierConfig":
        check_keys(data, [f.name for f in fields(cls)], where)
        kw = {}
        for k, v in data.items():
            if k in ("min_hits", "drone_after_frames", "drone_after_hits", "drone_leave_frames", "bird_speed_after_hits"):
                least = {"min_hits": 2, "drone_after_hits": 0, "bird_speed_after_hits": 0}.get(k, 1)
                if isinstance(v, bool) or not isinstance(v, int) or v < least:
                    raise UserError(f"{where}: {k} must be an integer >= {least}, got {v!r}")
                kw[k] = v
            elif k in ("drone_label_on_hit", "drone_stays_when_still"):
                if not isinstance(v, bool):
                    raise UserError(f"{where}: {k} must be true or false, got {v!r}")
                kw[k] = v
            else:
                kw[k] = as_float(v, k, where, lo=0)
        return cls(**kw)


def classify(track, cfg: ClassifierConfig) -> tuple[str, dict]:
    """``(label, features)`` of a track (module docstring): :func:`classify_many` of the one track."""
    return classify_many([track], cfg)[0]


def classify_many(tracks, cfg: ClassifierConfig) -> list[tuple[str, dict]]:
    """:func:`classify` of each of ``tracks`` (the same labels and features), their windows'
    features in one kernel call (:func:`foveatrack.sky.features.window_features_many`)."""
    enough = [len(tr.history) >= cfg.min_hits for tr in tracks]
    fs = window_features_many(tracks, enough, (cfg.min_flap_period_s, cfg.flap_autocorr))
    return [_rules(tr, f, e, cfg) for tr, f, e in zip(tracks, fs, enough)]


def _rules(track, f: dict, enough: bool, cfg: ClassifierConfig) -> tuple[str, dict]:
    """Rules 1-4 on the track's features ``f`` (``enough``: its window holds ``min_hits``)."""
    if not enough:
        n = cfg.bird_speed_after_hits
        if n and track.hits >= n and f["speed_m_s"] >= cfg.bird_speed_m_s:
            return "bird", f
        return "unknown", f
    if (f["net_speed_m_s"] < cfg.clutter_net_speed_m_s or (
            f["age_s"] >= cfg.clutter_age_s and f["excursion_m"] < cfg.clutter_excursion_m)) and not (
            cfg.drone_stays_when_still and getattr(track, "label", "unknown") == "drone"):
        return "clutter", f
    resolved = f["median_points"] >= cfg.flap_min_points
    if (f.get("manoeuvre_m_s2", 0.0) >= cfg.bird_manoeuvre_m_s2 or f["speed_m_s"] >= cfg.bird_speed_m_s
            or (resolved and (f["flap_cv"] >= cfg.bird_flap_cv or f["flap_period_s"] is not None))):
        return "bird", f
    if (cfg.clutter_turn_1_s > 0 and getattr(track, "label", "unknown") != "drone"
            and f.get("size_m", 0.0) >= cfg.clutter_size_m
            and f.get("manoeuvre_m_s2", 0.0) >= cfg.clutter_turn_1_s * f["net_speed_m_s"]):
        return "clutter", f
    return "drone", f


def held_label(rules_label: str, previous: str, drone_frames: int, drone_hits: int, hit: bool,
               cfg: ClassifierConfig, unseen_s: float = 0.0) -> tuple[str, int, int]:
    """Rule 5: ``(label, drone_frames, drone_hits)`` of a track after this frame, given what rules 1-4
    say now (``rules_label``), the label it showed (``previous``), ``drone_frames``: in how many frames
    in a row before this one they had said ``drone`` (> 0), or, for a track labelled drone, in how many
    they had said otherwise (< 0; it keeps the label until ``drone_leave_frames`` have), and
    ``drone_hits``: how many of those drone frames measured the track (``hit``: this one did; an
    object matched to it, or Algorithm 1 in its D while fixated).  With ``drone_label_on_hit`` the
    label is given only in a frame with ``hit``; leaving it needs none.  ``unseen_s``: time since the
    track's last hit of any kind (a lone return's too), for ``drone_through_unknown_s``."""
    if rules_label == "drone":
        drone_frames = max(drone_frames, 0) + 1
        drone_hits += hit
        ready = (drone_frames >= cfg.drone_after_frames and drone_hits >= cfg.drone_after_hits
                 and (hit or not cfg.drone_label_on_hit))
        return ("drone" if ready else previous), drone_frames, drone_hits
    if previous == "drone":
        if rules_label == "unknown" and unseen_s < cfg.drone_through_unknown_s:
            # too few hits in the window (out of the fovea, at the sparse rim) is no news, not a
            # verdict: the label stays while the track is still hit (lone returns count), as the
            # attention's keep_verdict keeps it; a track that coasts unseen longer loses it (kept
            # through a coast, the swarm's ghost tracks labelled drone doubled)
            return "drone", drone_frames, drone_hits
        away = 1 - min(drone_frames, 0)
        if away < cfg.drone_leave_frames:
            return "drone", -away, 0
    return rules_label, 0, 0
