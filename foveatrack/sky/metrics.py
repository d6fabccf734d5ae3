"""The figures the field judges a multi-object tracker by (issue 28), from the tracks a run output
and the truth of the drones.

GOSPA (A. S. Rahmathullah, A. F. Garcia-Fernandez, L. Svensson, "Generalized optimal sub-pattern
assignment metric", FUSION 2017, arXiv:1601.05585), with ``alpha = 2``, cut-off ``c`` and order
``p``, between the estimates ``X`` and the truths ``Y`` of one instant::

    GOSPA = ( min over assignments  sum_assigned min(d, c)^p  +  c^p / 2 (|X| + |Y| - 2 |assigned|) )^(1/p)

where a pair at ``d >= c`` counts as one missed and one false (``c^p / 2`` each), which is the same.
Found by scipy's ``linear_sum_assignment`` on ``min(d, c)^p``; the parts are reported as Stone Soup
reports them (``localisation`` = the assigned pairs' sum of ``d^p``, ``missed`` and ``false`` = their
count times ``c^p / 2``, each before the root); ``tests/sky/test_gospa.py`` checks them against
Stone Soup's ``GOSPAMetric``.

Per drone, with tracks matched to drones at each frame as CLEAR MOT matches them (K. Bernardin,
R. Stiefelhagen, "Evaluating multiple object tracking performance: the CLEAR MOT metrics", EURASIP
J. Image Video Process. 2008, Sect. 2.1.1; only confirmed tracks, any class): a drone keeps the
track it was matched to in the previous frame while that track is within ``match_m`` of it; the
drones and tracks left are matched by the same assignment as GOSPA's (cut-off ``match_m``).  (By
the assignment alone, a crown's track that passed within a few centimetres of a drone took the
drone's match for a frame, two id switches though the drone's own track never left it; and a drone
in a swarm was credited with another drone's track.)

``time_to_confirm_s``   first frame a track *of its own* is within ``match_m`` of it, minus the first
                        frame the drone is visible: a track is the own of the drone it was first
                        matched to, or, never matched, of the drone nearest it (within ``match_m``)
                        when it was first output (a track that followed one drone and drifted onto
                        another is the second drone's id switch, not its confirmation; matched or
                        not: CLEAR MOT keeps the drifted track matched, and the second drone's own
                        track is then a second track on it)
``first_matched_s``     the time of the first match of any track (None: never), where the revisit
                        gaps and the continuity start
``time_to_drone_label_s``  ... a track of its own labelled drone is (None: never; the label waits,
                        foveatrack.sky.classify rule 5)
``continuity``          share of the frames from that first match on with a matched track
``id_switches``         times the matched track's id changes (gaps without a match do not count)
``fovea_share``         share of its visible frames the drone spends in the fovea, of those in the
                        field where ``in_field`` is given (a drone that flew out of the space of
                        interest, still hit by a ray now and then, is not the fovea's to serve: the
                        tree line's drone, flown on past 70 m, was so for 90 s of an hour's run, and
                        a head that held still where it had gone scored less than one that swept away)
``longest_revisit_gap_s``  the longest stretch (after its first confirmation) out of the fovea, up
                        to its last frame in the field (``in_field`` where given: the simulator's is
                        the head's reach, :func:`sim.sky_summary.drone_truth`; a drone that has
                        left it, or the space of interest, for good is not waiting for a revisit;
                        one the head merely turned away from is); None for a drone in the field no track ever followed (it
                        was never revisited); ``longest_revisit_gap_from_s`` the time of its first
                        frame (None: no gap; the first of equally long ones)

and ``false_drone_tracks``: confirmed tracks labelled drone at some frame without being matched to a
drone at that frame, counted once per id (birds, trees, clutter called drones), and per hour of run.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from foveatrack.fixed_order import norm3


def _pair_distances(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    d = X[:, None, :] - Y[None, :, :]
    d2 = d * d
    return np.sqrt(d2[..., 0] + d2[..., 1] + d2[..., 2])


def gospa(estimates, truths, c: float, p: float = 2.0) -> dict:
    """GOSPA of one instant (module docstring): ``distance``, ``localisation``, ``missed``, ``false``,
    and ``assignment``: (estimate index, truth index) pairs closer than ``c``."""
    X = np.asarray(estimates, np.float64).reshape(-1, 3)
    Y = np.asarray(truths, np.float64).reshape(-1, 3)
    half = c ** p / 2.0
    loc, pairs = 0.0, []
    if X.shape[0] and Y.shape[0]:
        d = _pair_distances(X, Y)
        cost = np.minimum(d, c) ** p
        rows, cols = linear_sum_assignment(cost)
        for i, j in zip(rows.tolist(), cols.tolist()):
            if d[i, j] < c:
                loc += float(cost[i, j])
                pairs.append((i, j))
    n = len(pairs)
    missed = half * (Y.shape[0] - n)
    false = half * (X.shape[0] - n)
    return {"distance": (loc + missed + false) ** (1.0 / p), "localisation": loc, "missed": missed,
            "false": false, "assignment": pairs}


def drone_metrics(times_s, drones: dict, tracks_per_frame, match_m: float = 2.0) -> dict:
    """The per-drone figures and the false drone tracks (module docstring).

    times_s : (T,) frame times [s]
    drones : id -> {"xyz_m": (T, 3), "visible": (T,) bool, "in_fovea": (T,) bool or None,
                    "in_field": (T,) bool (optional)}
    tracks_per_frame : T lists of (track_id, label, xyz_m) of the confirmed tracks
    """
    t = np.asarray(times_s, np.float64)
    ids = sorted(drones)
    T = t.size
    matched = {d: [None] * T for d in ids}
    false_ids: set[int] = set()
    for k in range(T):
        tr = tracks_per_frame[k]
        live = [d for d in ids if np.all(np.isfinite(drones[d]["xyz_m"][k]))]
        hit = {}       # track index -> drone
        if k > 0 and tr:
            # the previous frame's matches that still hold (CLEAR MOT)
            where = {tid: i for i, (tid, _, _) in enumerate(tr)}
            for d in live:
                i = where.get(matched[d][k - 1])
                if i is not None and i not in hit and norm3(np.asarray(tr[i][2], np.float64) - drones[d]["xyz_m"][k]) < match_m:
                    hit[i] = d
        kept = set(hit.values())
        rest_d = [d for d in live if d not in kept]
        rest_i = [i for i in range(len(tr)) if i not in hit]
        if rest_d and rest_i:
            g = gospa([tr[i][2] for i in rest_i], [drones[d]["xyz_m"][k] for d in rest_d], match_m)
            for i, j in g["assignment"]:
                hit[rest_i[i]] = rest_d[j]
        for i, d in hit.items():
            matched[d][k] = tr[i][0]
        for i, (tid, label, _) in enumerate(tr):
            if label == "drone" and i not in hit:
                false_ids.add(tid)
    # each track's own drone: the first it was matched to; a track never matched, the nearest within
    # match_m when it was first output (None: none)
    owner: dict[int, str | None] = {}
    for k in range(T):
        for d in ids:
            if matched[d][k] is not None:
                owner.setdefault(matched[d][k], d)
    own_at = {d: None for d in ids}         # first frame a track of its own is within match_m
    own_label_at = {d: None for d in ids}   # ... and labelled drone
    for k in range(T):
        live = [d for d in ids if np.all(np.isfinite(drones[d]["xyz_m"][k]))]
        for tid, label, x in tracks_per_frame[k]:
            x = np.asarray(x, np.float64)
            if tid not in owner:
                near = min(((norm3(x - drones[d]["xyz_m"][k]), d) for d in live), default=(math.inf, None))
                owner[tid] = near[1] if near[0] < match_m else None
            d = owner[tid]
            if d is None or (own_at[d] is not None and (own_label_at[d] is not None or label != "drone")):
                continue            # nothing left for this track to tell its drone
            if d in live and norm3(x - drones[d]["xyz_m"][k]) < match_m:
                if own_at[d] is None:
                    own_at[d] = k
                if own_label_at[d] is None and label == "drone":
                    own_label_at[d] = k
    dt = float(np.median(np.diff(t))) if T > 1 else 0.0
    out = {}
    for d in ids:
        vis = np.asarray(drones[d]["visible"], bool)
        m = matched[d]
        first_vis = int(np.argmax(vis)) if vis.any() else None
        first = next((k for k in range(T) if m[k] is not None), None)
        own, labelled = own_at[d], own_label_at[d]
        r = {"time_to_confirm_s": None if own is None or first_vis is None else float(t[own] - t[first_vis]),
             "time_to_drone_label_s": None if labelled is None or first_vis is None else
             float(t[labelled] - t[first_vis]),
             "first_matched_s": None if first is None else float(t[first]),
             "continuity": 0.0, "id_switches": 0, "track_ids": sorted({x for x in m if x is not None})}
        if first is not None:
            seen = [x for x in m[first:] if x is not None]
            r["continuity"] = len(seen) / (T - first)
            r["id_switches"] = sum(1 for a, b in zip(seen, seen[1:]) if a != b)
        fov = drones[d].get("in_fovea")
        if fov is not None:
            fov = np.asarray(fov, bool)
            field = drones[d].get("in_field")
            counted = vis if field is None else vis & np.asarray(field, bool)
            r["fovea_share"] = float(fov[counted].mean()) if counted.any() else 0.0
            gap, longest, since = 0, 0, None
            # up to its last frame in the field (a drone never in it: no gap to count)
            end = T if field is None else (int(np.flatnonzero(field)[-1]) + 1 if np.any(field) else 0)
            for k in range(first if first is not None else T, end):
                gap = 0 if fov[k] else gap + 1
                if gap > longest:
                    longest, since = gap, k - gap + 1
            # a drone in the field that no track ever followed was never revisited: no gap is measured
            # (None), and it does not count as one within the revisit time
            never = first is None and (field is None or bool(np.any(field)))
            r["longest_revisit_gap_s"] = None if never else longest * dt
            r["longest_revisit_gap_from_s"] = None if since is None else float(t[since])
        out[d] = r
    hours = (t[-1] - t[0] + dt) / 3600.0 if T else math.nan
    return {"drones": out, "false_drone_tracks": sorted(false_ids),
            "false_drone_tracks_per_hour": len(false_ids) / hours if hours > 0 else math.nan}
